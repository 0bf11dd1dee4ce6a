"""anm_post: post-processing of Anm models: model files, 2D slices (label images), tables, plots.

Public API:
    read_model(path) -> Model                         (HDF5 model file into numpy arrays)
    Slicer(model, shells=ShellSpec(...)).slice(plane) -> SliceResult (labels; .save(npz|h5))
    axis_plane(model, axis, position, pixel), Plane(origin, u, v, size, pixel), stack_positions, n_max
    save_slice_png(result, model, path, nlayer)      (picture with a legend)
    psd_table(model), format_psd(rows, fmt)            (PSD table: text, csv, markdown)
    plot_study(csv, png)                               (contact studies, thesis Figs 2.14, 2.15)
    rdf(model, RdfSpec(...)) -> RdfResult             (wall effect g(t), thesis 3.4; docs/walleffect.md)
    volume_fractions(model, spec), convergence(model, spec, densities), plot_rdf, plot_convergence
    read_geometry_table(path) -> GeometryTable        (output of `anm shape` or a NIST *-geom*.dat table)
    read_shape_coefficients(path) -> (n, m, a) arrays of a NIST coefficient file
The compiled kernels (anm_post.kernels) are imported on first use of slicing.
"""
from .errors import AnmPostError
from .tables import GeometryTable, read_geometry_table, psd_table, format_psd
from .shapes import read_shape_coefficients
from .model import Model, read_model
from .slicing import Plane, ShellSpec, SliceResult, Slicer, axis_plane, n_max, random_plane, stack_positions
from .images import save_slice_png
from .plots import plot_study, read_study_csv
from .walleffect import RdfResult, RdfSpec, convergence, plot_convergence, plot_rdf, rdf, volume_fractions

__all__ = ["AnmPostError", "GeometryTable", "read_geometry_table", "read_shape_coefficients", "psd_table",
           "format_psd", "Model", "read_model", "Plane", "ShellSpec", "SliceResult", "Slicer", "axis_plane",
           "n_max", "random_plane", "stack_positions", "save_slice_png", "plot_study", "read_study_csv",
           "RdfSpec", "RdfResult", "rdf", "volume_fractions", "convergence", "plot_rdf", "plot_convergence"]
__version__ = "0.2.0"

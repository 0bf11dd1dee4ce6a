"""anm_post: post-processing of Anm models (tables now; slices, g(t) and plots in later releases).

Public API:
    read_geometry_table(path)  -> GeometryTable   (output of `anm shape` or a NIST *-geom*.dat table)
    read_shape_coefficients(path) -> (n, m, a) arrays of a NIST coefficient file
"""
from .errors import AnmPostError
from .tables import GeometryTable, read_geometry_table
from .shapes import read_shape_coefficients

__all__ = ["AnmPostError", "GeometryTable", "read_geometry_table", "read_shape_coefficients"]
__version__ = "0.1.0"

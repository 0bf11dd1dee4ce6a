"""VRML and ParaView exports read by VTK (issue 17, items 1 and 2).

- The default job's VRML in the flat layout (`vrml_layout = 'flat'`; one file per layer, and a
  single file of a small job) imported with VTK's own importer (vtkVRMLImporter, what ParaView
  uses; linear in the particles for this layout): one actor per sieve and per shell layer, its
  colour the sieve's (anm's palette) or the layer's with opacity 0.4 (the file says transparency
  0.6: with `.6` VTK read 0), as many closed surfaces (connected regions) as the model file has
  particles of that sieve, the tessellation's vertex count per particle, and each particle's
  vertices around its centre in the model file.
- The instanced layout (the default: one Transform + USE per surface) of a small job imported by
  VTK: one actor per particle and per shell surface, each with its sieve's or layer's colour (leading
  zeros read) around its particle's centre; the default job's instanced file stays small (< 30 MB).
- `anm-post export` in vtu (read by meshio and VTK), vtp and vtkhdf (read by VTK's readers):
  centres and fields against the model file, surface cells per particle, shell layers.
"""
from __future__ import annotations

import pathlib
import subprocess

import numpy as np
import pytest

vtk = pytest.importorskip("vtk")

from anm_post.cli import main  # noqa: E402
from anm_post.export import default_tessellation, sphere_directions  # noqa: E402
from anm_post.model import read_model  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
#: anm's VRML sieve colours (src/cli/run.f90) and the default colour of shell layer 1.
PALETTE = np.array([[0.55, 0.45, 0.35], [0.75, 0.65, 0.45], [0.85, 0.80, 0.60], [0.60, 0.60, 0.65],
                    [0.45, 0.55, 0.45], [0.70, 0.50, 0.50]])


def _run(anm_bin, folder: pathlib.Path, text: str) -> None:
    nml = folder / "job.nml"
    nml.write_text(text)
    res = subprocess.run([anm_bin, "run", str(nml)], capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stderr


@pytest.fixture(scope="module")
def default_job(anm_bin, tmp_path_factory):
    """The default job with one VRML file per layer (default tessellation), flat layout."""
    out = tmp_path_factory.mktemp("default")
    text = (ROOT / "inputs" / "default.nml").read_text().replace("directory = 'out'", f"directory = '{out}'")
    text = text.replace("vrml = .true.", "vrml = .true., vrml_per_layer = .true., vrml_layout = 'flat'")
    _run(anm_bin, out, text)
    return out


def import_vrml(path: pathlib.Path, centres: bool = False) -> list:
    """(diffuse colour, opacity, polydata) of every actor vtkVRMLImporter makes of the file, and
    with `centres` the world centre of the actor's bounds (its Transform applied) last."""
    win = vtk.vtkRenderWindow()
    win.SetOffScreenRendering(1)
    ren = vtk.vtkRenderer()
    win.AddRenderer(ren)
    imp = vtk.vtkVRMLImporter()
    imp.SetFileName(str(path))
    imp.SetRenderWindow(win)
    imp.Update()
    actors = ren.GetActors()
    actors.InitTraversal()
    out = []
    for _ in range(actors.GetNumberOfItems()):
        a = actors.GetNextActor()
        pd = a.GetMapper().GetInput()
        item = (np.array(a.GetProperty().GetDiffuseColor()), a.GetProperty().GetOpacity(), pd)
        out.append(item + (np.array(a.GetCenter()),) if centres else item)
    return out


def regions(pd) -> int:
    f = vtk.vtkPolyDataConnectivityFilter()
    f.SetInputData(pd)
    f.SetExtractionModeToAllRegions()
    f.Update()
    return f.GetNumberOfExtractedRegions()


def surfaces(actors):
    """Actors with polygons (the box is a line set)."""
    return [a for a in actors if a[2].GetNumberOfPolys() > 0]


def nvert(tess: int) -> int:
    return (tess - 1) * 2 * tess + 2


def check_particles(actors, model, tess) -> None:
    got = surfaces(actors)
    assert len(got) == model.n_sieves
    for colour, opacity, pd in got:
        s = int(np.argmin(np.abs(PALETTE[:model.n_sieves] - colour).sum(axis=1)))
        assert np.allclose(colour, PALETTE[s], atol=1e-4), colour  # not black: leading zeros read
        assert opacity == pytest.approx(1.0)
        ids = np.flatnonzero(model.sieve == s)
        nv = nvert(tess[s])
        assert pd.GetNumberOfPoints() == len(ids) * nv
        assert pd.GetNumberOfPolys() == len(ids) * 2 * tess[s] ** 2
        assert regions(pd) == len(ids)
        # particle k of the sieve: its vertices surround its centre (within its size)
        from vtk.util.numpy_support import vtk_to_numpy
        pts = vtk_to_numpy(pd.GetPoints().GetData()).reshape(len(ids), nv, 3)
        size = np.linalg.norm(pts - model.center[ids][:, None, :], axis=2).max(axis=1)
        assert np.all(np.linalg.norm(pts.mean(axis=1) - model.center[ids], axis=1) < 0.5 * size)
        assert np.all(size < model.sieves["max_width"][s] * 1.5)


def test_default_vrml_per_layer_imports_with_vtk(default_job):
    model = read_model(default_job / "default.h5")
    tess = default_tessellation(model.n_sieves)
    check_particles(import_vrml(default_job / "default-particles.wrl"), model, tess)
    layer = surfaces(import_vrml(default_job / "default-layer1.wrl"))
    assert len(layer) == 1  # one shape for the layer: its colour, translucent
    colour, opacity, pd = layer[0]
    assert opacity == pytest.approx(0.4, abs=1e-3)
    assert colour.max() > 0.5
    assert regions(pd) == model.n_particles
    assert pd.GetNumberOfPoints() == sum(nvert(tess[s]) for s in model.sieve)


def test_single_vrml_file_of_a_small_job(anm_bin, tmp_path):
    text = (ROOT / "inputs" / "default.nml").read_text().replace("directory = 'out'", f"directory = '{tmp_path}'")
    text = text.replace("length = 20.0, 20.0, 20.0", "length = 9.0, 9.0, 9.0").replace(
        "vrml = .true.", "vrml = .true., tessellation = 8, 6, 5, 4, vrml_layout = 'flat'")
    _run(anm_bin, tmp_path, text)
    model = read_model(tmp_path / "default.h5")
    text = (tmp_path / "default.wrl").read_text()
    assert " .5" not in text and " .6" not in text  # leading zeros
    actors = import_vrml(tmp_path / "default.wrl")
    particles = [a for a in actors if a[1] > 0.99]
    shells = [a for a in surfaces(actors) if a[1] < 0.99]
    check_particles(particles, model, [8, 6, 5, 4][:model.n_sieves])
    assert len(shells) == 1 and shells[0][1] == pytest.approx(0.4, abs=1e-3)
    assert regions(shells[0][2]) == model.n_particles


def test_instanced_vrml_of_a_small_job_imports_with_vtk(anm_bin, tmp_path):
    """The default layout: one actor per Transform, particles first (model order) then the shell
    surfaces; colours not black and shells translucent (the leading zeros read), each actor around
    its particle's centre."""
    text = (ROOT / "inputs" / "default.nml").read_text().replace("directory = 'out'", f"directory = '{tmp_path}'")
    text = text.replace("length = 20.0, 20.0, 20.0", "length = 9.0, 9.0, 9.0").replace(
        "vrml = .true.", "vrml = .true., tessellation = 8, 6, 5, 4")
    _run(anm_bin, tmp_path, text)
    model = read_model(tmp_path / "default.h5")
    text = (tmp_path / "default.wrl").read_text()
    assert "USE M" in text and " .5" not in text and " .6" not in text
    got = surfaces(import_vrml(tmp_path / "default.wrl", centres=True))
    n = model.n_particles
    assert len(got) == 2 * n
    tess = [8, 6, 5, 4]
    for p, (colour, opacity, pd, centre) in enumerate(got[:n]):
        s = model.sieve[p]
        assert np.allclose(colour, PALETTE[s], atol=1e-4), (p, colour)
        assert opacity == pytest.approx(1.0)
        assert pd.GetNumberOfPoints() == nvert(tess[s])
        assert np.linalg.norm(centre - model.center[p]) < 0.5 * model.sieves["max_width"][s]
    layer_colour = got[n][0]
    assert layer_colour.max() > 0.5
    for p, (colour, opacity, pd, centre) in enumerate(got[n:]):
        assert np.allclose(colour, layer_colour) and opacity == pytest.approx(0.4, abs=1e-3)
        assert np.linalg.norm(centre - model.center[p]) < 0.5 * model.sieves["max_width"][model.sieve[p]]


def test_default_job_instanced_vrml_stays_small(anm_bin, tmp_path):
    """The default layout keeps the default job's single VRML file small (8.7 MB; flat: 278 MB)."""
    text = (ROOT / "inputs" / "default.nml").read_text().replace("directory = 'out'", f"directory = '{tmp_path}'")
    _run(anm_bin, tmp_path, text)
    size = (tmp_path / "default.wrl").stat().st_size
    assert 1e6 < size < 30e6, size
    head = (tmp_path / "default.wrl").read_text()[:2000]
    assert "instanced layout" in head and "Transform" in head


# -- anm-post export ----------------------------------------------------------------------------

def read_vtk(path: pathlib.Path, fmt: str):
    reader = {"vtu": vtk.vtkXMLUnstructuredGridReader, "vtp": vtk.vtkXMLPolyDataReader,
              "vtkhdf": vtk.vtkHDFReader}[fmt]()
    reader.SetFileName(str(path))
    reader.Update()
    out = reader.GetOutput()
    from vtk.util.numpy_support import vtk_to_numpy
    cd = out.GetCellData()
    fields = {cd.GetArrayName(i): vtk_to_numpy(cd.GetArray(i)) for i in range(cd.GetNumberOfArrays())}
    pts = vtk_to_numpy(out.GetPoints().GetData())
    sizes = np.array([out.GetCell(i).GetNumberOfPoints() for i in range(min(out.GetNumberOfCells(), 200000))])
    first = np.array([out.GetCell(i).GetPointId(0) for i in range(model_n(fields))])
    return out, fields, pts, sizes, first


def model_n(fields) -> int:
    return int((fields["kind"] == 0).sum())


@pytest.mark.parametrize("fmt", ["vtu", "vtp", "vtkhdf"])
def test_export_read_by_vtk(default_job, tmp_path, fmt):
    model = read_model(default_job / "default.h5")
    out = tmp_path / f"m.{fmt}"
    tess = [6, 5, 4, 3]
    assert main(["export", str(default_job / "default.h5"), "--output", str(out), "--tessellation",
                 ",".join(map(str, tess)), "--shells", "0.02"]) == 0
    data, fields, pts, sizes, first = read_vtk(out, fmt)
    n = model.n_particles
    assert set(fields) == {"particle_id", "sieve", "shape", "layer", "kind"}
    kind = fields["kind"]
    assert (kind[:n] == 0).all() and (kind[n:] == 1).all()  # centres first
    assert np.array_equal(fields["particle_id"][:n], np.arange(n))
    assert np.allclose(pts[first], model.center, atol=1e-5)  # float32 points
    pid = fields["particle_id"]
    assert np.array_equal(fields["sieve"], model.sieve[pid])
    assert np.array_equal(fields["shape"], model.shape[pid])
    cells_per = np.array([2 * tess[s] ** 2 for s in model.sieve])
    for layer in (0, 1):
        sel = (kind == 1) & (fields["layer"] == layer)
        assert np.array_equal(np.bincount(pid[sel], minlength=n), cells_per)
    assert set(np.unique(sizes[n:])) <= {3, 4} and (sizes[:n] == 1).all()
    assert data.GetNumberOfCells() == n + 2 * cells_per.sum()


def test_export_vtu_read_by_meshio(default_job, tmp_path):
    meshio = pytest.importorskip("meshio")
    model = read_model(default_job / "default.h5")
    out = tmp_path / "m.vtu"
    assert main(["export", str(default_job / "default.h5"), "--output", str(out), "--tessellation", "4"]) == 0
    mesh = meshio.read(out)
    kinds = [c.type for c in mesh.cells]
    assert kinds == ["vertex", "triangle", "quad"]
    centres = mesh.points[mesh.cells[0].data[:, 0]]
    assert np.allclose(centres, model.center, atol=1e-5)
    assert np.array_equal(mesh.cell_data["sieve"][0], model.sieve)
    # triangles: 2 x 2 tess per particle; quads (tess - 2) 2 tess
    assert np.array_equal(np.bincount(mesh.cell_data["particle_id"][1], minlength=model.n_particles),
                          np.full(model.n_particles, 16))
    assert len(mesh.cells[2].data) == model.n_particles * 16


def test_export_surface_points_are_the_model_surfaces(default_job, tmp_path):
    """Surface vertices of a particle are its centre + scale R r(u) u with r from the SH series
    (independent numpy evaluation, synth.radius)."""
    from synth import radius
    model = read_model(default_job / "default.h5")
    out = tmp_path / "m.vtkhdf"
    assert main(["export", str(default_job / "default.h5"), "--output", str(out), "--tessellation", "5"]) == 0
    import h5py
    with h5py.File(out) as fh:
        pts = fh["VTKHDF/Points"][()]
    dirs = sphere_directions(5)
    n = model.n_particles
    for p in (0, n // 2, n - 1):
        s, order = model.shape[p], model.nmax[p]
        c = model.shape_coeffs[s][:(order + 1) ** 2]
        r = radius(c, order, dirs)
        want = model.center[p] + model.scale[p] * (model.rotation[p] @ (r[:, None] * dirs).T).T
        got = pts[n + p * len(dirs): n + (p + 1) * len(dirs)]
        assert np.allclose(got, want, atol=1e-4)


@pytest.mark.parametrize("layout", ["flat", "instanced"])
def test_castle_reads_the_vrml(anm_bin, tmp_path, layout):
    """view3dscene's engine (Castle Game Engine, Debian package view3dscene: its converter
    tovrmlx3d parses the file as view3dscene does) reads both layouts with the sieves' colours and
    the layer's transparency; the flat one has one IndexedFaceSet per sieve and per layer."""
    import shutil
    tool = shutil.which("tovrmlx3d")
    if tool is None:
        pytest.skip("tovrmlx3d (Debian package view3dscene) is not installed")
    text = (ROOT / "inputs" / "default.nml").read_text().replace("directory = 'out'", f"directory = '{tmp_path}'")
    text = text.replace("length = 20.0, 20.0, 20.0", "length = 8.0, 8.0, 8.0").replace(
        "vrml = .true.", f"vrml = .true., tessellation = 6, 5, 4, 4, vrml_layout = '{layout}'")
    _run(anm_bin, tmp_path, text)
    model = read_model(tmp_path / "default.h5")
    res = subprocess.run([tool, str(tmp_path / "default.wrl"), "--encoding", "classic"], capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    out = res.stdout
    if layout == "flat":
        assert out.count("IndexedFaceSet") == len(np.unique(model.sieve)) + 1
    import re
    colours = np.array([[float(x) for x in m.split()] for m in re.findall(r"diffuseColor ([0-9.e+-]+ [0-9.e+-]+ "
                                                                           r"[0-9.e+-]+)", out)])
    for s in np.unique(model.sieve):
        assert np.abs(colours - PALETTE[s]).max(axis=1).min() < 1e-6
    assert re.search(r"transparency 0\.6", out)

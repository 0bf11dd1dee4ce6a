"""Particle surfaces and centres of a model for ParaView/VTK (issue 17, item 2): VTU (meshio),
VTP (VTK's XML writer) or VTKHDF (h5py, VTKHDF 2.x PolyData layout).

One data set holds
  - the particle centres as vertex cells (one point each), and
  - every particle surface (and, with shells, every shell layer's outer surface) as triangles
    (at the poles) and quads of a latitude-longitude tessellation, as anm's VRML: `tess` polar and
    2 tess azimuthal divisions per sieve (anm's default 32 for the first sieve, coarser after).
Cell fields on both: particle_id (0-based), sieve (0-based), shape (0-based), layer (0 = the
particle, k = outer surface of shell layer k; centres 0) and kind (0 centre, 1 surface). Surface
points are r(u) u from the model's SH coefficients through the Fortran kernels (anm_post.kernels).

Cell order (the same in every format): centres, then all triangles, then all quads.

    mesh = surface_mesh(model, tessellation=[8, 6, 4])
    write_mesh(mesh, "m.vtkhdf", "vtkhdf")
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import kernels
from .errors import AnmPostError
from .model import Model

#: Output formats and their usual suffixes.
FORMATS = {"vtu": ".vtu", "vtp": ".vtp", "vtkhdf": ".vtkhdf"}
#: Cell fields written.
FIELDS = ("particle_id", "sieve", "shape", "layer", "kind")


def default_tessellation(n_sieves: int) -> list[int]:
    """anm's default VRML tessellation per sieve (docs/namelist.md: 32 for the first sieve, coarser
    for later ones, at least 8)."""
    return [max(8, 32 - (24 * i) // max(1, n_sieves)) for i in range(n_sieves)]


def sphere_directions(tess: int) -> np.ndarray:
    """Unit directions (nvert, 3) of the lat-long tessellation anm's VRML uses: rings i = 1..tess-1
    (theta = pi i / tess, 2 tess points each), then the north and south poles."""
    nt = max(2, int(tess))
    th = np.pi * np.arange(1, nt) / nt
    ph = 2 * np.pi * np.arange(2 * nt) / (2 * nt)
    t, p = np.meshgrid(th, ph, indexing="ij")
    u = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1).reshape(-1, 3)
    return np.concatenate([u, [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]])


def sphere_faces(tess: int) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (2 * 2 tess, 3) at the poles and quads ((tess - 2) * 2 tess, 4) between rings of
    sphere_directions(tess), outward oriented as in anm's VRML."""
    nt = max(2, int(tess))
    npp = 2 * nt
    j = np.arange(npp)
    jn = (j + 1) % npp
    north, south = (nt - 1) * npp, (nt - 1) * npp + 1
    tri = np.concatenate([np.stack([np.full(npp, north), jn, j], axis=1),
                          np.stack([(nt - 2) * npp + j, (nt - 2) * npp + jn, np.full(npp, south)], axis=1)])
    i = np.arange(nt - 2)[:, None]
    quad = np.stack([i * npp + j, i * npp + jn, (i + 1) * npp + jn, (i + 1) * npp + j], axis=-1).reshape(-1, 4)
    return tri, quad


@dataclass
class SurfaceMesh:
    """Points (n, 3) float32 mm; vertex cells (centres), triangles, quads (point indices); cell
    fields in cell order (centres, triangles, quads)."""

    points: np.ndarray
    centre_points: np.ndarray
    triangles: np.ndarray
    quads: np.ndarray
    fields: dict[str, np.ndarray]
    n_particles: int
    n_surfaces: int

    @property
    def n_cells(self) -> int:
        return len(self.centre_points) + len(self.triangles) + len(self.quads)


def estimate_bytes(model: Model, tessellation, nlayer: int = 0) -> int:
    """Rough peak memory of surface_mesh + a writer (bytes)."""
    tess = np.asarray(tessellation)[model.sieve]
    nv = (tess - 1) * 2 * tess + 2
    nf = 2 * tess * tess
    per = nv * 12 + nf * (4 * 8 + 5 * 4) * 2
    return int((1 + nlayer) * per.sum() * 1.5)


def surface_mesh(model: Model, tessellation=None, shells=None, progress=None) -> SurfaceMesh:
    """Tessellated surfaces of every particle (and of its shell layers with `shells`, a
    slicing.ShellSpec, grown as for slices) and the centres."""
    from .slicing import Slicer

    n = model.n_particles
    tessellation = default_tessellation(model.n_sieves) if tessellation is None else list(tessellation)
    if len(tessellation) == 1:
        tessellation = tessellation * model.n_sieves
    if len(tessellation) != model.n_sieves or min(tessellation) < 2:
        raise AnmPostError(f"tessellation: one value >= 2 per sieve ({model.n_sieves}) or one for all, "
                           f"got {tessellation}")
    tess_of = np.asarray(tessellation, dtype=np.int64)[model.sieve]
    slicer = Slicer(model, shells)
    nlayer = 0 if shells is None else len(shells.thickness)
    shelled = np.zeros(n, bool)
    if nlayer:
        shelled[np.arange(n) if shells.particles is None else np.asarray(shells.particles)] = True
    # instances: (particle, layer); layer surfaces only for shelled particles
    inst_p = [np.arange(n)] + [np.flatnonzero(shelled) for _ in range(nlayer)]
    inst_l = [np.zeros(n, np.int64)] + [np.full(int(shelled.sum()), k + 1) for k in range(nlayer)]
    inst_p = np.concatenate(inst_p)
    inst_l = np.concatenate(inst_l)
    nvert = (tess_of - 1) * 2 * tess_of + 2
    inst_nv = nvert[inst_p]
    first = np.concatenate([[n], n + np.cumsum(inst_nv)[:-1]]) if len(inst_p) else np.zeros(0, np.int64)
    total = n + int(inst_nv.sum())
    points = np.empty((total, 3), np.float32)
    points[:n] = model.center
    # body-frame vertices per key, then all instances of the key at once
    form = slicer.particle_form_ids()
    if nlayer:
        tsu = np.round(slicer.shell_distances(np.arange(n)), 12)
    keys: dict[tuple, list[int]] = {}
    for j, (p, layer) in enumerate(zip(inst_p, inst_l)):
        extra = tuple(tsu[p]) if layer else ()
        keys.setdefault((int(form[p]), int(tess_of[p]), int(layer), extra), []).append(j)
    if nlayer:  # every shell surface built in one kernel call (OpenMP inside)
        slicer.prepare_shells(np.flatnonzero(shelled))
    done = 0
    for (f, tess, layer, _), js in keys.items():
        js = np.asarray(js)
        dirs = sphere_directions(tess)
        if layer == 0:
            shape, order = slicer.form_pairs()[f]
            r = kernels.sh_radius(model.shape_coeffs, model.shape_nmax, int(shape), int(order), dirs)
        else:
            a, b, orders, _ = slicer.layer_forms(int(inst_p[js[0]]))
            r = kernels.form_radii(a, b, orders, dirs)[:, layer]
        body = r[:, None] * dirs
        ps = inst_p[js]
        world = (model.center[ps][:, None, :]
                 + model.scale[ps][:, None, None] * np.einsum("pij,vj->pvi", model.rotation[ps], body))
        idx = first[js][:, None] + np.arange(len(dirs))[None, :]
        points[idx.reshape(-1)] = world.reshape(-1, 3)
        done += len(js)
        if progress:
            progress(done, len(inst_p))
    # faces per tessellation
    tri_n = np.zeros(len(inst_p), np.int64)
    quad_n = np.zeros(len(inst_p), np.int64)
    for tess in np.unique(tess_of):
        js = np.flatnonzero(tess_of[inst_p] == tess)
        t, q = sphere_faces(int(tess))
        tri_n[js] = len(t)
        quad_n[js] = len(q)
    tri = np.empty((int(tri_n.sum()), 3), np.int64)
    quad = np.empty((int(quad_n.sum()), 4), np.int64)
    tpos = np.concatenate([[0], np.cumsum(tri_n)])
    qpos = np.concatenate([[0], np.cumsum(quad_n)])
    for tess in np.unique(tess_of):
        js = np.flatnonzero(tess_of[inst_p] == tess)
        t, q = sphere_faces(int(tess))
        ti = (tpos[js][:, None] + np.arange(len(t))[None, :]).reshape(-1)
        qi = (qpos[js][:, None] + np.arange(len(q))[None, :]).reshape(-1)
        tri[ti] = (first[js][:, None, None] + t[None, :, :]).reshape(-1, 3)
        quad[qi] = (first[js][:, None, None] + q[None, :, :]).reshape(-1, 4)
    cell_p = np.concatenate([np.arange(n), np.repeat(inst_p, tri_n), np.repeat(inst_p, quad_n)])
    cell_l = np.concatenate([np.zeros(n, np.int64), np.repeat(inst_l, tri_n), np.repeat(inst_l, quad_n)])
    fields = {
        "particle_id": cell_p.astype(np.int32),
        "sieve": model.sieve[cell_p].astype(np.int32),
        "shape": model.shape[cell_p].astype(np.int32),
        "layer": cell_l.astype(np.int32),
        "kind": np.concatenate([np.zeros(n, np.int8), np.ones(len(cell_p) - n, np.int8)]),
    }
    return SurfaceMesh(points, np.arange(n, dtype=np.int64), tri, quad, fields, n, len(inst_p))


def write_mesh(mesh: SurfaceMesh, path: str | Path, fmt: str) -> Path:
    """Write to `path` (a temporary name from the caller's safe writer) in format vtu|vtp|vtkhdf."""
    path = Path(path)
    if fmt == "vtu":
        import meshio
        nc = len(mesh.centre_points)
        nt = len(mesh.triangles)
        split = {k: [v[:nc], v[nc:nc + nt], v[nc + nt:]] for k, v in mesh.fields.items()}
        m = meshio.Mesh(mesh.points, [("vertex", mesh.centre_points[:, None]), ("triangle", mesh.triangles),
                                      ("quad", mesh.quads)], cell_data=split)
        meshio.write(path, m, file_format="vtu", binary=True, compression="zlib")
    elif fmt == "vtp":
        _write_vtp(mesh, path)
    elif fmt == "vtkhdf":
        _write_vtkhdf(mesh, path)
    else:
        raise AnmPostError(f"--format: unknown format {fmt!r} (vtu, vtp or vtkhdf)")
    return path


def _offsets_connectivity(cells: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    sizes = np.concatenate([np.full(len(c), c.shape[1], np.int64) for c in cells])
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    conn = np.concatenate([c.reshape(-1) for c in cells]).astype(np.int64)
    return offsets, conn


def _write_vtp(mesh: SurfaceMesh, path: Path) -> None:
    import vtk
    from vtk.util import numpy_support as ns

    pd = vtk.vtkPolyData()
    pts = vtk.vtkPoints()
    pts.SetData(ns.numpy_to_vtk(mesh.points, deep=True))
    pd.SetPoints(pts)
    for cells, setter in (([mesh.centre_points[:, None]], pd.SetVerts), ([mesh.triangles, mesh.quads], pd.SetPolys)):
        off, conn = _offsets_connectivity(cells)
        ca = vtk.vtkCellArray()
        ca.SetData(ns.numpy_to_vtkIdTypeArray(off, deep=True), ns.numpy_to_vtkIdTypeArray(conn, deep=True))
        setter(ca)
    for name, values in mesh.fields.items():
        arr = ns.numpy_to_vtk(np.ascontiguousarray(values), deep=True)
        arr.SetName(name)
        pd.GetCellData().AddArray(arr)
    w = vtk.vtkXMLPolyDataWriter()
    w.SetFileName(str(path))
    w.SetInputData(pd)
    w.SetDataModeToAppended()
    w.SetCompressorTypeToZLib()
    if not w.Write():
        raise OSError(f"{path}: VTK's XML writer failed")


def _write_vtkhdf(mesh: SurfaceMesh, path: Path) -> None:
    """VTKHDF 2.x PolyData: /VTKHDF with attributes Version and Type, Points, the four topologies
    (Vertices, Lines, Polygons, Strips: NumberOfCells, NumberOfConnectivityIds, Offsets,
    Connectivity) and CellData in that topology order."""
    import h5py

    with h5py.File(path, "w") as fh:
        root = fh.create_group("VTKHDF")
        root.attrs["Version"] = np.array([2, 0], dtype=np.int64)
        root.attrs.create("Type", np.bytes_("PolyData"), dtype=h5py.string_dtype("ascii", len("PolyData")))
        root.create_dataset("NumberOfPoints", data=np.array([len(mesh.points)], np.int64))
        root.create_dataset("Points", data=mesh.points, compression="gzip", compression_opts=1)
        topo = {"Vertices": [mesh.centre_points[:, None]], "Lines": [], "Polygons": [mesh.triangles, mesh.quads],
                "Strips": []}
        for name, cells in topo.items():
            g = root.create_group(name)
            off, conn = _offsets_connectivity(cells) if cells else (np.zeros(1, np.int64), np.zeros(0, np.int64))
            g.create_dataset("NumberOfCells", data=np.array([len(off) - 1], np.int64))
            g.create_dataset("NumberOfConnectivityIds", data=np.array([len(conn)], np.int64))
            g.create_dataset("Offsets", data=off, compression="gzip", compression_opts=1)
            g.create_dataset("Connectivity", data=conn, compression="gzip", compression_opts=1)
        cd = root.create_group("CellData")
        for name, values in mesh.fields.items():
            cd.create_dataset(name, data=values, compression="gzip", compression_opts=1)
        root.create_group("PointData")
        root.create_group("FieldData")

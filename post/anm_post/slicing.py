"""2D slices of a model (thesis section 3.3): label images, shells grown at slicing time, stacks
of parallel slices at slice density rho_s (thesis Eqs 3.3-3.4).

Library API:
    plane = axis_plane(model, "z", 10.0, pixel=0.05)          # z = 10 mm over the whole box face
    plane = Plane(origin, u, v, size=(w, h), pixel=0.05)      # any plane (u, v orthonormal)
    slicer = Slicer(model, shells=ShellSpec((0.02,), unit="fraction"))
    result = slicer.slice(plane)          # SliceResult: particle (-1 = matrix), layer (0 = none)
    result.save("slice.npz")              # or .h5
    for res in slicer.stack("z", pixel=0.05, density=0.1): ...
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from . import kernels
from .errors import AnmPostError
from .model import Model

_AXES = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True)
class Plane:
    """A slice rectangle: corner `origin` (mm), orthonormal in-plane axes u, v, size (mm along u, v)
    and pixel size R_s (mm per pixel). Pixel (row j, column i) has its centre at
    origin + (i + 1/2) R_s u + (j + 1/2) R_s v (0-based i, j)."""

    origin: tuple[float, float, float]
    u: tuple[float, float, float]
    v: tuple[float, float, float]
    size: tuple[float, float]
    pixel: float

    def __post_init__(self) -> None:
        u = np.asarray(self.u, float)
        v = np.asarray(self.v, float)
        if not (np.isfinite(self.pixel) and self.pixel > 0):
            raise AnmPostError(f"pixel size must be positive, got {self.pixel}")
        if not all(np.isfinite(s) and s > 0 for s in self.size):
            raise AnmPostError(f"slice size must be positive, got {self.size}")
        if abs(np.linalg.norm(u) - 1) > 1e-6 or abs(np.linalg.norm(v) - 1) > 1e-6 or abs(u @ v) > 1e-6:
            raise AnmPostError("in-plane axes u and v must be orthonormal")

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns) = (pixels along v, pixels along u)."""
        return max(1, round(self.size[1] / self.pixel)), max(1, round(self.size[0] / self.pixel))

    @property
    def normal(self) -> np.ndarray:
        """Unit normal u x v."""
        return np.cross(self.u, self.v)

    def pixel_centers(self) -> np.ndarray:
        """World positions (rows, columns, 3) of the pixel centres."""
        nv, nu = self.shape
        i = (np.arange(nu) + 0.5) * self.pixel
        j = (np.arange(nv) + 0.5) * self.pixel
        return (np.asarray(self.origin)[None, None, :] + j[:, None, None] * np.asarray(self.v)[None, None, :]
                + i[None, :, None] * np.asarray(self.u)[None, None, :])


def axis_plane(model: Model, axis: str | int, position: float, pixel: float) -> Plane:
    """The slice axis = position (mm) over the whole box face; in-plane axes in increasing order
    (x: u = y, v = z; y: u = x, v = z; z: u = x, v = y)."""
    k = _AXES.get(axis, axis) if isinstance(axis, str) else int(axis)
    if k not in (0, 1, 2):
        raise AnmPostError(f"axis must be x, y or z, got {axis!r}")
    if not (0.0 <= position <= model.box[k]):
        raise AnmPostError(f"slice position {position} outside the box [0, {model.box[k]}] along {'xyz'[k]}")
    iu, iv = [d for d in range(3) if d != k]
    eye = np.eye(3)
    origin = np.zeros(3)
    origin[k] = position
    return Plane(tuple(origin), tuple(eye[iu]), tuple(eye[iv]), (float(model.box[iu]), float(model.box[iv])),
                 float(pixel))


def random_plane(model: Model, pixel: float, size: float, rng: np.random.Generator) -> Plane:
    """A square slice of edge `size` with isotropic random orientation, its centre uniform in the box
    (for stereology; periodic boxes only make every point of it meaningful)."""
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    a = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(n, a)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    c = rng.uniform(0, 1, 3) * model.box
    origin = c - 0.5 * size * (u + v)
    return Plane(tuple(origin), tuple(u), tuple(v), (size, size), float(pixel))


def n_max(extent: float, pixel: float) -> int:
    """Thesis Eq 3.4: N_max = (X_max - X_min) / R_s, slices that make cubic voxels."""
    return max(1, int(np.floor(extent / pixel + 1e-9)))


def stack_positions(x_min: float, x_max: float, pixel: float, density: float) -> np.ndarray:
    """Positions of N = round(rho_s N_max) >= 1 equally spaced parallel slices in [x_min, x_max]
    (thesis Eqs 3.3-3.4: rho_s = N / N_max, 0 < rho_s <= 1); each slice sits in the middle of its
    1/N share of the range."""
    if not (0.0 < density <= 1.0):
        raise AnmPostError(f"slice density rho_s must be in (0, 1], got {density}")
    if not x_max > x_min:
        raise AnmPostError(f"slicing range must not be empty, got [{x_min}, {x_max}]")
    n = max(1, int(round(density * n_max(x_max - x_min, pixel))))
    return x_min + (np.arange(n) + 0.5) * (x_max - x_min) / n


@dataclass(frozen=True)
class ShellSpec:
    """Shells grown at slicing time: cumulative outer distances of the layers from the particle
    surface, in mm or as a fraction of each particle's length, around all particles (particles
    None) or the listed ones (0-based ids). With unit "mm" the distance in shape units, t / scale,
    is rounded to a geometric ladder of relative step `step` (default 2 %, so at most 1 % off) so
    that particles of one shape and order share their shells.

    `ShellSpec.stored(model)` is the specification the model was parked with (group /shells):
    its layers are then taken per particle from /particles/shell_thickness (mm, as the engine
    computed them), not recomputed, so the slice shows the shells the parking used."""

    thickness: tuple[float, ...]
    unit: str = "fraction"
    particles: tuple[int, ...] | None = None
    step: float = 0.02
    from_model: bool = False

    @classmethod
    def stored(cls, model: Model, particles: tuple[int, ...] | None = None) -> "ShellSpec | None":
        """The model's own shell layers, or None when it has none (or predates /shells)."""
        spec = model.shells
        if spec is None or spec["nlayer"] == 0:
            return None
        if model.shell_thickness.shape != (model.n_particles, spec["nlayer"]):
            raise AnmPostError(f"{model.path}::/particles/shell_thickness: expected ({model.n_particles}, "
                               f"{spec['nlayer']}) values for the layers of /shells")
        return cls(tuple(float(t) for t in spec["thickness"]), unit=spec["unit"], particles=particles,
                   from_model=True)

    def __post_init__(self) -> None:
        t = np.asarray(self.thickness, float)
        if t.size == 0 or not np.all(np.isfinite(t)) or np.any(t <= 0) or np.any(np.diff(t) <= 0):
            raise AnmPostError(f"shell thicknesses must be positive and increasing, got {list(self.thickness)}")
        if self.unit not in ("mm", "fraction"):
            raise AnmPostError(f"shell thickness unit must be 'mm' or 'fraction', got {self.unit!r}")
        if not (0 < self.step < 1):
            raise AnmPostError(f"shell quantisation step must be in (0, 1), got {self.step}")


@dataclass
class SliceResult:
    """Labels of one slice. particle: (rows, cols) 0-based particle id, -1 for no particle;
    layer: shell layer 1..nlayer, 0 for none (always 0 on particle pixels); owner: particle whose
    shell gives the layer, -1 if none; sieve: sieve of the pixel's particle, -1 for none."""

    plane: Plane
    particle: np.ndarray
    layer: np.ndarray
    owner: np.ndarray
    sieve: np.ndarray
    stats: dict[str, float] = field(default_factory=dict)

    @property
    def particle_fraction(self) -> float:
        """Fraction of pixels inside particles."""
        return float(np.mean(self.particle >= 0))

    def layer_fractions(self, nlayer: int) -> np.ndarray:
        """Fraction of pixels in each shell layer 1..nlayer."""
        return np.array([np.mean(self.layer == k) for k in range(1, nlayer + 1)])

    def save(self, path: str | Path) -> Path:
        """Write the labels and the plane to .npz or .h5/.hdf5 (by suffix)."""
        path = Path(path)
        meta = dict(origin=np.asarray(self.plane.origin), u=np.asarray(self.plane.u), v=np.asarray(self.plane.v),
                    size=np.asarray(self.plane.size), pixel=np.asarray(self.plane.pixel))
        data = dict(particle=self.particle, layer=self.layer, owner=self.owner, sieve=self.sieve)
        from .output import save_arrays
        return save_arrays(path, data, meta, "anm-slice", "--labels")


class Slicer:
    """Slices of one model. Particle forms (each shape at each order used) and shell surfaces are
    computed once and reused by every slice this object makes."""

    def __init__(self, model: Model, shells: ShellSpec | None = None) -> None:
        self.model = model
        self.shells = shells
        pairs = np.stack([model.shape, model.nmax], axis=1)
        self._pairs, self._form = np.unique(pairs, axis=0, return_inverse=True)
        self._form = self._form.reshape(-1).astype(np.int32)
        self._lmax = int(max(self._pairs[:, 1].max(initial=0), 1))
        self._pa = self._pb = self._pbounds = None
        self._geometry: np.ndarray | None = None
        self._shell_cache: dict[tuple, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = {}
        if shells is not None and shells.particles is not None:
            ids = np.asarray(shells.particles, dtype=int)
            if ids.size == 0 or ids.min() < 0 or ids.max() >= model.n_particles:
                raise AnmPostError(f"shell particle ids must be in 0..{model.n_particles - 1}")

    # -- per-model data ---------------------------------------------------------------------
    def _particle_forms(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self._pa is None:
            m = self.model
            self._pa, self._pb, self._pbounds = kernels.particle_forms(
                m.shape_coeffs, m.shape_nmax, self._pairs[:, 0], self._pairs[:, 1], self._lmax)
        return self._pa, self._pb, self._pbounds

    def geometry(self) -> np.ndarray:
        """Geometry (nform, 8) of every (shape, order) form, columns kernels.GEOMETRY_COLUMNS (shape
        units; computed once)."""
        if self._geometry is None:
            m = self.model
            self._geometry = kernels.geometry(m.shape_coeffs, m.shape_nmax, self._pairs[:, 0], self._pairs[:, 1])
        return self._geometry

    def lengths(self) -> np.ndarray:
        """Length L (shape units) of every (shape, order) form."""
        return self.geometry()[:, kernels.GEOMETRY_COLUMNS.index("length")]

    def particle_form_ids(self) -> np.ndarray:
        """Form index (a row of form_pairs) of every particle."""
        return self._form

    def form_pairs(self) -> np.ndarray:
        """(shape, order) of every form (nform, 2): each shape at each order the model uses."""
        return self._pairs

    def shell_distances(self, ids) -> np.ndarray:
        """Cumulative layer distances (len(ids), nlayer) of particles ids in shape units (quantised
        for mm), as slicing grows the shells."""
        if self.shells is None:
            raise AnmPostError("shell_distances needs a Slicer with shells")
        return self._shell_shape_units(np.asarray(ids))

    def prepare_shells(self, ids) -> None:
        """Build the shell surfaces of particles ids in one kernel call (cached; layer_forms then
        reuses them)."""
        ids = np.asarray(ids, dtype=int)
        if self.shells is None or ids.size == 0:
            return
        tsu = np.round(self._shell_shape_units(ids), 12)
        self._build_shells({(int(self._form[p]), tuple(t)) for p, t in zip(ids, tsu)})

    def layer_forms(self, pid: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The surfaces slicing uses for particle pid and its shell layers, as forms: a, b (lmax+1,
        lmax+1, 1 + nlayer), orders (1 + nlayer,), bounds (8, 1 + nlayer); form 0 is the particle,
        form k the outer surface of layer k (shells built once and cached, as for slices)."""
        if self.shells is None:
            raise AnmPostError("layer_forms needs a Slicer with shells")
        pid = int(pid)
        if not (0 <= pid < self.model.n_particles):
            raise AnmPostError(f"particle id must be in 0..{self.model.n_particles - 1}, got {pid}")
        pa, pb, pbounds = self._particle_forms()
        key = (int(self._form[pid]), tuple(np.round(self._shell_shape_units(np.array([pid]))[0], 12)))
        self._build_shells([key])
        sa, sb, so, sbd = self._shell_cache[key]
        f = self._form[pid]
        n0 = int(self._pairs[f, 1])
        lmax = max(n0, int(so.max()))
        nl = len(so)
        a = np.zeros((lmax + 1, lmax + 1, nl + 1), order="F")
        b = np.zeros_like(a)
        a[:n0 + 1, :n0 + 1, 0] = pa[:n0 + 1, :n0 + 1, f]
        b[:n0 + 1, :n0 + 1, 0] = pb[:n0 + 1, :n0 + 1, f]
        for k in range(nl):
            n = int(so[k])
            a[:n + 1, :n + 1, k + 1] = sa[:n + 1, :n + 1, k]
            b[:n + 1, :n + 1, k + 1] = sb[:n + 1, :n + 1, k]
        orders = np.concatenate([[n0], so]).astype(np.int32)
        bounds = np.concatenate([pbounds[:, [f]], sbd], axis=1)
        return a, b, orders, bounds

    def _build_shells(self, keys) -> None:
        """Build the shells of the keys (form, distances in shape units) not in the cache."""
        m = self.model
        todo = sorted({k for k in keys if k not in self._shell_cache})
        if not todo:
            return
        f = np.array([k[0] for k in todo])
        th = np.array([k[1] for k in todo])
        lmax_s = int(min(119, max(24, 2 * self._pairs[f, 1].max())))
        sa, sb, so, sbd = kernels.shell_forms(m.shape_coeffs, m.shape_nmax, self._pairs[f, 0], self._pairs[f, 1],
                                              th, lmax_s)
        for j, key in enumerate(todo):
            self._shell_cache[key] = (sa[:, :, :, j], sb[:, :, :, j], so[:, j], sbd[:, :, j])

    def _shell_shape_units(self, ids: np.ndarray) -> np.ndarray:
        """Cumulative layer distances (len(ids), nlayer) in shape units, quantised for mm."""
        spec = self.shells
        if spec.from_model:
            # the engine's own values (mm): one conversion, no second rounding
            return self.model.shell_thickness[ids] / self.model.scale[ids][:, None]
        t = np.asarray(spec.thickness, float)
        if spec.unit == "fraction":
            return self.lengths()[self._form[ids]][:, None] * t[None, :]
        ts = t[None, :] / self.model.scale[ids][:, None]
        q = np.log1p(spec.step)
        return np.exp(np.round(np.log(ts) / q) * q)

    # -- slicing ------------------------------------------------------------------------------
    def _near(self, planes: Sequence[Plane], reach: np.ndarray) -> np.ndarray:
        """Particles whose bounding sphere (radius reach) comes within reach of any plane (any image)."""
        m = self.model
        shifts = np.array([[i, j, k] for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)], float) * m.box \
            if m.periodic else np.zeros((1, 3))
        near = np.zeros(m.n_particles, bool)
        for p in planes:
            d = (m.center[:, None, :] + shifts[None, :, :] - np.asarray(p.origin)) @ p.normal
            near |= np.min(np.abs(d), axis=1) <= reach
        return near

    def slice_many(self, planes: Sequence[Plane]) -> list[SliceResult]:
        """Label several planes of equal pixel counts in one kernel call."""
        m = self.model
        planes = list(planes)
        if not planes:
            return []
        if len({(p.shape, p.pixel) for p in planes}) != 1:
            raise AnmPostError("planes of one call must have the same pixel size and counts")
        a, b, bounds = self._particle_forms()
        orders = self._pairs[:, 1].astype(np.int32)
        form = self._form + 1
        nlayer = 0 if self.shells is None else len(self.shells.thickness)
        shell_form = np.zeros((m.n_particles, nlayer), np.int32)
        if nlayer:
            a, b, bounds, orders, shell_form = self._add_shells(planes, a, b, bounds, orders, shell_form)
        p0 = planes[0]
        nv, nu = p0.shape
        part, lay, own, stats = kernels.slice_labels(
            a, b, orders, bounds, form, shell_form, m.center, m.rotation, m.scale, m.box, m.periodic,
            np.array([p.origin for p in planes]), np.array([p.u for p in planes]), np.array([p.v for p in planes]),
            nu, nv, p0.pixel)
        names = ("queried", "candidates", "tests", "evaluations")
        out = []
        for k, p in enumerate(planes):
            pid = part[k].astype(np.int64) - 1
            sieve = np.where(pid >= 0, m.sieve[np.maximum(pid, 0)], -1)
            out.append(SliceResult(p, pid, lay[k].astype(np.int32), own[k].astype(np.int64) - 1, sieve,
                                   dict(zip(names, (stats / len(planes)).tolist()))))
        return out

    def slice(self, plane: Plane) -> SliceResult:
        """Label one plane."""
        return self.slice_many([plane])[0]

    def stack(self, axis: str | int, pixel: float, density: float, chunk: int = 8) -> Iterator[SliceResult]:
        """Parallel axis-normal slices over the whole box at slice density rho_s (thesis Eqs 3.3-3.4),
        yielded one by one (computed `chunk` planes per kernel call)."""
        k = _AXES.get(axis, axis) if isinstance(axis, str) else int(axis)
        if k not in (0, 1, 2):
            raise AnmPostError(f"axis must be x, y or z, got {axis!r}")
        pos = stack_positions(0.0, float(self.model.box[k]), pixel, density)
        planes = [axis_plane(self.model, k, float(x), pixel) for x in pos]
        for i in range(0, len(planes), chunk):
            yield from self.slice_many(planes[i:i + chunk])

    def _add_shells(self, planes, a, b, bounds, orders, shell_form):
        """Build (or reuse) the shells of the particles that can reach the planes; append them as forms."""
        m = self.model
        spec = self.shells
        ids = np.arange(m.n_particles) if spec.particles is None else np.unique(np.asarray(spec.particles))
        # reach of a shelled particle: particle bound + outermost distance (+ margin for the fit)
        pb = self._particle_forms()[2]
        tsu = self._shell_shape_units(ids)
        reach = np.zeros(m.n_particles)
        reach[ids] = m.scale[ids] * (pb[1, self._form[ids]] + 1.5 * tsu[:, -1]) + 1e-9
        near = self._near(planes, reach)
        sel = ids[near[ids]]
        tsu = tsu[near[ids]]
        if sel.size == 0:
            return a, b, bounds, orders, shell_form
        keys = [(int(self._form[i]), tuple(np.round(t, 12))) for i, t in zip(sel, tsu)]
        self._build_shells(keys)
        used = sorted(set(keys))
        nlayer = shell_form.shape[1]
        lmax = max(a.shape[0] - 1, max(int(self._shell_cache[k][2].max()) for k in used))
        nform0 = a.shape[2]
        nnew = len(used) * nlayer
        A = np.zeros((lmax + 1, lmax + 1, nform0 + nnew), order="F")
        B = np.zeros_like(A)
        A[:a.shape[0], :a.shape[1], :nform0] = a
        B[:b.shape[0], :b.shape[1], :nform0] = b
        O = np.concatenate([orders, np.zeros(nnew, np.int32)])
        BD = np.concatenate([bounds, np.zeros((8, nnew))], axis=1)
        index = {}
        for j, key in enumerate(used):
            sa, sb, so, sbd = self._shell_cache[key]
            for layer in range(nlayer):
                col = nform0 + j * nlayer + layer
                n = int(so[layer])
                A[:n + 1, :n + 1, col] = sa[:n + 1, :n + 1, layer]
                B[:n + 1, :n + 1, col] = sb[:n + 1, :n + 1, layer]
                O[col] = n
                BD[:, col] = sbd[:, layer]
            index[key] = nform0 + j * nlayer + 1
        for i, key in zip(sel, keys):
            shell_form[i, :] = index[key] + np.arange(nlayer)
        return A, B, BD, O, shell_form

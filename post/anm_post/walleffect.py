"""The wall effect g(t) around one coarse aggregate (thesis section 3.4, Eqs 3.1-3.11).

K uniform-thickness shells are grown around the RDF particle (default: the longest particle) with
cumulative outer distances t_1 < ... < t_K from its surface (default 10 values spaced linearly from
0.5 % to 5 % of its length). Layer k is the region between shells k-1 and k (layer 1: between the
particle surface and shell 1), never inside the RDF particle. Parallel slices normal to an axis
cross the particle's outer-shell extent at slice density rho_s (Eqs 3.3-3.4); in slice i the
pixels of layer k are the mask A_ik and those of them inside a small particle (a chosen set of
sieves) A_ik^s. The small-particle fraction of layer k (Eq 3.10) and g (Eq 3.11) are

    phi_k = sum_i A_ik^s / sum_i A_ik,      g_k = phi_k / phi_B,
    phi_B = V_s / (V_Omega - V_a)           (Eq 3.6; V_a: volume of all particles not small).

Per-slice values g_ik = A_ik^s / (A_ik phi_B) over the slices that cut layer k give the mean and
standard deviation plotted as error bars (Fig 3.8); the standard error of g_k is that of a ratio
estimator over blocks of consecutive slices spanning the widest small particle (closer slices cut
the same particles and are not independent). `volume_fractions` measures phi_k directly in the
volume (a stratified random sample of each layer with the slicer's own surfaces, no slices; its
standard error from independent replicates), so Eq 3.11 can be checked numerically.

Library API:
    spec = RdfSpec(particle=None, n_shells=10, t_min=0.005, t_max=0.05, unit="fraction", axis="x",
                   pixel=0.05, density=1.0, small_sieves=None, small_below=None, phi_b=None)
    st = prepare(model, spec)                    # shared by the calls below (optional)
    res = rdf(model, spec, setup=st)             # RdfResult (per layer: t, g, mean, sd, se, counts)
    vol = volume_fractions(model, spec, spacing=0.05, replicates=8, setup=st)   # 3D phi_k, its s.e.
    res.to_csv("g.csv", vol); plot_rdf(res, "g.png", volume=vol)
    conv = convergence(model, spec, densities=(0.05, 0.1, 0.25, 0.5, 1.0), setup=st)
"""
from __future__ import annotations

import csv
import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from . import kernels
from .errors import AnmPostError
from .model import Model
from .slicing import Plane, ShellSpec, Slicer, stack_positions, _AXES


@dataclass(frozen=True)
class RdfSpec:
    """What to measure. particle: 0-based id of the RDF particle; width or length (mm): the particle
    of the nearest width or length instead (the thesis chose its RDF particle by size, section 3.4);
    none of the three: the longest particle;
    n_shells, t_min, t_max: K shells with outer distances linear from t_min to t_max, in `unit`
    ("fraction" of the RDF particle's length, or "mm"); axis, pixel (R_s, mm), density (rho_s):
    the slices; small_sieves: 0-based sieves counted as small particles, or small_below: every
    sieve whose max width is <= this (mm); neither: the sieve of smallest max width. phi_b: bulk
    fraction to divide by (None: Eq 3.6 from the particle volumes)."""

    particle: int | None = None
    width: float | None = None
    length: float | None = None
    n_shells: int = 10
    t_min: float = 0.005
    t_max: float = 0.05
    unit: str = "fraction"
    axis: str = "x"
    pixel: float = 0.05
    density: float = 1.0
    small_sieves: tuple[int, ...] | None = None
    small_below: float | None = None
    phi_b: float | None = None

    def __post_init__(self) -> None:
        if sum(x is not None for x in (self.particle, self.width, self.length)) > 1:
            raise AnmPostError("the RDF particle is chosen by one of id, width and length, got more than one")
        for name in ("width", "length"):
            value = getattr(self, name)
            if value is not None and not (value > 0 and np.isfinite(value)):
                raise AnmPostError(f"RDF particle {name} must be positive, got {value}")
        if self.n_shells < 1:
            raise AnmPostError(f"number of shells must be >= 1, got {self.n_shells}")
        if not (0 < self.t_min <= self.t_max) or (self.n_shells > 1 and self.t_min == self.t_max):
            raise AnmPostError(f"shell distances need 0 < t_min < t_max, got {self.t_min}, {self.t_max}")
        if self.unit not in ("fraction", "mm"):
            raise AnmPostError(f"shell unit must be 'fraction' or 'mm', got {self.unit!r}")
        if self.axis not in _AXES:
            raise AnmPostError(f"axis must be x, y or z, got {self.axis!r}")
        if not (self.pixel > 0 and np.isfinite(self.pixel)):
            raise AnmPostError(f"pixel size must be positive, got {self.pixel}")
        if not (0 < self.density <= 1):
            raise AnmPostError(f"slice density rho_s must be in (0, 1], got {self.density}")
        if self.phi_b is not None and not (0 < self.phi_b <= 1):
            raise AnmPostError(f"bulk fraction phi_B must be in (0, 1], got {self.phi_b}")


@dataclass
class RdfResult:
    """g(t) per layer. t_inner, t_outer: layer bounds (mm from the surface); phi: Eq 3.10; g: Eq
    3.11; g_mean, g_sd: mean and standard deviation of the per-slice values; g_se: standard error
    of g; n_slices: slices cutting the layer; area, small: pixel counts summed over slices."""

    particle: int
    length: float
    phi_b: float
    small_sieves: tuple[int, ...]
    density: float
    pixel: float
    axis: str
    positions: np.ndarray
    t_inner: np.ndarray
    t_outer: np.ndarray
    phi: np.ndarray
    g: np.ndarray
    g_mean: np.ndarray
    g_sd: np.ndarray
    g_se: np.ndarray
    n_slices: np.ndarray
    area: np.ndarray
    small: np.ndarray
    seconds: float = 0.0
    per_slice: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 2)))

    @property
    def layer_volume(self) -> np.ndarray:
        """The slices' estimate of each layer's volume (mm^3): its pixels times R_s^2 times the
        slice spacing."""
        gap = float(self.positions[1] - self.positions[0]) if len(self.positions) > 1 else np.nan
        return self.area * self.pixel ** 2 * gap

    @property
    def t_mid(self) -> np.ndarray:
        """Layer mid distances (mm)."""
        return 0.5 * (self.t_inner + self.t_outer)

    def rows(self) -> list[dict[str, float]]:
        """One dict per layer (the CSV columns)."""
        return [dict(layer=k + 1, t_inner_mm=self.t_inner[k], t_outer_mm=self.t_outer[k], phi=self.phi[k],
                     g=self.g[k], g_mean=self.g_mean[k], g_sd=self.g_sd[k], g_se=self.g_se[k],
                     n_slices=int(self.n_slices[k]), area_px=int(self.area[k]), small_px=int(self.small[k]))
                for k in range(len(self.g))]

    def to_csv(self, path: str | Path, volume: "VolumeResult | None" = None) -> Path:
        """Write the per-layer table (with the 3D columns when `volume` is given)."""
        rows = self.rows()
        if volume is not None:
            for r, pv, se, v, vse, vs in zip(rows, volume.phi, volume.phi_se, volume.volume, volume.volume_se,
                                             self.layer_volume):
                r.update(phi_3d=pv, g_3d=pv / self.phi_b, g_3d_se=se / self.phi_b,
                         diff_per_se=(r["g"] - pv / self.phi_b) / r["g_se"], volume_slices_mm3=vs,
                         volume_3d_mm3=v, volume_3d_se_mm3=vse)
        return _write_csv(path, rows, "--csv")


@dataclass
class VolumeResult:
    """Small-particle fraction of each layer measured in the volume (`volume_fractions`): phi and
    its standard error phi_se (from independent replicates), the layer volumes (mm^3) and their
    standard error, the sample's replicates, spacing (mm), strata (n_z, n_phi, radial strata per
    layer), points drawn in all and phi of each replicate (replicates, K)."""

    phi: np.ndarray
    phi_se: np.ndarray
    volume: np.ndarray
    volume_se: np.ndarray
    replicates: int
    spacing: float
    strata: tuple
    n_points: int
    per_replicate: np.ndarray
    seconds: float = 0.0


def _write_csv(path: str | Path, rows: list[dict], option: str) -> Path:
    from .output import atomic_open
    path = Path(path)
    with atomic_open(path, option, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    return path


# -- model quantities ------------------------------------------------------------------------
def particle_lengths(model: Model, slicer: Slicer | None = None) -> np.ndarray:
    """Length L (mm) of every particle."""
    slicer = slicer or Slicer(model)
    return slicer.lengths()[slicer.particle_form_ids()] * model.scale


def particle_volumes(model: Model, slicer: Slicer | None = None) -> np.ndarray:
    """Volume (mm^3) of every particle (its expansion at the order used)."""
    slicer = slicer or Slicer(model)
    return slicer.geometry()[slicer.particle_form_ids(), kernels.GEOMETRY_COLUMNS.index("volume")] * model.scale ** 3


def small_sieves(model: Model, spec: RdfSpec) -> tuple[int, ...]:
    """The sieves counted as small particles (see RdfSpec)."""
    ns = model.n_sieves
    if spec.small_sieves is not None:
        s = tuple(sorted(set(int(k) for k in spec.small_sieves)))
        if not s or min(s) < 0 or max(s) >= ns:
            raise AnmPostError(f"small sieves must be in 0..{ns - 1}, got {list(spec.small_sieves)}")
        return s
    wmax = np.asarray(model.sieves["max_width"], float)
    if spec.small_below is not None:
        s = tuple(int(k) for k in np.flatnonzero(wmax <= spec.small_below))
        if not s:
            raise AnmPostError(f"no sieve has max width <= {spec.small_below} mm (widths {wmax.tolist()})")
        return s
    return (int(np.argmin(wmax)),)


def bulk_fraction(model: Model, small: Sequence[int], volumes: np.ndarray | None = None) -> float:
    """Thesis Eq 3.6: phi_B = V_s / (V_Omega - V_a), V_s the small particles' volume, V_a that of the others."""
    vol = particle_volumes(model) if volumes is None else volumes
    is_small = np.isin(model.sieve, np.asarray(small))
    vs, va = float(vol[is_small].sum()), float(vol[~is_small].sum())
    if vs <= 0 or model.volume - va <= 0:
        raise AnmPostError(f"{model.path}: bulk fraction undefined (V_s = {vs:.4g}, V_Omega - V_a = "
                           f"{model.volume - va:.4g} mm^3)")
    return vs / (model.volume - va)


def _fibonacci(n: int) -> np.ndarray:
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = k * np.pi * (3 - np.sqrt(5))
    s = np.sqrt(1 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


def particle_extent(model: Model, pid: int, n_dirs: int = 6000) -> tuple[np.ndarray, np.ndarray]:
    """World bounding box (lo, hi) of particle pid from its surface along n_dirs directions."""
    d = _fibonacci(n_dirs)
    r = kernels.sh_radius(model.shape_coeffs, model.shape_nmax, int(model.shape[pid]), int(model.nmax[pid]), d)
    pts = model.center[pid] + model.scale[pid] * (d * r[:, None]) @ model.rotation[pid].T
    return pts.min(axis=0), pts.max(axis=0)


# -- the measurement ---------------------------------------------------------------------------
@dataclass
class RdfSetup:
    """What `rdf`, `convergence` and `volume_fractions` share for one model and RdfSpec (made by
    `prepare`): the RDF particle pid, its length (mm), the shell distances t_mm, the small sieves,
    phi_B, a Slicer of the whole model (full), one of the RDF particle alone with its shells (own:
    the masks), the sampled box [lo, hi] and the widest small particle (mm)."""

    pid: int
    length: float
    t_mm: np.ndarray
    small: tuple[int, ...]
    phi_b: float
    full: Slicer
    own: Slicer
    lo: np.ndarray
    hi: np.ndarray
    width: float


def particle_widths(model: Model, slicer: Slicer | None = None) -> np.ndarray:
    """Width W (mm) of every particle (the thesis' sieve size: the longest extent perpendicular to
    the length)."""
    slicer = slicer or Slicer(model)
    return slicer.geometry()[slicer.particle_form_ids(), kernels.GEOMETRY_COLUMNS.index("width")] * model.scale


def choose_particle(model: Model, spec: RdfSpec, slicer: Slicer | None = None) -> int:
    """The RDF particle of `spec`: its id, the particle (outside the small sieves) whose width or
    length is nearest the one asked for (ties: the lowest id), or the longest particle."""
    slicer = slicer or Slicer(model)
    if spec.particle is not None:
        return int(spec.particle)
    lengths = particle_lengths(model, slicer)
    if spec.width is None and spec.length is None:
        return int(np.argmax(lengths))
    size = particle_widths(model, slicer) if spec.width is not None else lengths
    wanted = spec.width if spec.width is not None else spec.length
    small = small_sieves(model, spec)
    cand = np.flatnonzero(~np.isin(model.sieve, small))
    if cand.size == 0:
        raise AnmPostError("no particle outside the small-particle sieves to choose the RDF particle from")
    return int(cand[np.argmin(np.abs(size[cand] - wanted))])


def prepare(model: Model, spec: RdfSpec) -> RdfSetup:
    """The RDF particle, its shells, phi_B and the two slicers (computed once; pass the result as
    `setup=` to rdf, convergence and volume_fractions of the same model and spec)."""
    full = Slicer(model)
    lengths = particle_lengths(model, full)
    pid = choose_particle(model, spec, full)
    if not (0 <= pid < model.n_particles):
        raise AnmPostError(f"RDF particle id must be in 0..{model.n_particles - 1}, got {spec.particle}")
    length = float(lengths[pid])
    t = np.linspace(spec.t_min, spec.t_max, spec.n_shells)
    t_mm = t * length if spec.unit == "fraction" else t
    small = small_sieves(model, spec)
    if model.sieve[pid] in small:
        raise AnmPostError(f"the RDF particle {pid} belongs to a small-particle sieve ({model.sieve[pid]})")
    phi_b = spec.phi_b if spec.phi_b is not None else bulk_fraction(model, small, particle_volumes(model, full))
    # the RDF particle alone, with its shells (fraction unit: exact distances, no quantisation)
    one = dataclasses.replace(
        model, shape=model.shape[[pid]], center=model.center[[pid]], rotation=model.rotation[[pid]],
        scale=model.scale[[pid]], nmax=model.nmax[[pid]], sieve=model.sieve[[pid]],
        shell_thickness=np.zeros((1, 0)))
    own = Slicer(one, ShellSpec(tuple(t_mm / length), unit="fraction", particles=(0,)))
    lo, hi = particle_extent(model, pid)
    margin = t_mm[-1] + 0.01 * length + 2 * spec.pixel
    width = float(np.max(np.asarray(model.sieves["max_width"], float)[list(small)]))
    return RdfSetup(pid, length, t_mm, small, float(phi_b), full, own, lo - margin, hi + margin, width)


def _planes(st: RdfSetup, spec: RdfSpec, density: float) -> list[Plane]:
    k = _AXES[spec.axis]
    iu, iv = [d for d in range(3) if d != k]
    eye = np.eye(3)
    pos = stack_positions(float(st.lo[k]), float(st.hi[k]), spec.pixel, density)
    size = (float(st.hi[iu] - st.lo[iu]), float(st.hi[iv] - st.lo[iv]))
    out = []
    for x in pos:
        o = st.lo.copy()
        o[k] = x
        out.append(Plane(tuple(o), tuple(eye[iu]), tuple(eye[iv]), size, spec.pixel))
    return out


def _count(st: RdfSetup, planes: list[Plane], chunk: int = 16, progress=None) -> np.ndarray:
    """Pixel counts (nslice, K, 2): layer area, small-particle pixels in it. `progress(done, total)`
    is called after each chunk of slices when given."""
    K = len(st.t_mm)
    small_lut = np.zeros(st.full.model.n_sieves + 1, bool)
    small_lut[np.asarray(st.small)] = True
    out = np.zeros((len(planes), K, 2), np.int64)
    for i in range(0, len(planes), chunk):
        batch = planes[i:i + chunk]
        masks = st.own.slice_many(batch)
        labels = st.full.slice_many(batch)
        for j, (mk, lb) in enumerate(zip(masks, labels)):
            lay = mk.layer.ravel()
            is_small = small_lut[lb.sieve.ravel()]     # sieve -1 -> last entry (False)
            out[i + j, :, 0] = np.bincount(lay, minlength=K + 1)[1:K + 1]
            out[i + j, :, 1] = np.bincount(lay[is_small], minlength=K + 1)[1:K + 1]
        if progress:
            progress(min(i + chunk, len(planes)), len(planes))
    return out


def _summarise(counts: np.ndarray, phi_b: float, block: int = 1) -> dict[str, np.ndarray]:
    """Eq 3.10/3.11 and the per-slice statistics from counts (nslice, K, 2). The standard error of
    g is that of a ratio estimator over blocks of `block` consecutive slices (slices closer than a
    small particle's width see the same particles, so single slices are not independent)."""
    area, small = counts[:, :, 0].astype(float), counts[:, :, 1].astype(float)
    A, S = area.sum(axis=0), small.sum(axis=0)
    K = counts.shape[1]
    phi = np.where(A > 0, S / np.maximum(A, 1), np.nan)
    mean, sd, se, n = (np.full(K, np.nan) for _ in range(4))
    nb = -(-len(counts) // block)
    edges = np.arange(nb) * block
    barea, bsmall = np.add.reduceat(area, edges, axis=0), np.add.reduceat(small, edges, axis=0)
    for k in range(K):
        ok = area[:, k] > 0
        n[k] = ok.sum()
        if n[k] == 0:
            continue
        gi = small[ok, k] / area[ok, k] / phi_b
        mean[k] = gi.mean()
        if n[k] > 1:
            sd[k] = gi.std(ddof=1)
        bok = barea[:, k] > 0
        m = bok.sum()
        if m > 1:
            resid = bsmall[bok, k] - phi[k] * barea[bok, k]
            se[k] = np.sqrt(np.sum(resid ** 2) / (m * (m - 1))) / barea[bok, k].mean() / phi_b
    return dict(phi=phi, g=phi / phi_b, g_mean=mean, g_sd=sd, g_se=se, n_slices=n, area=A, small=S)


def _block(st: "RdfSetup", planes: list[Plane], axis: str) -> int:
    """Slices per block for the standard error: enough to span the widest small particle."""
    if len(planes) < 2:
        return 1
    k = _AXES[axis]
    spacing = abs(planes[1].origin[k] - planes[0].origin[k])
    return max(1, int(np.ceil(st.width / spacing - 1e-9)))


def rdf(model: Model, spec: RdfSpec = RdfSpec(), setup: RdfSetup | None = None, progress=None) -> RdfResult:
    """g(t) of thesis section 3.4 from slices (see the module docstring); `progress(done, total)`
    after each chunk of slices when given."""
    t0 = time.perf_counter()
    st = setup or prepare(model, spec)
    planes = _planes(st, spec, spec.density)
    counts = _count(st, planes, progress=progress)
    s = _summarise(counts, st.phi_b, _block(st, planes, spec.axis))
    k = _AXES[spec.axis]
    t_in = np.concatenate([[0.0], st.t_mm[:-1]])
    return RdfResult(particle=st.pid, length=st.length, phi_b=st.phi_b, small_sieves=st.small, density=spec.density,
                     pixel=spec.pixel, axis=spec.axis, positions=np.array([p.origin[k] for p in planes]),
                     t_inner=t_in, t_outer=st.t_mm.copy(), seconds=time.perf_counter() - t0, per_slice=counts,
                     **{key: np.asarray(v) for key, v in s.items()})


def legendre_table(order: int, x: np.ndarray) -> np.ndarray:
    """Pbar_n^m(x) (order+1, order+1, len(x)) indexed [n, m]: orthonormal on the sphere with the
    Condon-Shortley phase (Y_n^m = Pbar_n^m(cos theta) e^{i m phi}, scipy's sph_harm_y), by the
    standard sectoral and column recursions (fine for the orders used, <= ~60)."""
    x = np.asarray(x, float)
    sq = np.sqrt(np.maximum(0.0, 1.0 - x * x))
    p = np.zeros((order + 1, order + 1, x.size))
    p[0, 0] = np.sqrt(1.0 / (4 * np.pi))
    for m in range(1, order + 1):
        p[m, m] = -np.sqrt((2 * m + 1) / (2 * m)) * sq * p[m - 1, m - 1]
    for m in range(order):
        p[m + 1, m] = np.sqrt(2 * m + 3) * x * p[m, m]
        for n in range(m + 2, order + 1):
            a = np.sqrt((4 * n * n - 1) / (n * n - m * m))
            b = np.sqrt(((n - 1) ** 2 - m * m) / (4 * (n - 1) ** 2 - 1))
            p[n, m] = a * (x * p[n - 1, m] - b * p[n - 2, m])
    return p


def form_radius(a: np.ndarray, b: np.ndarray, order: int, dirs: np.ndarray) -> np.ndarray:
    """r(d) of a real-form expansion r = sum_n sum_m Pbar_n^m(cos theta) (A_nm cos m phi + B_nm sin m phi)
    (the kernels' convention) along unit body-frame directions dirs (n, 3); a, b indexed [n, m].
    Plain numpy, independent of the kernels."""
    dirs = np.atleast_2d(dirs)
    p = legendre_table(order, np.clip(dirs[:, 2], -1.0, 1.0))
    phi = np.arctan2(dirs[:, 1], dirs[:, 0])
    m = np.arange(order + 1)
    cm, sm = np.cos(m[:, None] * phi[None, :]), np.sin(m[:, None] * phi[None, :])
    am, bm = a[:order + 1, :order + 1], b[:order + 1, :order + 1]
    # sum over n for each m, then over m
    ca = np.einsum("nm,nmk->mk", am, p)
    cb = np.einsum("nm,nmk->mk", bm, p)
    return np.sum(ca * cm + cb * sm, axis=0)


def _layer_sampling(spacing: float, r_eff: float, thickness: np.ndarray) -> tuple[int, int, np.ndarray]:
    """Strata of the volume sample: n_z polar (equal-area) and n_phi azimuthal direction strata
    whose cells are about `spacing` wide at radius r_eff (mm), and per layer the radial strata of
    about `spacing` (mm) each."""
    nz = max(4, int(np.ceil(2 * r_eff / spacing)))
    nphi = max(8, int(round(np.pi * nz)))
    nt = np.maximum(1, np.round(np.asarray(thickness) / spacing)).astype(int)
    return nz, nphi, nt


def volume_fractions(model: Model, spec: RdfSpec = RdfSpec(), spacing: float | None = None, replicates: int = 8,
                     seed: int = 1, setup: "RdfSetup | None" = None) -> VolumeResult:
    """Small-particle fraction of each layer measured directly in the volume, without slices.

    The layers are the slicer's own surfaces (the RDF particle and its K shell surfaces, star-shaped
    about the particle centre), so in body-frame spherical coordinates layer k along direction u is
    the radial interval a_k(u) < r <= b_k(u), a_k = max(r_0..r_{k-1}), b_k = r_k (the labelling
    rule of the slices: the first layer whose surface contains the point). With s = r^3 / 3 the
    volume element is ds dOmega, so a point uniform in the layer is (u uniform on the sphere, s
    uniform in [a^3/3, b^3/3]) with weight (b^3 - a^3)/3 per unit solid angle. The sample is
    stratified (jittered): z = cos(theta) in n_z strata and phi in n_phi strata (equal-area cells
    about `spacing` mm wide at the layers; default: the pixel size of spec), one random direction
    per cell, and per layer round(thickness / spacing) radial strata of s with one random point
    each. A point counts as small when a particle of the small sieves contains it (the Fortran
    point labels, anm_slicing_points: cell list and point-in-particle test, no planes).

    phi_k = sum(w * small) / sum(w) per replicate; `replicates` independent randomisations give
    the mean and its standard error (replicate s.d. / sqrt(replicates)), and the layer volumes
    sum(w) (mm^3) likewise. Tests Eq 3.11: at rho_s = 1 the slices must give the same phi_k."""
    if replicates < 2:
        raise AnmPostError(f"number of replicates must be >= 2 (for a standard error), got {replicates}")
    t0 = time.perf_counter()
    st = setup or prepare(model, spec)
    h = float(spec.pixel if spacing is None else spacing)
    if not (h > 0 and np.isfinite(h)):
        raise AnmPostError(f"volume sample spacing must be positive, got {spacing}")
    K = len(st.t_mm)
    pid = st.pid
    a, b, orders, _ = st.own.layer_forms(0)
    rot, c, s = model.rotation[pid], model.center[pid], float(model.scale[pid])
    r_eff = float(np.sqrt(np.mean(kernels.form_radii(a, b, orders, _fibonacci(4000))[:, K] ** 2))) * s
    nz, nphi, nt = _layer_sampling(h, r_eff, np.diff(np.concatenate([[0.0], st.t_mm])))
    # the small particles and their forms (those of the full model)
    full = st.full
    pa, pb, pbounds = full._particle_forms()
    ids = np.flatnonzero(np.isin(model.sieve, np.asarray(st.small)))
    porder = full._pairs[:, 1].astype(np.int32)
    pform = full._form[ids] + 1
    cell = 4 * np.pi / (nz * nphi)
    W = np.zeros((replicates, K))
    S = np.zeros((replicates, K))
    npts = 0
    block = max(1, 1_000_000 // (nphi * int(nt.sum())))          # polar strata per batch of points
    for rep in range(replicates):
        rng = np.random.default_rng([int(seed), rep])
        for i0 in range(0, nz, block):
            iz = np.arange(i0, min(nz, i0 + block))
            z = -1 + (iz[:, None] + rng.random((len(iz), nphi))) * (2.0 / nz)
            ph = (np.arange(nphi)[None, :] + rng.random((len(iz), nphi))) * (2 * np.pi / nphi)
            z, ph = z.ravel(), ph.ravel()
            sz = np.sqrt(np.maximum(0.0, 1 - z * z))
            u = np.stack([sz * np.cos(ph), sz * np.sin(ph), z], axis=1)
            R = kernels.form_radii(a, b, orders, u)               # (ndir, 1 + K), shape units
            inner = np.maximum.accumulate(R, axis=1)              # a_k = max(r_0 .. r_{k-1}) in column k - 1
            pts, wts, lay = [], [], []
            for k in range(1, K + 1):
                s_lo = inner[:, k - 1] ** 3 / 3
                ds = np.maximum(0.0, R[:, k] ** 3 / 3 - s_lo)
                keep = np.flatnonzero(ds > 0)
                for l in range(nt[k - 1]):
                    tau = (l + rng.random(keep.size)) / nt[k - 1]
                    r = np.cbrt(3 * (s_lo[keep] + tau * ds[keep]))
                    pts.append(u[keep] * r[:, None])
                    wts.append(ds[keep] * (cell / nt[k - 1]))
                    lay.append(np.full(keep.size, k - 1))
            y = np.concatenate(pts)
            x = c + s * (y @ rot.T)
            lab = kernels.point_labels(pa, pb, porder, pbounds, pform, model.center[ids], model.rotation[ids],
                                       model.scale[ids], model.box, model.periodic, x)
            w, k = np.concatenate(wts), np.concatenate(lay)
            W[rep] += np.bincount(k, weights=w, minlength=K)
            S[rep] += np.bincount(k, weights=w * (lab > 0), minlength=K)
            npts += len(x)
    phi_r = S / np.where(W > 0, W, np.nan)
    vol_r = W * s ** 3
    sq = np.sqrt(replicates)
    return VolumeResult(phi=phi_r.mean(axis=0), phi_se=phi_r.std(axis=0, ddof=1) / sq,
                        volume=vol_r.mean(axis=0), volume_se=vol_r.std(axis=0, ddof=1) / sq, replicates=replicates,
                        spacing=h, strata=(nz, nphi, tuple(int(v) for v in nt)), n_points=npts,
                        per_replicate=phi_r, seconds=time.perf_counter() - t0)


# -- convergence in rho_s ----------------------------------------------------------------------
@dataclass
class ConvergenceResult:
    """g and its spread against the slice density: one RdfResult per density (same particle,
    shells and pixel)."""

    densities: np.ndarray
    results: list[RdfResult]

    def rows(self) -> list[dict[str, float]]:
        """One row per (density, layer)."""
        out = []
        for d, r in zip(self.densities, self.results):
            for row in r.rows():
                out.append(dict(density=float(d), n=len(r.positions), **row))
        return out

    def to_csv(self, path: str | Path) -> Path:
        """Write rows() as CSV."""
        return _write_csv(path, self.rows(), "--csv")


def convergence(model: Model, spec: RdfSpec = RdfSpec(),
                densities: Sequence[float] = (0.01, 0.05, 0.1, 0.25, 0.5, 1.0),
                setup: RdfSetup | None = None, progress=None) -> ConvergenceResult:
    """g(t) at several slice densities (thesis Figs 3.9, 3.10, 3.12, 3.13). The slices of every
    density are a subset of the union labelled once: each plane is labelled once even when several
    densities use it."""
    dens = np.asarray(sorted(set(float(d) for d in densities)))
    if dens.size == 0 or dens[0] <= 0 or dens[-1] > 1:
        raise AnmPostError(f"slice densities must be in (0, 1], got {list(densities)}")
    t0 = time.perf_counter()
    st = setup or prepare(model, spec)
    per = [_planes(st, spec, float(d)) for d in dens]
    key = {}
    for planes in per:
        for p in planes:
            key.setdefault(round(p.origin[_AXES[spec.axis]], 9), p)
    uniq = list(key.values())
    counts = _count(st, uniq, progress=progress)
    index = {k: i for i, k in enumerate(key)}
    k = _AXES[spec.axis]
    t_in = np.concatenate([[0.0], st.t_mm[:-1]])
    results = []
    for d, planes in zip(dens, per):
        c = counts[[index[round(p.origin[k], 9)] for p in planes]]
        s = _summarise(c, st.phi_b, _block(st, planes, spec.axis))
        results.append(RdfResult(particle=st.pid, length=st.length, phi_b=st.phi_b, small_sieves=st.small,
                                 density=float(d), pixel=spec.pixel, axis=spec.axis,
                                 positions=np.array([p.origin[k] for p in planes]), t_inner=t_in,
                                 t_outer=st.t_mm.copy(), per_slice=c, **{kk: np.asarray(v) for kk, v in s.items()}))
    elapsed = time.perf_counter() - t0
    for r in results:
        r.seconds = elapsed
    return ConvergenceResult(dens, results)


# -- plots -------------------------------------------------------------------------------------
def _figure():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _save(fig, plt, path: str | Path, option: str) -> Path:
    from .output import save_figure
    try:
        return save_figure(fig, path, option, dpi=150)
    finally:
        plt.close(fig)


def plot_rdf(res: RdfResult, path: str | Path, volume: VolumeResult | None = None, title: str = "") -> Path:
    """Bar plot of g per layer (bar width = layer thickness) with the per-slice standard deviation as
    error bars (thesis Fig 3.8); g = 1 dashed. With the 3D values (volume_fractions) they are drawn
    as points, and a second panel shows the check of Eq 3.11: g_slices - g_3D per layer against
    the slices' standard error (band) with the 3D standard error as error bars."""
    plt = _figure()
    if volume is None:
        fig, ax = plt.subplots(figsize=(6.4, 4))
    else:
        fig, (ax, ax2) = plt.subplots(2, 1, figsize=(6.4, 6.4), sharex=True, height_ratios=(2, 1))
    width = res.t_outer - res.t_inner
    ax.bar(res.t_inner, res.g, width=width, align="edge", color="#9ecae1", edgecolor="#3182bd",
           label=f"slices (rho_s = {res.density:g}, N = {len(res.positions)})")
    ax.errorbar(res.t_mid, res.g, yerr=res.g_sd, fmt="none", ecolor="#08306b", capsize=3, label="per-slice s.d.")
    if volume is not None:
        g3, se3 = volume.phi / res.phi_b, volume.phi_se / res.phi_b
        ax.errorbar(res.t_mid, g3, yerr=se3, fmt="o", ms=4, color="#d62728", capsize=2,
                    label="3D (volume sample, no slices)")
        edges = np.concatenate([res.t_inner, res.t_outer[-1:]])
        se = np.concatenate([res.g_se, res.g_se[-1:]])
        ax2.fill_between(edges, -se, se, step="post", color="#9ecae1", alpha=0.6,
                         label="+- standard error of the slice estimate")
        ax2.errorbar(res.t_mid, res.g - g3, yerr=se3, fmt="o", ms=4, color="#d62728", capsize=2,
                     label="g_slices - g_3D (bars: 3D standard error)")
        ax2.axhline(0.0, color="grey", lw=1)
        ax2.set_xlabel("distance t from the particle surface (mm)")
        ax2.set_ylabel("g_slices - g_3D")
        ax2.legend(fontsize=7, loc="lower left")
    else:
        ax.set_xlabel("distance t from the particle surface (mm)")
    ax.axhline(1.0, ls="--", color="grey", lw=1)
    ax.set_ylabel("g(t) = phi_shell / phi_B")
    ax.set_title(title or f"g(t) around particle {res.particle} (L = {res.length:.3g} mm, "
                          f"phi_B = {res.phi_b:.3f}, R_s = {res.pixel:g} mm)", fontsize=9)
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    return _save(fig, plt, path, "--png")


def plot_convergence(conv: ConvergenceResult, path: str | Path, layers: Sequence[int] | None = None) -> Path:
    """Two panels: g(t) per layer for each slice density (thesis Figs 3.9/3.12) and the standard
    deviation of the per-slice g against rho_s for chosen layers (1-based; Figs 3.10/3.13)."""
    plt = _figure()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    for r in conv.results:
        a1.plot(r.t_mid, r.g, marker="o", ms=3, label=f"rho_s = {r.density:g} (N = {len(r.positions)})")
    a1.axhline(1.0, ls="--", color="grey", lw=1)
    a1.set_xlabel("distance t from the particle surface (mm)")
    a1.set_ylabel("g(t)")
    a1.legend(fontsize=7)
    r0 = conv.results[0]
    K = len(r0.g)
    layers = list(layers) if layers else sorted({1, max(1, K // 3), max(1, 2 * K // 3), K})
    for k in layers:
        if not 1 <= k <= K:
            raise AnmPostError(f"layer {k} outside 1..{K} (--layers)")
        sd = [r.g_sd[k - 1] for r in conv.results]
        a2.plot(conv.densities, sd, marker="o", ms=3, label=f"t = {r0.t_mid[k - 1]:.3f} mm (layer {k})")
    a2.set_xscale("log")
    a2.set_xlabel("slice density rho_s")
    a2.set_ylabel("standard deviation of g over slices")
    a2.legend(fontsize=7)
    fig.suptitle(f"Convergence in rho_s, particle {r0.particle}, R_s = {r0.pixel:g} mm", fontsize=9)
    fig.tight_layout()
    return _save(fig, plt, path, "--png")

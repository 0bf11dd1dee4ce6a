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
the same particles and are not independent). `volume_fractions` estimates phi_k directly in the volume with
uniform Monte Carlo points (no slices), so Eq 3.11 can be checked numerically.

Library API:
    spec = RdfSpec(particle=None, n_shells=10, t_min=0.005, t_max=0.05, unit="fraction", axis="x",
                   pixel=0.05, density=1.0, small_sieves=None, small_below=None, phi_b=None)
    res = rdf(model, spec)                       # RdfResult (per layer: t, g, mean, sd, se, counts)
    vol = volume_fractions(model, spec, n_points=2_000_000, seed=1)   # 3D phi_k and its error
    res.to_csv("g.csv"); plot_rdf(res, "g.png", volume=vol)
    conv = convergence(model, spec, densities=(0.05, 0.1, 0.25, 0.5, 1.0))
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
    """What to measure. particle: 0-based id of the RDF particle (None: the longest particle);
    n_shells, t_min, t_max: K shells with outer distances linear from t_min to t_max, in `unit`
    ("fraction" of the RDF particle's length, or "mm"); axis, pixel (R_s, mm), density (rho_s):
    the slices; small_sieves: 0-based sieves counted as small particles, or small_below: every
    sieve whose max width is <= this (mm); neither: the sieve of smallest max width. phi_b: bulk
    fraction to divide by (None: Eq 3.6 from the particle volumes)."""

    particle: int | None = None
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
            for r, pv, se in zip(rows, volume.phi, volume.phi_se):
                r.update(phi_3d=pv, g_3d=pv / self.phi_b, g_3d_se=se / self.phi_b)
        return _write_csv(path, rows, "--csv")


@dataclass
class VolumeResult:
    """Small-particle fraction of each layer estimated in the volume: phi, its standard error
    phi_se (binomial), points per layer and the number of points drawn."""

    phi: np.ndarray
    phi_se: np.ndarray
    points: np.ndarray
    n_points: int
    seconds: float = 0.0


def _write_csv(path: str | Path, rows: list[dict], option: str) -> Path:
    path = Path(path)
    try:
        with open(path, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            for r in rows:
                w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    except OSError as exc:
        raise AnmPostError(f"{path}: cannot write ({option}): {exc.strerror}") from None
    return path


# -- model quantities ------------------------------------------------------------------------
def particle_lengths(model: Model, slicer: Slicer | None = None) -> np.ndarray:
    """Length L (mm) of every particle."""
    slicer = slicer or Slicer(model)
    return slicer.lengths()[slicer._form] * model.scale


def particle_volumes(model: Model, slicer: Slicer | None = None) -> np.ndarray:
    """Volume (mm^3) of every particle (its expansion at the order used)."""
    slicer = slicer or Slicer(model)
    m = model
    geo = kernels.geometry(m.shape_coeffs, m.shape_nmax, slicer._pairs[:, 0], slicer._pairs[:, 1])
    return geo[slicer._form, kernels.GEOMETRY_COLUMNS.index("volume")] * m.scale ** 3


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
class _Setup:
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


def _setup(model: Model, spec: RdfSpec) -> _Setup:
    full = Slicer(model)
    lengths = particle_lengths(model, full)
    pid = int(np.argmax(lengths)) if spec.particle is None else int(spec.particle)
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
    return _Setup(pid, length, t_mm, small, float(phi_b), full, own, lo - margin, hi + margin, width)


def _planes(st: _Setup, spec: RdfSpec, density: float) -> list[Plane]:
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


def _count(st: _Setup, planes: list[Plane], chunk: int = 8) -> np.ndarray:
    """Pixel counts (nslice, K, 2): layer area, small-particle pixels in it."""
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


def _block(st: "_Setup", planes: list[Plane], axis: str) -> int:
    """Slices per block for the standard error: enough to span the widest small particle."""
    if len(planes) < 2:
        return 1
    k = _AXES[axis]
    spacing = abs(planes[1].origin[k] - planes[0].origin[k])
    return max(1, int(np.ceil(st.width / spacing - 1e-9)))


def rdf(model: Model, spec: RdfSpec = RdfSpec()) -> RdfResult:
    """g(t) of thesis section 3.4 from slices (see the module docstring)."""
    t0 = time.perf_counter()
    st = _setup(model, spec)
    planes = _planes(st, spec, spec.density)
    counts = _count(st, planes)
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


def _small_member(model: Model, small: tuple[int, ...], pts: np.ndarray, cache: dict) -> np.ndarray:
    """Whether each point lies in a particle of the small sieves: cKDTree of their centres (periodic
    when the box is), then |y| <= r(y/|y|) with the model's complex coefficients (kernels.sh_radius)."""
    from scipy.spatial import cKDTree

    if "tree" not in cache:
        ids = np.flatnonzero(np.isin(model.sieve, np.asarray(small)))
        slicer = Slicer(model)
        pb = kernels.geometry(model.shape_coeffs, model.shape_nmax, slicer._pairs[:, 0], slicer._pairs[:, 1])
        rmax = pb[slicer._form[ids], kernels.GEOMETRY_COLUMNS.index("rmax")] * model.scale[ids]
        c = model.center[ids]
        if model.periodic:
            c = np.mod(c, model.box)
            c = np.minimum(c, np.nextafter(model.box, 0))
        cache.update(ids=ids, rmax=rmax, reach=float(rmax.max()) * 1.01,
                     tree=cKDTree(c, boxsize=model.box if model.periodic else None))
    ids, rmax, tree = cache["ids"], cache["rmax"], cache["tree"]
    q = np.mod(pts, model.box) if model.periodic else pts
    if model.periodic:
        q = np.minimum(q, np.nextafter(model.box, 0))
    hits = tree.query_ball_point(q, cache["reach"])
    lens = np.fromiter((len(h) for h in hits), int, len(hits))
    pi = np.repeat(np.arange(len(pts)), lens)
    if pi.size == 0:
        return np.zeros(len(pts), bool)
    kk = ids[np.concatenate([np.asarray(h, int) for h in hits if h])]
    y = pts[pi] - model.center[kk]
    if model.periodic:
        y -= model.box * np.round(y / model.box)
    y = np.einsum("nji,nj->ni", model.rotation[kk], y) / model.scale[kk][:, None]
    ly = np.linalg.norm(y, axis=1)
    inside = np.zeros(len(pi), bool)
    near = ly <= rmax[np.searchsorted(ids, kk)] / model.scale[kk] + 1e-12
    key = model.shape[kk] * 1000 + model.nmax[kk]
    for kv in np.unique(key[near]):
        sel = np.flatnonzero(near & (key == kv))
        d = y[sel] / np.maximum(ly[sel], 1e-300)[:, None]
        r = kernels.sh_radius(model.shape_coeffs, model.shape_nmax, int(kv // 1000), int(kv % 1000), d)
        inside[sel] = ly[sel] <= r
    out = np.zeros(len(pts), bool)
    np.logical_or.at(out, pi, inside)
    return out


def volume_fractions(model: Model, spec: RdfSpec = RdfSpec(), n_points: int = 1_000_000, seed: int = 1,
                     chunk: int = 100_000) -> VolumeResult:
    """Small-particle fraction of each layer directly in the volume, without slices: n_points
    uniform random points in the box around the RDF particle's outer shell. A point's layer comes
    from the radii of the particle and its K shell surfaces (the kernels' shell forms, evaluated
    here with scipy) along the point's body-frame direction; membership in a small particle from a
    k-d tree of their centres and the point-in-particle test. phi_k = points in layer k and in a
    small particle / points in layer k, with its binomial standard error. Tests Eq 3.11."""
    if n_points < 1:
        raise AnmPostError(f"number of Monte Carlo points must be >= 1, got {n_points}")
    t0 = time.perf_counter()
    st = _setup(model, spec)
    K = len(st.t_mm)
    pid = st.pid
    sh, order = np.array([model.shape[pid]]), np.array([model.nmax[pid]])
    pa, pb_, _ = kernels.particle_forms(model.shape_coeffs, model.shape_nmax, sh, order, int(max(order[0], 1)))
    lmax_s = int(min(119, max(24, 2 * order[0])))
    sa, sb, so, _ = kernels.shell_forms(model.shape_coeffs, model.shape_nmax, sh, order,
                                        (st.t_mm / model.scale[pid])[None, :], lmax_s)
    forms = [(pa[:, :, 0], pb_[:, :, 0], int(order[0]))] + \
        [(sa[:, :, k, 0], sb[:, :, k, 0], int(so[k, 0])) for k in range(K)]
    rng = np.random.default_rng(seed)
    n_in, n_small = np.zeros(K, np.int64), np.zeros(K, np.int64)
    cache: dict = {}
    rot, c, s = model.rotation[pid], model.center[pid], model.scale[pid]
    done = 0
    while done < n_points:
        m = min(chunk, n_points - done)
        pts = st.lo + rng.random((m, 3)) * (st.hi - st.lo)
        y = (pts - c) @ rot / s
        ly = np.linalg.norm(y, axis=1)
        d = y / np.maximum(ly, 1e-300)[:, None]
        lay = np.zeros(m, np.int64)
        # candidates: outside the particle, inside the outermost shell; then the innermost
        # enclosing shell gives the layer
        cand = np.flatnonzero(ly > form_radius(*forms[0], d))
        cand = cand[ly[cand] <= form_radius(*forms[K], d[cand])]
        lay[cand] = K
        for k in range(K - 1, 0, -1):
            sub = cand[ly[cand] <= form_radius(*forms[k], d[cand])]
            lay[sub] = k
            cand = sub
        sel = lay > 0
        is_small = _small_member(model, st.small, pts[sel], cache)
        n_in += np.bincount(lay[sel], minlength=K + 1)[1:K + 1]
        n_small += np.bincount(lay[sel][is_small], minlength=K + 1)[1:K + 1]
        done += m
    phi = np.where(n_in > 0, n_small / np.maximum(n_in, 1), np.nan)
    se = np.sqrt(phi * (1 - phi) / np.maximum(n_in, 1))
    return VolumeResult(phi=phi, phi_se=se, points=n_in, n_points=n_points, seconds=time.perf_counter() - t0)


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
                densities: Sequence[float] = (0.01, 0.05, 0.1, 0.25, 0.5, 1.0)) -> ConvergenceResult:
    """g(t) at several slice densities (thesis Figs 3.9, 3.10, 3.12, 3.13). The slices of every
    density are a subset of the union labelled once: each plane is labelled once even when several
    densities use it."""
    dens = np.asarray(sorted(set(float(d) for d in densities)))
    if dens.size == 0 or dens[0] <= 0 or dens[-1] > 1:
        raise AnmPostError(f"slice densities must be in (0, 1], got {list(densities)}")
    t0 = time.perf_counter()
    st = _setup(model, spec)
    per = [_planes(st, spec, float(d)) for d in dens]
    key = {}
    for planes in per:
        for p in planes:
            key.setdefault(round(p.origin[_AXES[spec.axis]], 9), p)
    uniq = list(key.values())
    counts = _count(st, uniq)
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
    path = Path(path)
    try:
        fig.savefig(path, dpi=150)
    except OSError as exc:
        raise AnmPostError(f"{path}: cannot write PNG ({option}): {exc}") from None
    finally:
        plt.close(fig)
    return path


def plot_rdf(res: RdfResult, path: str | Path, volume: VolumeResult | None = None, title: str = "") -> Path:
    """Bar plot of g per layer (bar width = layer thickness) with the per-slice standard deviation as
    error bars (thesis Fig 3.8); the 3D Monte Carlo values as points when given; g = 1 dashed."""
    plt = _figure()
    fig, ax = plt.subplots(figsize=(6.4, 4))
    width = res.t_outer - res.t_inner
    ax.bar(res.t_inner, res.g, width=width, align="edge", color="#9ecae1", edgecolor="#3182bd",
           label=f"slices (rho_s = {res.density:g}, N = {len(res.positions)})")
    ax.errorbar(res.t_mid, res.g, yerr=res.g_sd, fmt="none", ecolor="#08306b", capsize=3, label="per-slice s.d.")
    if volume is not None:
        ax.errorbar(res.t_mid, volume.phi / res.phi_b, yerr=volume.phi_se / res.phi_b, fmt="o", ms=4,
                    color="#d62728", capsize=2, label="3D (Monte Carlo)")
    ax.axhline(1.0, ls="--", color="grey", lw=1)
    ax.set_xlabel("distance t from the particle surface (mm)")
    ax.set_ylabel("g(t) = phi_shell / phi_B")
    ax.set_title(title or f"g(t) around particle {res.particle} (L = {res.length:.3g} mm, "
                          f"phi_B = {res.phi_b:.3f}, R_s = {res.pixel:g} mm)", fontsize=9)
    ax.legend(fontsize=8)
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

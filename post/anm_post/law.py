"""The statistical law of a packed model (issue 14, docs/dense.md "The law of the result"):
orientation statistics of the particles' long axes per sieve, centre density profiles across the
box in slabs, and the centre-line gaps between the particles of chosen (coarse) sieves.

All three are measured from the model file alone:

- The long axis of a shape (at the order a particle uses) is the principal axis of the largest
  second moment of its solid, M = int_V x x^T dV = int (r^5 / 5) u u^T dOmega, integrated over
  Fibonacci directions with the SH radius r(u). A particle's long axis is R @ axis (body -> world).
- The orientation tensor of a sieve is Q = <a a^T> over its particles; isotropy gives eigenvalues
  1/3 each. For N independent isotropic unit vectors, each component of Q has standard error
  sqrt(4/45 / N) on the diagonal (Var(a_x^2) = 1/5 - 1/9); the report gives that error beside the
  eigenvalues.
- The slab profile of a sieve along an axis is the volume of its particles whose centres fall in
  each slab, divided by the slab volume and by the sieve's fraction of the whole box: 1 everywhere
  for a homogeneous packing. Its standard error per slab is that of the homogeneous null, n ~
  Poisson(N / nslab) particles with the sieve's volumes: sqrt(<v^2>) / <v> / sqrt(N / nslab).
- The centre-line gap of a pair is d - s_A r_A(u) - s_B r_B(-u), u the unit vector from A's
  centre to B's and d the minimum-image centre distance (r in the body frames, s the scales): the gap where the two surfaces face each other along that line.
  It is an upper bound of the true surface distance (equal for spheres), zero or more in a model
  without overlaps. Pairs are those whose bounding spheres are closer than `reach`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import kernels
from .model import Model
from .walleffect import _fibonacci

#: Directions of the moment quadrature.
N_DIRS = 4000


def shape_moments(model: Model, shape: int, order: int, n_dirs: int = N_DIRS) -> tuple[float, np.ndarray, float]:
    """Volume, second moment tensor M (3, 3) and largest radius of one shape at one order (shape
    units), by quadrature over n_dirs Fibonacci directions."""
    d = _fibonacci(n_dirs)
    r = kernels.sh_radius(model.shape_coeffs, model.shape_nmax, shape, order, d)
    w = 4 * np.pi / n_dirs
    vol = w * float(np.sum(r ** 3)) / 3
    m = w * (d * (r ** 5 / 5)[:, None]).T @ d
    return vol, m, float(r.max())


def long_axes(model: Model) -> np.ndarray:
    """World long axis (unit vector, sign arbitrary) of every particle, (np, 3)."""
    axes = np.zeros((model.n_particles, 3))
    kinds = np.unique(np.stack([model.shape, model.nmax], axis=1), axis=0)
    for shape, order in kinds:
        _, m, _ = shape_moments(model, int(shape), int(order))
        w, v = np.linalg.eigh(m)
        body = v[:, np.argmax(w)]
        sel = (model.shape == shape) & (model.nmax == order)
        axes[sel] = model.rotation[sel] @ body
    return axes


@dataclass
class Orientation:
    """Orientation tensor of one sieve: eigenvalues (descending), their isotropic standard error
    sqrt(4/45/N), the particle count and the tensor itself."""

    sieve: int
    count: int
    eigenvalues: np.ndarray
    std_error: float
    tensor: np.ndarray

    @property
    def deviation(self) -> float:
        """Largest |eigenvalue - 1/3| in standard errors (inf for fewer than 2 particles)."""
        if self.count < 2:
            return float("inf")
        return float(np.max(np.abs(self.eigenvalues - 1 / 3)) / self.std_error)


def orientation(axes: np.ndarray, sieve: int = -1) -> Orientation:
    """Orientation tensor <a a^T> of unit vectors axes (n, 3)."""
    n = len(axes)
    q = axes.T @ axes / max(n, 1)
    ev = np.sort(np.linalg.eigvalsh(q))[::-1]
    return Orientation(sieve, n, ev, float(np.sqrt(4 / 45 / max(n, 1))), q)


def orientations(model: Model) -> list[Orientation]:
    """Orientation tensor of every sieve of the model (sieves without particles are skipped)."""
    axes = long_axes(model)
    return [orientation(axes[model.sieve == s], s) for s in range(model.n_sieves) if np.any(model.sieve == s)]


def particle_volumes(model: Model) -> np.ndarray:
    """Volume of every particle (mm^3) from the moment quadrature."""
    vols = np.zeros(model.n_particles)
    kinds = np.unique(np.stack([model.shape, model.nmax], axis=1), axis=0)
    for shape, order in kinds:
        v, _, _ = shape_moments(model, int(shape), int(order))
        sel = (model.shape == shape) & (model.nmax == order)
        vols[sel] = v * model.scale[sel] ** 3
    return vols


@dataclass
class SlabProfile:
    """Normalised centre density of one sieve in slabs along one axis: 1 = the sieve's mean."""

    sieve: int
    axis: int
    edges: np.ndarray
    density: np.ndarray
    std_error: np.ndarray
    count: np.ndarray

    @property
    def deviation(self) -> float:
        """Largest |density - 1| over the slabs, in standard errors."""
        return float(np.max(np.abs(self.density - 1) / self.std_error))


def slab_profiles(model: Model, axis: int = 2, nslab: int = 20,
                  volumes: np.ndarray | None = None) -> list[SlabProfile]:
    """Centre density profile of every sieve in nslab slabs along axis (0, 1, 2 = x, y, z)."""
    vols = particle_volumes(model) if volumes is None else volumes
    length = float(model.box[axis])
    edges = np.linspace(0.0, length, nslab + 1)
    out = []
    for s in range(model.n_sieves):
        sel = model.sieve == s
        if not np.any(sel):
            continue
        x = np.mod(model.center[sel, axis], length) if model.periodic else model.center[sel, axis]
        idx = np.clip((x / length * nslab).astype(int), 0, nslab - 1)
        vol = np.bincount(idx, weights=vols[sel], minlength=nslab)
        cnt = np.bincount(idx, minlength=nslab)
        dens = vol / (vol.sum() / nslab)
        # homogeneous null: n ~ Poisson(N / nslab) particles of the sieve's volumes per slab, so the
        # relative error of a slab's volume is sqrt(<v^2>) / <v> / sqrt(N / nslab)
        v = vols[sel]
        rel = float(np.sqrt(np.mean(v * v)) / np.mean(v)) if np.mean(v) > 0 else 1.0
        se = np.full(nslab, rel / np.sqrt(sel.sum() / nslab))
        out.append(SlabProfile(s, axis, edges, dens, se, cnt))
    return out


def centre_line_gaps(model: Model, sieves: list[int] | None = None, reach: float = 0.5,
                     chunk: int = 512) -> np.ndarray:
    """Centre-line gaps (mm) of every pair of particles of the chosen sieves (default: all) whose
    bounding spheres are closer than `reach` mm; one value per pair, sorted."""
    sel = np.flatnonzero(np.isin(model.sieve, sieves) if sieves is not None else np.ones(model.n_particles, bool))
    if sel.size < 2:
        return np.zeros(0)
    rmax = np.zeros(model.n_particles)
    kinds = np.unique(np.stack([model.shape[sel], model.nmax[sel]], axis=1), axis=0)
    for shape, order in kinds:
        _, _, r = shape_moments(model, int(shape), int(order), n_dirs=2000)
        k = (model.shape == shape) & (model.nmax == order)
        rmax[k] = r * model.scale[k] * 1.02      # the quadrature's largest radius, 2 % margin
    c = model.center[sel]
    pairs_i, pairs_j, seps = [], [], []
    for a in range(0, sel.size, chunk):
        d = c[None, :, :] - c[a:a + chunk, None, :]
        if model.periodic:
            d -= model.box * np.round(d / model.box)
        dist = np.linalg.norm(d, axis=2)
        lim = rmax[sel[a:a + chunk], None] + rmax[sel][None, :] + reach
        ii, jj = np.nonzero((dist < lim) & (np.arange(sel.size)[None, :] > np.arange(a, a + dist.shape[0])[:, None]))
        pairs_i.append(sel[a + ii])
        pairs_j.append(sel[jj])
        seps.append(d[ii, jj])
    i = np.concatenate(pairs_i)
    j = np.concatenate(pairs_j)
    sep = np.concatenate(seps)
    if i.size == 0:
        return np.zeros(0)
    dist = np.linalg.norm(sep, axis=1)
    u = sep / dist[:, None]                      # from i towards j
    gap = dist.copy()
    for who, sign in ((i, 1.0), (j, -1.0)):
        body = np.einsum("nji,nj->ni", model.rotation[who], sign * u)   # R^T u: body-frame direction
        r = np.zeros(who.size)
        for shape, order in np.unique(np.stack([model.shape[who], model.nmax[who]], axis=1), axis=0):
            k = (model.shape[who] == shape) & (model.nmax[who] == order)
            r[k] = kernels.sh_radius(model.shape_coeffs, model.shape_nmax, int(shape), int(order), body[k])
        gap -= model.scale[who] * r
    return np.sort(gap)


def format_report(model: Model, orient: list[Orientation], slabs: list[SlabProfile], gaps: np.ndarray | None,
                  gap_sieves: list[int] | None) -> str:
    """Plain-text report of the three measurements."""
    lines = [f"model: {model.path}", f"particles: {model.n_particles}", "",
             "orientation tensor of the long axes per sieve (isotropic: 1/3 each; se = sqrt(4/45/N); for an",
             "isotropic sample max|l-1/3|/se has median 2.0, 95 % quantile 3.1, 99 % 3.7, whatever N)",
             f"{'sieve':>5} {'N':>8} {'lambda1':>8} {'lambda2':>8} {'lambda3':>8} {'se':>8} {'max|l-1/3|/se':>14}"]
    for o in orient:
        e = o.eigenvalues
        lines.append(f"{o.sieve + 1:>5} {o.count:>8} {e[0]:8.4f} {e[1]:8.4f} {e[2]:8.4f} {o.std_error:8.4f} "
                     f"{o.deviation:14.2f}")
    if slabs:
        ax = "xyz"[slabs[0].axis]
        lines += ["", f"centre density across the box in {slabs[0].density.size} slabs along {ax} "
                      "(1 = the sieve's mean; se of a homogeneous sample, sqrt(<v^2>)/<v>/sqrt(N/slabs);",
                  "for a homogeneous sample in 20 slabs max|d-1|/se is about 3.0 at the 95 % quantile)",
                  f"{'sieve':>5} {'min':>7} {'max':>7} {'first':>7} {'last':>7} {'max|d-1|/se':>12}"]
        for p in slabs:
            d = p.density
            lines.append(f"{p.sieve + 1:>5} {d.min():7.3f} {d.max():7.3f} {d[0]:7.3f} {d[-1]:7.3f} "
                         f"{p.deviation:12.2f}")
    if gaps is not None:
        which = "all" if gap_sieves is None else ",".join(str(s + 1) for s in gap_sieves)
        lines += ["", f"centre-line gaps between particles of sieves {which} (mm; pairs with bounding spheres "
                      "within reach)"]
        if gaps.size:
            q = np.quantile(gaps, [0.0, 0.05, 0.25, 0.5])
            lines.append(f"pairs {gaps.size}; min {q[0]:.4f}; 5% {q[1]:.4f}; 25% {q[2]:.4f}; median {q[3]:.4f}; "
                         f"negative {int(np.sum(gaps < 0))}")
        else:
            lines.append("no pairs within reach")
    return "\n".join(lines) + "\n"


def profiles_csv(slabs: list[SlabProfile]) -> str:
    """CSV of the slab profiles: sieve, slab centre, density, standard error, count."""
    rows = ["sieve,position,density,std_error,count"]
    for p in slabs:
        mid = 0.5 * (p.edges[1:] + p.edges[:-1])
        for x, d, e, n in zip(mid, p.density, p.std_error, p.count):
            rows.append(f"{p.sieve + 1},{x:.6g},{d:.6g},{e:.6g},{n}")
    return "\n".join(rows) + "\n"


def plot_law(slabs: list[SlabProfile], gaps: np.ndarray | None, path, option: str = "--png") -> None:
    """Two panels: the slab profiles per sieve (with +-1 se bands) and the histogram of gaps."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from .output import save_figure

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    ax = axes[0]
    for p in slabs:
        mid = 0.5 * (p.edges[1:] + p.edges[:-1])
        line, = ax.plot(mid, p.density, marker="o", ms=3, label=f"sieve {p.sieve + 1}")
        se = np.where(np.isfinite(p.std_error), p.std_error, 0.0)
        ax.fill_between(mid, p.density - se, p.density + se, color=line.get_color(), alpha=0.15)
    ax.axhline(1.0, color="k", lw=0.8)
    if slabs:
        ax.set_xlabel(f"{'xyz'[slabs[0].axis]} (mm)")
    ax.set_ylabel("centre density / sieve mean")
    ax.set_title("centre density across the box")
    ax.legend(fontsize=7, ncol=2)
    ax = axes[1]
    if gaps is not None and gaps.size:
        ax.hist(gaps, bins=60, color="tab:gray")
        ax.set_xlabel("centre-line gap (mm)")
        ax.set_ylabel("pairs")
        ax.set_title(f"gaps between particles ({gaps.size} pairs)")
    else:
        ax.set_axis_off()
    fig.tight_layout()
    save_figure(fig, path, option, dpi=120)
    plt.close(fig)

"""Typed wrappers of the Fortran kernels (module `_kernels`, built by numpy.f2py from
src/api/slice.f90 and the program's own sources). Arrays are converted to the dtype and
(Fortran) order the adapter expects; a non-zero status becomes an AnmPostError.

Conventions: shapes are passed as in the model file, coeffs (nshape, ncoef, 2) and nmax (nshape,);
shape indices are 0-based here (1-based on the Fortran side). Shape data, (shape, order) pairs,
particle placements and the box are checked by the model validator (anm_post.validate) before
every call, so arrays that did not come through read_model are held to the same contract.
"""
from __future__ import annotations

import numpy as np

from .errors import AnmPostError
from .validate import check_box, check_forms, check_particles, check_shapes

try:
    from . import _kernels  # type: ignore[attr-defined]
except ImportError as _exc:  # pragma: no cover - only without a built extension
    _kernels = None
    _import_error = _exc


def _api():
    if _kernels is None:
        raise AnmPostError("the compiled kernels (anm_post._kernels) are missing: run `bash scripts/setup.sh` "
                           f"({_import_error})")
    return _kernels.anm_api_slice


def _check(status: int, message: bytes | str, what: str) -> None:
    if status != 0:
        text = message.decode(errors="replace") if isinstance(message, bytes) else str(message)
        raise AnmPostError(f"{what}: {text.strip()}")


def _f64(x: np.ndarray) -> np.ndarray:
    return np.asfortranarray(x, dtype=np.float64)


def _i32(x: np.ndarray) -> np.ndarray:
    return np.asfortranarray(x, dtype=np.int32)


def _coeffs(coeffs: np.ndarray) -> np.ndarray:
    return _f64(np.asarray(coeffs, dtype=np.float64).transpose(2, 1, 0))


def _checked_forms(coeffs, nmax, shapes, orders, what: str) -> None:
    """The model validator's checks of shape data and (shape, order) pairs before a kernel call."""
    check_shapes(coeffs, nmax, what)
    check_forms(nmax, np.asarray(shapes).reshape(-1), np.asarray(orders).reshape(-1), what)


def _checked_particles(center, rotation, scale, box, what: str) -> None:
    """The model validator's checks of particle placements and the box before a kernel call."""
    check_box(np.asarray(box, dtype=np.float64), what)
    check_particles(np.asarray(center, dtype=np.float64), np.asarray(rotation, dtype=np.float64),
                    np.asarray(scale, dtype=np.float64), what)


def sh_radius(coeffs: np.ndarray, nmax: np.ndarray, shape: int, order: int, dirs: np.ndarray) -> np.ndarray:
    """r along body-frame directions dirs (n, 3) of shape `shape` truncated at `order` (shape units)."""
    dirs = np.atleast_2d(np.asarray(dirs, dtype=np.float64))
    _checked_forms(coeffs, nmax, [shape], [order], "sh_radius input")
    r, status, msg = _api().api_sh_radius(_coeffs(coeffs), _i32(nmax), int(shape) + 1, int(order), _f64(dirs.T))
    _check(status, msg, "sh_radius input")
    return np.asarray(r)


#: Columns of `geometry`.
GEOMETRY_COLUMNS = ("volume", "area", "length", "width", "thickness", "equiv_diameter", "rmin", "rmax")


def geometry(coeffs: np.ndarray, nmax: np.ndarray, shapes: np.ndarray, orders: np.ndarray) -> np.ndarray:
    """Geometry (n, 8) of (shape, order) pairs, columns GEOMETRY_COLUMNS, shape units."""
    _checked_forms(coeffs, nmax, shapes, orders, "geometry input")
    props, status, msg = _api().api_geometry(_coeffs(coeffs), _i32(nmax), _i32(np.asarray(shapes) + 1),
                                             _i32(orders))
    _check(status, msg, "geometry")
    return np.asarray(props).T.copy()


def particle_forms(coeffs: np.ndarray, nmax: np.ndarray, shapes: np.ndarray, orders: np.ndarray,
                   lmax: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Real-form coefficients a, b (lmax+1, lmax+1, n) and certified bounds (8, n) of (shape, order) pairs."""
    _checked_forms(coeffs, nmax, shapes, orders, "particle forms input")
    a, b, bounds, status, msg = _api().api_particle_forms(_coeffs(coeffs), _i32(nmax), _i32(np.asarray(shapes) + 1),
                                                          _i32(orders), int(lmax))
    _check(status, msg, "particle forms")
    return a, b, bounds


def shell_forms(coeffs: np.ndarray, nmax: np.ndarray, shapes: np.ndarray, orders: np.ndarray,
                thickness: np.ndarray, lmax: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Outer surfaces of shell layers: thickness (nkey, nlayer) cumulative, shape units. Returns
    a, b (lmax+1, lmax+1, nlayer, nkey), order (nlayer, nkey), bounds (8, nlayer, nkey)."""
    thickness = np.atleast_2d(np.asarray(thickness, dtype=np.float64))
    _checked_forms(coeffs, nmax, shapes, orders, "shells input")
    a, b, order, bounds, status, msg = _api().api_shell_forms(
        _coeffs(coeffs), _i32(nmax), _i32(np.asarray(shapes) + 1), _i32(orders), _f64(thickness.T), int(lmax))
    _check(status, msg, "shells")
    return a, b, order, bounds


def slice_labels(a: np.ndarray, b: np.ndarray, order: np.ndarray, bounds: np.ndarray, form: np.ndarray,
                 shell_form: np.ndarray, center: np.ndarray, rotation: np.ndarray, scale: np.ndarray,
                 box: np.ndarray, periodic: bool, origin: np.ndarray, u: np.ndarray, v: np.ndarray,
                 nu: int, nv: int, pixel: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Raw kernel call. form (np,) and shell_form (np, nlayer) are 1-based form indices (0 = none);
    center (np, 3), rotation (np, 3, 3) world = R @ body; origin, u, v (nplane, 3). Returns particle,
    layer, owner as (nplane, nv, nu) arrays (row = v, column = u; particle ids 1-based, 0 = none) and
    the work counters (queried, candidates, pixel tests, SH evaluations)."""
    shell_form = np.asarray(shell_form, dtype=np.int32).reshape(len(form), -1)
    _checked_particles(center, rotation, scale, box, "slice input")
    part, lay, own, stats, status, msg = _api().api_slice(
        _f64(a), _f64(b), _i32(order), _f64(bounds), _i32(form), _i32(shell_form.T), _f64(np.asarray(center).T),
        _f64(np.asarray(rotation).transpose(1, 2, 0)), _f64(scale), _f64(box), int(bool(periodic)),
        _f64(np.atleast_2d(origin).T), _f64(np.atleast_2d(u).T), _f64(np.atleast_2d(v).T), int(nu), int(nv),
        float(pixel))
    _check(status, msg, "slice")
    tr = (2, 1, 0)
    return (np.ascontiguousarray(part.transpose(tr)), np.ascontiguousarray(lay.transpose(tr)),
            np.ascontiguousarray(own.transpose(tr)), np.asarray(stats))


def form_radii(a: np.ndarray, b: np.ndarray, order: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Radii (ndir, nform) of real-form surfaces a, b (lmax+1, lmax+1, nform) of the given orders
    along body-frame directions dirs (ndir, 3), all forms from one recursion per direction."""
    dirs = np.atleast_2d(np.asarray(dirs, dtype=np.float64))
    r, status, msg = _api().api_form_radii(_f64(a), _f64(b), _i32(order), _f64(dirs.T))
    _check(status, msg, "form radii")
    return np.asarray(r)


def point_labels(a: np.ndarray, b: np.ndarray, order: np.ndarray, bounds: np.ndarray, form: np.ndarray,
                 center: np.ndarray, rotation: np.ndarray, scale: np.ndarray, box: np.ndarray, periodic: bool,
                 points: np.ndarray) -> np.ndarray:
    """Particle containing each point (npoint, 3) (1-based id, 0 none; the first found when several
    do), forms as for slice_labels; form (np,) 1-based."""
    points = np.atleast_2d(np.asarray(points, dtype=np.float64))
    _checked_particles(center, rotation, scale, box, "point labels input")
    label, status, msg = _api().api_point_labels(
        _f64(a), _f64(b), _i32(order), _f64(bounds), _i32(form), _f64(np.asarray(center).T),
        _f64(np.asarray(rotation).transpose(1, 2, 0)), _f64(scale), _f64(box), int(bool(periodic)), _f64(points.T))
    _check(status, msg, "point labels")
    return np.asarray(label)

"""The one validator of model data in anm_post (issue 12): every command that reads a model file
(`read_model`) and every kernel call that receives particle or shape arrays (anm_post.kernels)
checks them here before using them, so that a broken file gives a named error and never a silent
wrong result.

Checks (docs/reliability.md):
    box lengths: 3 values, finite, > 0
    shapes: coefficients finite; nmax >= 0 and (nmax + 1)^2 <= number of coefficients stored
    particles: array lengths agree; shape index in 0..nshape-1; nmax in 0..nmax of its shape;
        centre finite; scale finite and > 0; rotation finite, orthonormal and proper:
        max |R^T R - I| <= ROTATION_TOLERANCE and |det R - 1| <= ROTATION_TOLERANCE;
        sieve index in 0..nsieve-1; shell thicknesses (if any) finite
    sieves: widths and fractions finite
    format_version: one of FORMAT_VERSIONS

Every error names the file (or the caller), the dataset and the first bad particle (0-based).
Strings stored by any HDF5 writer (fixed-length, NUL- or space-padded, or variable-length UTF-8)
are read by `text`; bytes that are not UTF-8 are reported by position, never printed.
"""
from __future__ import annotations

import numpy as np

from .errors import AnmPostError

#: Model file format versions this package reads (docs/model-file.md).
FORMAT_VERSIONS = (1,)
#: Tolerance on every entry of R^T R - I and on det R - 1 for a stored rotation R. Rotations are
#: written in double precision (errors ~1e-15); 1e-6 accepts any honest rounding and refuses a
#: scaled matrix (x3 gives R^T R - I = 8), a reflection (det = -1) or a shear.
ROTATION_TOLERANCE = 1e-6


def text(value, where: str) -> str:
    """A string attribute or dataset element as str: accepts str (variable-length UTF-8 as h5py
    writes it), bytes or numpy.bytes_ (fixed-length, NUL- or space-padded), or a one-element
    array of these. Raises AnmPostError naming `where` for anything else or for bytes that are not
    UTF-8 (reporting the byte offset, not the bytes)."""
    if isinstance(value, np.ndarray):
        if value.size != 1:
            raise AnmPostError(f"{where}: expected one string, found an array of {value.size}")
        value = value.reshape(-1)[0]
    if isinstance(value, (bytes, np.bytes_)):
        raw = bytes(value).rstrip(b"\0 ")
        try:
            value = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise AnmPostError(f"{where}: not UTF-8 text (bad byte at offset {exc.start} of {len(raw)})") from None
    if not isinstance(value, str):
        raise AnmPostError(f"{where}: expected a string, found {type(value).__name__}")
    return value.rstrip("\0 ")


def _first_bad(bad: np.ndarray) -> int:
    return int(np.flatnonzero(bad)[0])


def _fail(where: str, dataset: str, message: str) -> None:
    raise AnmPostError(f"{where}::/{dataset}: {message}")


def check_box(box: np.ndarray, where: str) -> None:
    """Box edges: shape (3,), finite, > 0."""
    box = np.asarray(box)
    if box.shape != (3,):
        _fail(where, "box/length", f"expected 3 edge lengths, found shape {box.shape}")
    if not np.all(np.isfinite(box)) or not np.all(box > 0):
        _fail(where, "box/length", f"edge lengths must be finite and > 0, found {box.tolist()}")


def check_shapes(coeffs: np.ndarray, nmax: np.ndarray, where: str) -> None:
    """Shape coefficients (nshape, ncoef, 2) finite; nmax (nshape,) in 0.. with (nmax+1)^2 <= ncoef."""
    coeffs = np.asarray(coeffs)
    nmax = np.asarray(nmax)
    if coeffs.ndim != 3 or coeffs.shape[2] != 2:
        _fail(where, "shapes/coeffs", f"expected shape (nshape, ncoef, 2), found {coeffs.shape}")
    if nmax.shape != (coeffs.shape[0],):
        _fail(where, "shapes/nmax", f"expected {coeffs.shape[0]} values (one per shape), found shape {nmax.shape}")
    bad = ~np.all(np.isfinite(coeffs), axis=(1, 2))
    if bad.any():
        s = _first_bad(bad)
        k = int(np.flatnonzero(~np.all(np.isfinite(coeffs[s]), axis=1))[0])
        n = int(np.floor(np.sqrt(k)))
        _fail(where, "shapes/coeffs", f"shape {s}: coefficient {k} (n = {n}, m = {n * n + n - k}) is not finite")
    bad = (nmax < 0) | ((nmax.astype(np.int64) + 1) ** 2 > coeffs.shape[1])
    if bad.any():
        s = _first_bad(bad)
        _fail(where, "shapes/nmax", f"shape {s}: nmax = {int(nmax[s])} outside 0..{int(np.sqrt(coeffs.shape[1])) - 1} "
                                    f"({coeffs.shape[1]} coefficients stored)")


def check_rotations(rotation: np.ndarray, where: str, dataset: str = "particles/rotation") -> None:
    """Rotations (np, 3, 3): finite, orthonormal and proper within ROTATION_TOLERANCE."""
    r = np.asarray(rotation, dtype=np.float64)
    if r.ndim != 3 or r.shape[1:] != (3, 3):
        _fail(where, dataset, f"expected shape (np, 3, 3), found {r.shape}")
    if r.shape[0] == 0:
        return
    bad = ~np.all(np.isfinite(r), axis=(1, 2))
    if bad.any():
        _fail(where, dataset, f"particle {_first_bad(bad)}: not finite")
    err = np.abs(np.einsum("pki,pkj->pij", r, r) - np.eye(3)).max(axis=(1, 2))
    bad = err > ROTATION_TOLERANCE
    if bad.any():
        p = _first_bad(bad)
        _fail(where, dataset, f"particle {p}: not orthonormal (max |R^T R - I| = {err[p]:.3g} > "
                              f"{ROTATION_TOLERANCE:g})")
    det = np.linalg.det(r)
    bad = np.abs(det - 1) > ROTATION_TOLERANCE
    if bad.any():
        p = _first_bad(bad)
        _fail(where, dataset, f"particle {p}: determinant {det[p]:.6g}, a proper rotation has +1 "
                              f"(a reflection has -1)")


def check_particles(center: np.ndarray, rotation: np.ndarray, scale: np.ndarray, where: str) -> None:
    """Centres (np, 3) finite, rotations proper, scales (np,) finite and > 0."""
    center = np.asarray(center)
    scale = np.asarray(scale)
    npart = scale.shape[0] if scale.ndim == 1 else -1
    if scale.ndim != 1:
        _fail(where, "particles/scale", f"expected one value per particle, found shape {scale.shape}")
    if center.shape != (npart, 3):
        _fail(where, "particles/center", f"expected shape ({npart}, 3), found {center.shape}")
    if np.asarray(rotation).shape != (npart, 3, 3):
        _fail(where, "particles/rotation", f"expected shape ({npart}, 3, 3), found {np.asarray(rotation).shape}")
    bad = ~np.all(np.isfinite(center), axis=1)
    if bad.any():
        p = _first_bad(bad)
        _fail(where, "particles/center", f"particle {p}: centre {center[p].tolist()} is not finite")
    bad = ~(np.isfinite(scale) & (scale > 0))
    if bad.any():
        p = _first_bad(bad)
        _fail(where, "particles/scale", f"particle {p}: scale {scale[p]} must be finite and > 0")
    check_rotations(rotation, where)


def check_forms(nmax_shapes: np.ndarray, shape: np.ndarray, order: np.ndarray, where: str) -> None:
    """Shape indices (0-based) within the shapes stored and orders within 0..nmax of their shape."""
    nmax_shapes = np.asarray(nmax_shapes)
    shape = np.asarray(shape)
    order = np.asarray(order)
    nshape = nmax_shapes.shape[0]
    if shape.shape != order.shape:
        _fail(where, "particles/nmax", f"expected {shape.size} values (one per particle), found shape {order.shape}")
    bad = (shape < 0) | (shape >= nshape)
    if bad.any():
        p = _first_bad(bad)
        _fail(where, "particles/shape", f"particle {p}: shape index {int(shape[p])} outside 0..{nshape - 1} "
                                        f"({nshape} shapes in the file)")
    limit = nmax_shapes[shape] if shape.size else np.zeros(0, int)
    bad = (order < 0) | (order > limit)
    if bad.any():
        p = _first_bad(bad)
        _fail(where, "particles/nmax", f"particle {p}: order {int(order[p])} outside 0..{int(limit[p])} "
                                       f"(nmax of its shape {int(shape[p])})")


def validate_model(model) -> None:
    """Check a Model (anm_post.model.Model) against the contract; raises AnmPostError naming the
    file, the dataset and the first bad particle. Called by read_model."""
    where = str(model.path)
    version = model.attrs.get("format_version") if hasattr(model, "attrs") else None
    if version is not None and version not in FORMAT_VERSIONS:
        raise AnmPostError(f"{where}: format_version {version} is not one this anm-post reads "
                           f"({', '.join(map(str, FORMAT_VERSIONS))}); use the anm-post of the anm that wrote it")
    check_box(model.box, where)
    check_shapes(model.shape_coeffs, model.shape_nmax, where)
    npart = np.asarray(model.shape).shape[0]
    for name in ("nmax", "sieve", "scale"):
        arr = np.asarray(getattr(model, name))
        if arr.shape != (npart,):
            _fail(where, f"particles/{name}", f"expected {npart} values (one per particle), found shape {arr.shape}")
    check_forms(model.shape_nmax, model.shape, model.nmax, where)
    check_particles(model.center, model.rotation, model.scale, where)
    nsieve = int(np.asarray(model.sieves["count"]).size)
    for key, arr in model.sieves.items():
        arr = np.asarray(arr)
        if arr.shape != (nsieve,):
            _fail(where, f"sieves/{key}", f"expected {nsieve} values (one per sieve), found shape {arr.shape}")
        if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
            _fail(where, f"sieves/{key}", f"sieve {_first_bad(~np.isfinite(arr))}: not finite")
    sieve = np.asarray(model.sieve)
    bad = (sieve < 0) | (sieve >= nsieve)
    if bad.any():
        p = _first_bad(bad)
        _fail(where, "particles/sieve", f"particle {p}: sieve index {int(sieve[p])} outside 0..{nsieve - 1}")
    shells = np.asarray(model.shell_thickness)
    if shells.size:
        bad = ~np.all(np.isfinite(shells), axis=1)
        if bad.any():
            _fail(where, "particles/shell_thickness", f"particle {_first_bad(bad)}: not finite")

"""Independent helpers for the slicing tests: complex orthonormal spherical harmonics with the
Condon-Shortley phase in plain numpy (no anm code), and writers of small synthetic model files."""
from __future__ import annotations

from math import factorial, pi, sqrt

import h5py
import numpy as np


def assoc_legendre(n: int, m: int, x: np.ndarray) -> np.ndarray:
    """P_n^m(x), m >= 0, with the Condon-Shortley phase (-1)^m."""
    pmm = np.ones_like(x)
    s = np.sqrt(np.maximum(0.0, 1.0 - x * x))
    for k in range(1, m + 1):
        pmm = -(2 * k - 1) * s * pmm
    if n == m:
        return pmm
    p1 = x * (2 * m + 1) * pmm
    if n == m + 1:
        return p1
    p0 = pmm
    for ell in range(m + 2, n + 1):
        p0, p1 = p1, ((2 * ell - 1) * x * p1 - (ell + m - 1) * p0) / (ell - m)
    return p1


def ylm(n: int, m: int, theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Orthonormal complex Y_n^m(theta, phi) (scipy's sph_harm_y convention)."""
    am = abs(m)
    norm = sqrt((2 * n + 1) / (4 * pi) * factorial(n - am) / factorial(n + am))
    y = norm * assoc_legendre(n, am, np.cos(theta)) * np.exp(1j * am * phi)
    return y if m >= 0 else (-1) ** am * np.conj(y)


def radius(coeffs: np.ndarray, nmax: int, dirs: np.ndarray) -> np.ndarray:
    """r = Re sum a_nm Y_n^m along directions (k, 3); coeffs (ncoef, 2) in NIST line order."""
    d = dirs / np.linalg.norm(dirs, axis=1)[:, None]
    theta = np.arccos(np.clip(d[:, 2], -1, 1))
    phi = np.arctan2(d[:, 1], d[:, 0])
    r = np.zeros(len(d), complex)
    for n in range(nmax + 1):
        for m in range(n, -n - 1, -1):
            a = coeffs[n * n + n - m, 0] + 1j * coeffs[n * n + n - m, 1]
            if a != 0:
                r += a * ylm(n, m, theta, phi)
    return r.real


def random_shape(rng: np.random.Generator, nmax: int, mean_radius: float, rough: float) -> np.ndarray:
    """Conjugate-symmetric coefficients (ncoef, 2) of a smooth star shape of mean radius ~mean_radius."""
    c = np.zeros(((nmax + 1) ** 2, 2))
    c[0, 0] = mean_radius * sqrt(4 * pi)
    for n in range(1, nmax + 1):
        for m in range(0, n + 1):
            z = rough * mean_radius * sqrt(4 * pi) * (rng.normal() + (1j * rng.normal() if m else 0)) / n ** 1.5
            c[n * n + n - m] = [z.real, z.imag]
            if m:
                zc = (-1) ** m * np.conj(z)
                c[n * n + n + m] = [zc.real, zc.imag]
    return c


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random proper rotation."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q


def write_model(path, box, shapes: list[np.ndarray], nmax_shapes: list[int], shape_idx, centers, rotations, scales,
                orders, sieves=None, periodic: bool = True) -> None:
    """Write a minimal contract-v1 model file."""
    npart = len(shape_idx)
    sieves = np.zeros(npart, np.int32) if sieves is None else np.asarray(sieves, np.int32)
    nsieve = int(sieves.max()) + 1
    ncoef = max(c.shape[0] for c in shapes)
    coeffs = np.zeros((len(shapes), ncoef, 2))
    for k, c in enumerate(shapes):
        coeffs[k, :c.shape[0]] = c
    with h5py.File(path, "w") as fh:
        fh.attrs["format"] = "anm-model"
        fh.attrs["format_version"] = 1
        fh.create_dataset("box/length", data=np.asarray(box, float))
        fh["box"].attrs["periodic"] = int(periodic)
        fh.create_dataset("shapes/coeffs", data=coeffs)
        fh.create_dataset("shapes/nmax", data=np.asarray(nmax_shapes, np.int32))
        fh.create_dataset("shapes/name", data=np.array([f"synthetic{k}" for k in range(len(shapes))], dtype="S16"))
        fh.create_dataset("particles/shape", data=np.asarray(shape_idx, np.int32))
        fh.create_dataset("particles/center", data=np.asarray(centers, float))
        fh.create_dataset("particles/rotation", data=np.asarray(rotations, float))
        fh.create_dataset("particles/scale", data=np.asarray(scales, float))
        fh.create_dataset("particles/nmax", data=np.asarray(orders, np.int32))
        fh.create_dataset("particles/sieve", data=sieves)
        for name in ("min_width", "max_width", "target_fraction", "achieved_fraction"):
            fh.create_dataset(f"sieves/{name}", data=np.ones(nsieve))
        fh.create_dataset("sieves/count", data=np.bincount(sieves, minlength=nsieve).astype(np.int32))

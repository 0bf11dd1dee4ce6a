"""The law of a packing (anm_post.law, `anm-post law`; issue 14): orientation tensor of the long
axes, centre density in slabs, centre-line gaps. Checked against outside truth: the volume and
second moments of an ellipsoid (4/3 pi abc, V/5 diag(a^2, b^2, c^2)), the exact gap of two
spheres (across a periodic boundary too), the isotropic limit 1/3 with its sampling error, and the
homogeneous slab profile; then a model compacted by `strategy = 'dense'` measured end to end."""
from __future__ import annotations

import subprocess
import sys
from math import pi, sqrt

import numpy as np
import pytest

from anm_post import law
from anm_post.model import read_model

from synth import random_rotation, write_model, ylm

A, B, C = 2.0, 1.2, 1.0      # ellipsoid semi-axes (x, y, z)


def ellipsoid_coeffs(nmax: int = 12) -> np.ndarray:
    """a_nm of r(theta, phi) of the ellipsoid A, B, C by Gauss-Legendre x uniform quadrature."""
    x, w = np.polynomial.legendre.leggauss(64)
    phi = np.linspace(0, 2 * pi, 128, endpoint=False)
    th, ph = np.meshgrid(np.arccos(x), phi, indexing="ij")
    wt = np.repeat(w[:, None], phi.size, axis=1) * (2 * pi / phi.size)
    u = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=-1)
    r = 1.0 / np.sqrt((u[..., 0] / A) ** 2 + (u[..., 1] / B) ** 2 + (u[..., 2] / C) ** 2)
    c = np.zeros(((nmax + 1) ** 2, 2))
    for n in range(nmax + 1):
        for m in range(-n, n + 1):
            a = np.sum(wt * r * np.conj(ylm(n, m, th, ph)))
            c[n * n + n - m] = [a.real, a.imag]
    return c


def sphere_coeffs(radius: float) -> np.ndarray:
    return np.array([[radius * sqrt(4 * pi), 0.0]])


def test_ellipsoid_volume_and_moments(tmp_path):
    path = tmp_path / "e.h5"
    write_model(path, [10, 10, 10], [ellipsoid_coeffs()], [12], [0], [[5, 5, 5]], [np.eye(3)], [1.0], [12])
    model = read_model(path)
    vol, m, rmax = law.shape_moments(model, 0, 12)
    v_true = 4 / 3 * pi * A * B * C
    assert vol == pytest.approx(v_true, rel=2e-3)
    assert np.sort(np.linalg.eigvalsh(m)) == pytest.approx(np.sort(v_true / 5 * np.array([A, B, C]) ** 2), rel=1e-2)
    assert rmax == pytest.approx(A, rel=1e-2)
    ax = law.long_axes(model)[0]
    assert abs(ax[0]) == pytest.approx(1.0, abs=1e-6)


def make_ellipsoids(tmp_path, rotations, centers=None, box=(50.0, 50.0, 50.0)):
    n = len(rotations)
    rng = np.random.default_rng(3)
    centers = rng.uniform(0, box[0], size=(n, 3)) if centers is None else centers
    path = tmp_path / "many.h5"
    write_model(path, box, [ellipsoid_coeffs(8)], [8], np.zeros(n, int), centers, rotations, np.full(n, 0.1),
                np.full(n, 8))
    return read_model(path)


def test_aligned_particles_have_one_eigenvalue(tmp_path):
    rng = np.random.default_rng(5)
    rots = []
    for _ in range(200):        # random turns about x keep the long axis (x) along x
        t = rng.uniform(0, 2 * pi)
        rots.append(np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]]))
    o = law.orientations(make_ellipsoids(tmp_path, rots))[0]
    assert o.eigenvalues == pytest.approx([1.0, 0.0, 0.0], abs=1e-9)
    assert o.deviation > 30


def test_random_rotations_are_isotropic_within_sampling_error(tmp_path):
    rng = np.random.default_rng(6)
    o = law.orientations(make_ellipsoids(tmp_path, [random_rotation(rng) for _ in range(3000)]))[0]
    assert o.std_error == pytest.approx(sqrt(4 / 45 / 3000))
    assert np.sum(o.eigenvalues) == pytest.approx(1.0)
    assert o.deviation < 3.7          # the 99 % quantile of an isotropic sample


def test_slab_profile_homogeneous_and_one_sided(tmp_path):
    rng = np.random.default_rng(7)
    rots = [np.eye(3)] * 4000
    model = make_ellipsoids(tmp_path, rots)
    p = law.slab_profiles(model, axis=2, nslab=10)[0]
    assert p.density.mean() == pytest.approx(1.0)
    assert p.deviation < 4.0
    half = rng.uniform(0, 1, size=(4000, 3)) * [50, 50, 25]          # every centre in z < 25
    p = law.slab_profiles(make_ellipsoids(tmp_path, rots, centers=half), axis=2, nslab=10)[0]
    assert p.density[:5] == pytest.approx(2.0, abs=0.25) and np.all(p.density[5:] == 0)
    assert p.deviation > 10


def test_sphere_gaps_exact_and_periodic(tmp_path):
    path = tmp_path / "s.h5"
    centers = [[1.5, 5, 5], [4.0, 5, 5], [9.5, 5, 5]]        # gaps 0.5 (direct) and 0.0 + 1 across x = 0
    write_model(path, [10, 10, 10], [sphere_coeffs(1.0)], [0], [0, 0, 0], centers, [np.eye(3)] * 3, [1.0] * 3, [0] * 3)
    gaps = law.centre_line_gaps(read_model(path), None, reach=1.0)
    assert gaps == pytest.approx([0.0, 0.5], abs=1e-9)      # 9.5 -> 1.5 across the boundary: d = 2
    write_model(path, [10, 10, 10], [sphere_coeffs(1.0)], [0], [0, 0, 0], centers, [np.eye(3)] * 3, [1.0] * 3,
                [0] * 3, periodic=False)
    gaps = law.centre_line_gaps(read_model(path), None, reach=1.0)
    assert gaps == pytest.approx([0.5], abs=1e-9)


def test_ellipsoid_gap_along_the_centre_line(tmp_path):
    """Two ellipsoids end to end along x, the second turned a quarter about z: the gap is
    d - A - B."""
    path = tmp_path / "e2.h5"
    rz = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    write_model(path, [20, 20, 20], [ellipsoid_coeffs()], [12], [0, 0], [[5, 10, 10], [8.5, 10, 10]],
                [np.eye(3), rz], [1.0, 1.0], [12, 12], periodic=False)
    gaps = law.centre_line_gaps(read_model(path), None, reach=1.0)
    assert gaps == pytest.approx([3.5 - A - B], abs=2e-3)


def run_post(*args):
    return subprocess.run([sys.executable, "-m", "anm_post", *map(str, args)], capture_output=True, text=True,
                          timeout=300)


def test_command_line_and_errors(tmp_path):
    path = tmp_path / "s.h5"
    write_model(path, [10, 10, 10], [sphere_coeffs(1.0)], [0], [0, 0], [[2, 5, 5], [5, 5, 5]], [np.eye(3)] * 2,
                [1.0] * 2, [0] * 2)
    res = run_post("law", path, "--csv", tmp_path / "p.csv", "--png", tmp_path / "p.png", "--slabs", 5, "--reach", 2)
    assert res.returncode == 0, res.stderr
    assert "orientation tensor" in res.stdout and "pairs 1; min 1.0000" in res.stdout
    assert (tmp_path / "p.csv").read_text().startswith("sieve,position,density,std_error,count\n")
    assert (tmp_path / "p.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    for args, text in ((["--gap-sieves", "3"], "--gap-sieves"), (["--slabs", "0"], "--slabs"),
                       (["--reach", "-1"], "--reach"), (["--gap-sieves", "x"], "--gap-sieves")):
        res = run_post("law", path, *args)
        assert res.returncode == 1 and text in res.stderr and "Traceback" not in res.stderr, (args, res.stderr)


DENSE = """&box length = 10, 10, 10 /
&sieves nsieve = 2, min_width = 2.0, 1.0, max_width = 2.4, 1.2, fraction = 0.25, 0.20, order = 8, 6,
   source = 'synthetic', 'synthetic' /
&synthetic count = 4 /
&parking max_locations = 300, strategy = 'dense', dense_rounds = 4, dense_sweeps = 4 /
&output directory = '{dir}', name = 'm', vrml = .false. /
&run seed = 4 /
"""


def test_a_compacted_model_is_isotropic_and_homogeneous(anm_bin, tmp_path):
    """A model compacted by relaxation sweeps (strategy = 'dense'): long axes isotropic and
    centres homogeneous within the sampling error of its ~300 particles, no negative gap."""
    nml = tmp_path / "d.nml"
    nml.write_text(DENSE.format(dir=tmp_path / "o"))
    res = subprocess.run([anm_bin, "run", str(nml)], capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    model = read_model(tmp_path / "o" / "m.h5")
    axes = law.long_axes(model)
    o = law.orientation(axes)
    assert o.count > 250
    assert o.deviation < 3.7, o.eigenvalues
    for p in law.slab_profiles(model, axis=0, nslab=10):
        assert p.deviation < 4.0, (p.sieve, p.density)
    gaps = law.centre_line_gaps(model, None, reach=0.2)
    assert gaps.size > 100 and gaps.min() >= 0.0

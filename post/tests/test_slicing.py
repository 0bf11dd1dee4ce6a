"""Slices against outside truth: an independent numpy point-in-particle test, Delesse's principle,
the exact apparent shell thickness of a sphere on oblique planes, the labelling rules, thread-count
independence and bad input."""
from __future__ import annotations

import os
import subprocess
import sys
from math import pi, sqrt

import numpy as np
import pytest

from synth import radius, random_rotation, random_shape, write_model

from anm_post import AnmPostError, Plane, ShellSpec, Slicer, axis_plane, read_model, random_plane
from anm_post import kernels
from anm_post.slicing import n_max, stack_positions


def lattice_model(path, rng, n_side=3, box=9.0, nmax=4, jitter_origin=0.4):
    """Particles on a lattice (non-overlapping: r_max < half the spacing), some crossing box faces."""
    shapes = [random_shape(rng, nmax, 1.0, 0.08) for _ in range(3)]
    spacing = box / n_side
    centers, rots, idx, scales = [], [], [], []
    for i in range(n_side):
        for j in range(n_side):
            for k in range(n_side):
                centers.append((np.array([i, j, k]) * spacing + jitter_origin) % box)
                rots.append(random_rotation(rng))
                idx.append(len(centers) % 3)
                scales.append(rng.uniform(0.8, 1.1) * spacing / 3.0)
    write_model(path, [box] * 3, shapes, [nmax] * 3, idx, centers, rots, scales, [nmax] * len(idx))
    return read_model(path)


def numpy_labels(model, plane, nmax=4):
    """Independent labels: for every pixel and particle image, |y| <= r(y/|y|) with numpy SH."""
    x = plane.pixel_centers().reshape(-1, 3)
    label = np.full(len(x), -1)
    margin = np.full(len(x), np.inf)
    shifts = [np.array([a, b, c]) * model.box for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)]
    for p in range(model.n_particles):
        coeffs = model.shape_coeffs[model.shape[p]]
        for sh in shifts:
            y = (x - (model.center[p] + sh)) @ model.rotation[p] / model.scale[p]   # R^T (x - c) / s
            q = np.linalg.norm(y, axis=1)
            near = q < 3.0
            if not near.any():
                continue
            r = radius(coeffs, nmax, y[near])
            inside = q[near] <= r
            idx = np.flatnonzero(near)
            label[idx[inside]] = p
            margin[idx] = np.minimum(margin[idx], np.abs(q[near] - r))
    return label.reshape(plane.shape), margin.reshape(plane.shape)


def test_labels_match_numpy_point_in_particle(tmp_path):
    rng = np.random.default_rng(7)
    model = lattice_model(tmp_path / "lat.h5", rng)
    slicer = Slicer(model)
    planes = [axis_plane(model, "z", 0.3, 0.045),                       # crosses particles at the z = 0 face
              Plane((-1.0, 0.5, 2.0), (0.6, 0.8, 0.0), (-0.48, 0.36, 0.8), (11.0, 9.0), 0.05)]
    for plane in planes:
        res = slicer.slice(plane)
        ref, margin = numpy_labels(model, plane)
        agree = np.mean(res.particle == ref)
        assert agree >= 0.999, agree
        bad = res.particle != ref
        assert np.all(margin[bad] < 1e-6), margin[bad]          # disagreements only on boundaries
        assert np.unique(ref[ref >= 0]).size > 5
        assert res.stats["candidates"] < 3 * model.n_particles


def test_delesse_area_fraction_equals_volume_fraction(tmp_path):
    rng = np.random.default_rng(11)
    model = lattice_model(tmp_path / "del.h5", rng, n_side=4, box=8.0, jitter_origin=0.0)
    slicer = Slicer(model)
    vol = kernels.geometry(model.shape_coeffs, model.shape_nmax, slicer._pairs[:, 0], slicer._pairs[:, 1])[:, 0]
    phi = np.sum(vol[slicer._form] * model.scale ** 3) / model.volume
    fractions = np.array([slicer.slice(random_plane(model, 0.08, 8.0, rng)).particle_fraction for _ in range(60)])
    mean, err = fractions.mean(), fractions.std(ddof=1) / sqrt(len(fractions))
    assert abs(mean - phi) < 3 * err + 0.002, (mean, phi, err)
    # and with the same statistic the stack of axis slices at rho_s = 0.5
    stack = np.array([r.particle_fraction for r in slicer.stack("x", 0.08, 0.5)])
    assert len(stack) == round(0.5 * n_max(8.0, 0.08))
    assert abs(stack.mean() - phi) < 3 * stack.std(ddof=1) / sqrt(len(stack)) + 0.002


def sphere_model(path, centers, radii, box=10.0):
    shapes = [np.array([[r * sqrt(4 * pi), 0.0]]) for r in radii]
    write_model(path, [box] * 3, shapes, [0] * len(radii), list(range(len(radii))), centers,
                [np.eye(3)] * len(radii), [1.0] * len(radii), [0] * len(radii), periodic=False)
    return read_model(path)


def test_apparent_shell_thickness_on_oblique_planes_matches_sphere(tmp_path):
    R, t = 2.0, 0.3
    model = sphere_model(tmp_path / "sph.h5", [[5.0, 5.0, 5.0]], [R])
    slicer = Slicer(model, ShellSpec((t,), unit="mm"))
    pix = 0.01
    for d, normal in [(0.0, (0, 0, 1.0)), (1.2, (1.0, 1.0, 0.5)), (1.8, (0.2, -1.0, 0.7))]:
        n = np.asarray(normal) / np.linalg.norm(normal)
        u = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        c = np.array([5.0, 5, 5]) + d * n
        size = 5.0
        res = slicer.slice(Plane(tuple(c - 0.5 * size * (u + v)), tuple(u), tuple(v), (size, size), pix))
        a_in = np.sum(res.particle >= 0) * pix ** 2
        a_out = a_in + np.sum(res.layer == 1) * pix ** 2
        apparent = sqrt(a_out / pi) - sqrt(a_in / pi)
        exact = sqrt((R + t) ** 2 - d ** 2) - sqrt(R ** 2 - d ** 2)
        assert abs(apparent - exact) < 0.02 * t + 2 * pix ** 2 / exact, (d, apparent, exact)
        if d > 0:
            assert apparent > 1.2 * t


def test_labelling_rules_with_two_layers(tmp_path):
    # three spheres; shells of two layers overlap each other and the neighbours
    centers = np.array([[3.0, 5.0, 5.0], [5.3, 5.0, 5.0], [4.2, 6.9, 5.0]])
    radii = [1.0, 0.9, 0.7]
    t = (0.2, 0.5)
    model = sphere_model(tmp_path / "rules.h5", centers, radii)
    res = Slicer(model, ShellSpec(t, unit="mm")).slice(axis_plane(model, "z", 5.0, 0.02))
    x = res.plane.pixel_centers()
    dist = np.linalg.norm(x[:, :, None, :] - centers[None, None], axis=-1) - np.asarray(radii)
    ref_part = np.where(dist.min(-1) <= 0, dist.argmin(-1), -1)
    ref_layer = np.zeros(ref_part.shape, int)
    for k in (2, 1):                                   # inner layer wins
        ref_layer[(dist.min(-1) <= t[k - 1]) & (ref_part < 0)] = k
    boundary = np.min(np.abs(np.stack([dist, dist - t[0], dist - t[1]], -1)), axis=(-1, -2)) < 0.03 * t[0] + 0.005
    ok = (res.particle == ref_part) & (res.layer == ref_layer)
    assert np.mean(ok) >= 0.999
    assert np.all(ok | boundary)
    # the layers of different particles merge: layer 1 pixels owned by at least two particles
    assert len(np.unique(res.owner[res.layer == 1])) == 3
    assert np.all(res.layer[res.particle >= 0] == 0)


def test_shells_around_one_particle_only(tmp_path):
    model = sphere_model(tmp_path / "one.h5", [[3.0, 5.0, 5.0], [6.5, 5.0, 5.0]], [1.0, 1.0])
    res = Slicer(model, ShellSpec((0.1,), unit="fraction", particles=(1,))).slice(axis_plane(model, "z", 5.0, 0.02))
    assert set(np.unique(res.owner[res.layer == 1])) == {1}
    width = np.sum(res.layer[250] == 1) * 0.02 / 2           # row through both centres: two shell runs
    assert abs(width - 0.2) < 0.05                           # 10 % of the length 2 mm


def test_thread_count_does_not_change_labels(tmp_path):
    rng = np.random.default_rng(3)
    lattice_model(tmp_path / "thr.h5", rng)
    outs = []
    for threads in ("1", "2"):
        out = tmp_path / f"labels{threads}.npz"
        env = dict(os.environ, OMP_NUM_THREADS=threads)
        subprocess.run([sys.executable, "-m", "anm_post", "slice", str(tmp_path / "thr.h5"), "--axis", "y",
                        "--position", "4.4", "--pixel", "0.05", "--shells", "0.05", "--labels", str(out)],
                       check=True, env=env, capture_output=True)
        outs.append(np.load(out))
    for key in ("particle", "layer", "owner"):
        assert np.array_equal(outs[0][key], outs[1][key])


def test_stack_positions_follow_slice_density():
    assert n_max(20.0, 0.05) == 400
    pos = stack_positions(0.0, 20.0, 0.05, 0.1)
    assert len(pos) == 40 and np.allclose(np.diff(pos), 0.5)
    with pytest.raises(AnmPostError):
        stack_positions(0.0, 20.0, 0.05, 1.5)


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "anm_post", *args], capture_output=True, text=True)


def test_cli_bad_input_names_file_and_option(tmp_path):
    res = run_cli("slice", str(tmp_path / "missing.h5"), "--pixel", "0.1", "--position", "1")
    assert res.returncode != 0 and "missing.h5" in res.stderr and "Traceback" not in res.stderr
    bad = tmp_path / "bad.h5"
    bad.write_text("not hdf5")
    res = run_cli("slice", str(bad), "--pixel", "0.1", "--position", "1")
    assert res.returncode != 0 and "bad.h5" in res.stderr and "Traceback" not in res.stderr
    model = sphere_model(tmp_path / "ok.h5", [[5.0, 5.0, 5.0]], [1.0])
    for opts, name in [(["--pixel", "-0.1", "--position", "5"], "--pixel"),
                       (["--pixel", "0.1", "--position", "50"], "--position"),
                       (["--pixel", "0.1", "--position", "5", "--shells", "0.1,0.05"], "--shells"),
                       (["--pixel", "0.1", "--position", "5", "--shells", "x"], "--shells"),
                       (["--pixel", "0.1", "--density", "2"], "--density"),
                       (["--pixel", "0.1", "--center", "1", "1", "1", "--normal", "0", "0", "0", "--size", "2", "2"],
                        "--normal")]:
        res = run_cli("slice", str(model.path), *opts)
        assert res.returncode != 0, opts
        assert name in res.stderr and "Traceback" not in res.stderr, (opts, res.stderr)
    res = run_cli("slice", str(model.path), "--pixel", "0.1", "--position", "5", "--labels", str(tmp_path / "x.txt"))
    assert res.returncode != 0 and "x.txt" in res.stderr


def test_cli_slice_png_labels_and_psd_table(tmp_path):
    model = sphere_model(tmp_path / "m.h5", [[5.0, 5.0, 5.0], [2.0, 2.0, 5.0]], [1.0, 0.5])
    png, lab = tmp_path / "s.png", tmp_path / "s.h5"
    res = run_cli("slice", str(model.path), "--position", "5", "--pixel", "0.05", "--shells", "0.1",
                  "--png", str(png), "--labels", str(lab))
    assert res.returncode == 0, res.stderr
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    import h5py
    with h5py.File(lab) as fh:
        part = fh["particle"][()]
    area = np.sum(part == 0) * 0.05 ** 2
    assert abs(area - pi) < 0.05
    res = run_cli("table", str(model.path), "--format", "csv")
    assert res.returncode == 0 and res.stdout.splitlines()[0].startswith("sieve,min_width_mm")
    assert res.stdout.splitlines()[-1].split(",")[-1] == "2"


def test_cli_plot_study_csv(tmp_path):
    csv = tmp_path / "next.csv"
    csv.write_text("next,v_box,v_box_certified\n10,1.0,1.2\n20,1.1,1.15\n40,1.12,1.13\n")
    res = run_cli("plot", str(csv), "-o", str(tmp_path / "n.png"))
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "n.png").stat().st_size > 1000
    csv.write_text("foo,bar\n1,2\n")
    res = run_cli("plot", str(csv))
    assert res.returncode != 0 and "next.csv:1" in res.stderr


def test_sh_radius_kernel_matches_numpy():
    rng = np.random.default_rng(5)
    c = random_shape(rng, 6, 1.0, 0.1)
    dirs = rng.normal(size=(50, 3))
    r = kernels.sh_radius(c[None], np.array([6]), 0, 6, dirs)
    assert np.allclose(r, radius(c, 6, dirs), atol=1e-12)


def test_slice_stack_reports_progress(tmp_path):
    """A stack of slices prints its progress on stderr (percent, slices done of all, time left)."""
    sphere_model(tmp_path / "p.h5", [[5.0, 5.0, 5.0], [2.0, 2.0, 2.0]], [2.0, 1.0])
    res = run_cli("slice", str(tmp_path / "p.h5"), "--axis", "z", "--pixel", "0.1", "--density", "0.2",
                  "--labels", str(tmp_path / "stack.npz"))
    assert res.returncode == 0, res.stderr
    lines = [line for line in res.stderr.splitlines() if line.startswith("slices:")]
    assert lines and "100%" in lines[-1] and "(20/20)" in lines[-1] and "s left" in lines[-1], res.stderr

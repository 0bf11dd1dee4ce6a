"""g(t) of thesis section 3.4 (anm_post.walleffect) against outside truth: a constructed case with
an exact answer, the slice estimate against the volume estimate (Eq 3.11), and the M_sand model."""
from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
from math import pi, sqrt

import numpy as np
import pytest

from synth import random_rotation, random_shape, write_model, ylm
from anm_post import Plane, read_model
from anm_post.cli import main
from anm_post.errors import AnmPostError
from anm_post.walleffect import (RdfSpec, convergence, form_radius, legendre_table, prepare, rdf, volume_fractions)

SPHERE = np.array([[sqrt(4 * pi), 0.0]])      # r = 1: order 0, a_00 = sqrt(4 pi)


def lens_volume(r1: float, r2: float, d: np.ndarray) -> np.ndarray:
    """Volume of the intersection of balls of radii r1, r2 at centre distance d (|r1 - r2| <= d <= r1 + r2)."""
    return pi * (r1 + r2 - d) ** 2 * (d * d + 2 * d * r2 - 3 * r2 * r2 + 2 * d * r1 + 6 * r1 * r2 - 3 * r1 * r1) \
        / (12 * d)


def set_widths(path, max_widths) -> None:
    """Give the sieves of a synthetic model file their max widths (mm)."""
    import h5py
    with h5py.File(path, "r+") as fh:
        fh["sieves/max_width"][...] = np.asarray(max_widths, float)
        fh["sieves/min_width"][...] = 0.9 * np.asarray(max_widths, float)


def boolean_model(path, box=6.0, big=2.0, small=0.1, number=8450, seed=3):
    """One big sphere (sieve 0) in the box centre; `number` small spheres (sieve 1, overlaps among
    them allowed) with centres independent and uniform in the box outside the ball of radius
    big + small around the big one. Returns the allowed volume."""
    rng = np.random.default_rng(seed)
    c0 = np.full(3, box / 2)
    cs = []
    while len(cs) < number:
        c = rng.uniform(0, box, (2 * number, 3))
        cs.extend(c[np.linalg.norm(c - c0, axis=1) >= big + small])
    cs = np.array(cs[:number])
    n = number + 1
    write_model(path, [box] * 3, [SPHERE], [0], np.zeros(n, int), np.vstack([c0, cs]), np.tile(np.eye(3), (n, 1, 1)),
                np.r_[big, np.full(number, small)], np.zeros(n, int), sieves=np.r_[0, np.ones(number, int)])
    set_widths(path, [2 * big, 2 * small])
    return box ** 3 - 4 / 3 * pi * (big + small) ** 3


def exact_g(t_in, t_out, big, small, number, allowed):
    """E[g] per layer: coverage 1 - (1 - V(x)/V_allowed)^N, V(x) the allowed part of the ball of
    radius `small` around x, volume-averaged over the layer, over the same far from the wall."""
    v = 4 / 3 * pi * small ** 3
    phi_b = 1 - (1 - v / allowed) ** number
    out = []
    for a, b in zip(t_in, t_out):
        rho = np.linspace(big + a, big + b, 2001)
        vx = v - np.where(rho < big + 2 * small, lens_volume(big + small, small, np.minimum(rho, big + 2 * small)), 0)
        p = 1 - (1 - vx / allowed) ** number
        w = rho ** 2
        out.append(np.trapezoid(p * w, rho) / np.trapezoid(w, rho) / phi_b)
    return np.array(out), phi_b


def closed_form_ylm(n: int, m: int, theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Textbook closed forms of the orthonormal Y_n^m (Condon-Shortley phase), n <= 3, m >= 0."""
    c, s, e = np.cos(theta), np.sin(theta), np.exp(1j * m * phi)
    table = {
        (0, 0): 0.5 * sqrt(1 / pi) + 0 * c,
        (1, 0): 0.5 * sqrt(3 / pi) * c,
        (1, 1): -0.5 * sqrt(3 / (2 * pi)) * s,
        (2, 0): 0.25 * sqrt(5 / pi) * (3 * c * c - 1),
        (2, 1): -0.5 * sqrt(15 / (2 * pi)) * s * c,
        (2, 2): 0.25 * sqrt(15 / (2 * pi)) * s * s,
        (3, 0): 0.25 * sqrt(7 / pi) * (5 * c ** 3 - 3 * c),
        (3, 1): -0.125 * sqrt(21 / pi) * s * (5 * c * c - 1),
        (3, 2): 0.25 * sqrt(105 / (2 * pi)) * s * s * c,
        (3, 3): -0.125 * sqrt(35 / pi) * s ** 3,
    }
    return table[(n, m)] * e


def test_legendre_and_form_radius_match_kernels():
    # the reference Y_n^m (synth.ylm: unnormalised recurrence times the factorial norm, no anm code)
    # is checked first against textbook closed forms, then legendre_table against it up to n = 12
    x = np.linspace(-1, 1, 9)
    th = np.arccos(x)
    ph = np.linspace(0.3, 5.9, 9)
    for n in range(4):
        for m in range(n + 1):
            assert np.allclose(ylm(n, m, th, ph), closed_form_ylm(n, m, th, ph), atol=1e-14)
    # a known value: Y_12^0 at the pole is sqrt(25 / (4 pi))
    assert abs(ylm(12, 0, np.array([0.0]), np.array([0.0]))[0] - sqrt(25 / (4 * pi))) < 1e-13
    p = legendre_table(12, x)
    for n in range(13):
        for m in range(n + 1):
            assert np.allclose(p[n, m], ylm(n, m, th, 0 * th).real, atol=1e-13)
    from anm_post import kernels
    rng = np.random.default_rng(0)
    c = random_shape(rng, 6, 1.0, 0.2)[None]
    a, b, _ = kernels.particle_forms(c, np.array([6]), np.array([0]), np.array([6]), 6)
    d = rng.normal(size=(50, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    assert np.allclose(form_radius(a[:, :, 0], b[:, :, 0], 6, d), kernels.sh_radius(c, np.array([6]), 0, 6, d),
                       atol=1e-12)
    # several forms of different orders evaluated together (kernels.form_radii) against numpy
    cs = [random_shape(rng, n, 1.0 + 0.1 * n, 0.08)[None] for n in (3, 9, 6)]
    fa = np.zeros((10, 10, 3))
    fb = np.zeros((10, 10, 3))
    for k, (cc, n) in enumerate(zip(cs, (3, 9, 6))):
        ak, bk, _ = kernels.particle_forms(cc, np.array([n]), np.array([0]), np.array([n]), n)
        fa[:n + 1, :n + 1, k], fb[:n + 1, :n + 1, k] = ak[:, :, 0], bk[:, :, 0]
    r = kernels.form_radii(fa, fb, np.array([3, 9, 6]), 2.0 * d)
    for k, n in enumerate((3, 9, 6)):
        assert np.allclose(r[:, k], form_radius(fa[:, :, k], fb[:, :, k], n, d), atol=1e-12)


def test_constructed_boolean_case_matches_geometry(tmp_path):
    """Small spheres uniform outside one big sphere: g(t) from slices and from the volume equals
    the exact expectation within 3 standard errors per layer, with a clear wall effect."""
    big, small, number = 2.0, 0.1, 8450
    allowed = boolean_model(tmp_path / "b.h5", big=big, small=small, number=number)
    model = read_model(tmp_path / "b.h5")
    t_in = np.arange(10) * 0.02
    expect, phi_b = exact_g(t_in, t_in + 0.02, big, small, number, allowed)
    # slices 0.2 mm = 2 r apart are nearly independent, so their standard error measures the
    # realisation's fluctuation
    spec = RdfSpec(t_min=0.02, t_max=0.2, unit="mm", pixel=0.01, density=0.05, phi_b=phi_b, axis="z")
    res = rdf(model, spec)
    assert res.particle == 0 and res.small_sieves == (1,)
    assert np.allclose(res.t_outer, t_in + 0.02)
    z = (res.g - expect) / res.g_se
    print("exact", np.round(expect, 3), "\nslices", np.round(res.g, 3), "\nz", np.round(z, 2))
    assert np.all(np.abs(z) < 3)
    assert expect[0] < 0.05 and res.g[0] < 0.05 and expect[-1] > 0.98
    vol = volume_fractions(model, spec, spacing=0.03, replicates=4, seed=2)
    g3 = vol.phi / phi_b
    print("3D", np.round(g3, 3))
    assert np.all(np.abs(g3 - expect) < 3 * np.hypot(res.g_se, vol.phi_se / phi_b))


def shaped_model(path, seed=5):
    """M_sand-like: one rough coarse particle (order 6) and 3000 small rough grains (order 3) placed
    with their centres at least half a grain radius outside the coarse one (overlap among the
    grains allowed), periodic 4 mm box."""
    rng = np.random.default_rng(seed)
    big = random_shape(rng, 6, 1.0, 0.12)
    grain = random_shape(rng, 3, 1.0, 0.1)
    box, c0, sc_big, sc = 4.0, np.full(3, 2.0), 1.2, 0.06
    rot0 = random_rotation(rng)
    from anm_post import kernels
    cs = []
    while len(cs) < 3000:
        c = rng.uniform(0, box, (3, ))
        y = rot0.T @ (c - c0) / sc_big
        ly = np.linalg.norm(y)
        if ly * sc_big > 3 * sc_big:
            cs.append(c)
            continue
        r = kernels.sh_radius(big[None], np.array([6]), 0, 6, (y / ly)[None])[0]
        if (ly - r) * sc_big > 0.5 * sc:          # grains may touch the coarse particle, not cross it
            cs.append(c)
    n = len(cs) + 1
    rots = np.array([rot0] + [random_rotation(rng) for _ in cs])
    write_model(path, [box] * 3, [big, grain], [6, 3], np.r_[0, np.ones(len(cs), int)], np.vstack([c0, cs]), rots,
                np.r_[sc_big, np.full(len(cs), sc)], np.r_[6, np.full(len(cs), 3)],
                sieves=np.r_[0, np.ones(len(cs), int)])
    set_widths(path, [2.5, 0.15])


def within_one_se(g, g_se, g3):
    """The check of Eq 3.11: every layer's slice g lies within one of its standard errors of g_3D."""
    return bool(np.all(np.abs(g - g3) <= g_se))


def test_slices_at_full_density_equal_volume_value(tmp_path):
    """Eq 3.11: at rho_s = 1 the slice estimate of every layer equals the volume value within one
    standard error of the slice estimate; the volume value is precise (its own standard error is a
    small fraction of the slices'). The check fails for a wrong phi_B and for layers shifted by
    half a layer, and the slices' layer volumes equal the volume sample's."""
    shaped_model(tmp_path / "s.h5")
    model = read_model(tmp_path / "s.h5")
    spec = RdfSpec(t_min=0.01, t_max=0.1, pixel=0.025, density=1.0, axis="y")
    st = prepare(model, spec)
    res = rdf(model, spec, setup=st)
    vol = volume_fractions(model, spec, spacing=0.04, replicates=4, seed=4, setup=st)
    g3, se3 = vol.phi / res.phi_b, vol.phi_se / res.phi_b
    print("slices", np.round(res.g, 3), "\nse    ", np.round(res.g_se, 3), "\n3D    ", np.round(g3, 3),
          "\n3D se ", np.round(se3, 4), "\n(g - g3) / se", np.round((res.g - g3) / res.g_se, 2))
    assert within_one_se(res.g, res.g_se, g3)
    assert np.all(se3 < 0.3 * res.g_se)                 # the reference is precise
    assert res.g[0] < 0.8 and g3[0] < 0.8               # the wall effect is there
    # the masks: pixel volumes of the layers against the volume sample's (geometry only)
    assert np.allclose(res.layer_volume, vol.volume, rtol=0.01), (res.layer_volume, vol.volume)
    # the check can fail: phi_B 10 % too large (g = phi / phi_B scales by 1 / 1.1) ...
    assert not within_one_se(res.g / 1.1, res.g_se / 1.1, g3)
    # ... or the 3D layers half a layer farther out
    dt = 0.5 * (spec.t_max - spec.t_min) / (spec.n_shells - 1)
    shifted = dataclasses.replace(spec, t_min=spec.t_min + dt, t_max=spec.t_max + dt)
    vs = volume_fractions(model, shifted, spacing=0.04, replicates=4, seed=4)
    assert not within_one_se(res.g, res.g_se, vs.phi / res.phi_b)


def test_masks_with_direction_tables_match_numpy(tmp_path):
    """The layer masks of a rough particle (slices fast enough for rho_s = 1: direction tables,
    layers evaluated together) against an independent numpy labelling of the same surfaces: the
    particle where |y| <= r_0(u), else the first layer k with |y| <= r_k(u)."""
    shaped_model(tmp_path / "s.h5")
    model = read_model(tmp_path / "s.h5")
    spec = RdfSpec(t_min=0.01, t_max=0.1, n_shells=6, pixel=0.02)
    st = prepare(model, spec)
    a, b, orders, _ = st.own.layer_forms(0)
    c, rot, s = model.center[0], model.rotation[0], model.scale[0]
    planes = [Plane((c[0] - 1.6, c[1] - 1.6, c[2] + dz), (1.0, 0, 0), (0, 1.0, 0), (3.2, 3.2), 0.02)
              for dz in (-0.9, -0.3, 0.2, 0.7)]
    labels = st.own.slice_many(planes)            # four planes: the particle's pixels pay for a table
    alone = st.own.slice(planes[0])                # one plane: too few pixels for a table
    assert labels[0].stats["evaluations"] < 0.8 * alone.stats["evaluations"]
    assert np.array_equal(labels[0].layer, alone.layer) and np.array_equal(labels[0].particle, alone.particle)
    for plane, lab in zip(planes, labels):
        y = (plane.pixel_centers().reshape(-1, 3) - c) @ rot / s
        q = np.linalg.norm(y, axis=1)
        r = np.stack([form_radius(a[:, :, f], b[:, :, f], int(orders[f]), y / q[:, None])
                      for f in range(len(orders))], axis=1)
        inside = q[:, None] <= r
        part = np.where(inside[:, 0], 0, -1)
        first = np.argmax(inside[:, 1:], axis=1) + 1
        layer = np.where(inside[:, 0] | ~inside[:, 1:].any(axis=1), 0, first)
        sure = np.min(np.abs(q[:, None] - r), axis=1) > 1e-9
        assert np.array_equal(lab.particle.ravel()[sure], part[sure])
        assert np.array_equal(lab.layer.ravel()[sure], layer[sure])
        assert (layer > 0).sum() > 1000 and (part == 0).sum() > 1000


def test_rdf_and_volume_do_not_depend_on_threads(tmp_path):
    """Slices (with direction tables and layer stacks) and the volume sample (point labels) give
    byte-identical tables with 1 and 2 OpenMP threads."""
    shaped_model(tmp_path / "s.h5")
    texts = []
    for threads in ("1", "2"):
        out = tmp_path / f"g{threads}.csv"
        env = dict(os.environ, OMP_NUM_THREADS=threads)
        subprocess.run([sys.executable, "-m", "anm_post", "rdf", str(tmp_path / "s.h5"), "--pixel", "0.04",
                        "--density", "0.5", "--volume", "--spacing", "0.08", "--replicates", "2", "--csv", str(out)],
                       check=True, env=env, capture_output=True)
        texts.append(out.read_text())
    assert texts[0] == texts[1] and "g_3d" in texts[0]


def test_convergence_shares_the_rho1_result(tmp_path):
    shaped_model(tmp_path / "s.h5")
    model = read_model(tmp_path / "s.h5")
    spec = RdfSpec(pixel=0.04, axis="z")
    conv = convergence(model, spec, densities=(0.1, 1.0))
    full = rdf(model, RdfSpec(pixel=0.04, axis="z", density=1.0))
    assert np.allclose(conv.results[-1].g, full.g, equal_nan=True)
    assert len(conv.results[0].positions) < len(conv.results[1].positions)
    conv.to_csv(tmp_path / "c.csv")
    assert (tmp_path / "c.csv").read_text().startswith("density,n,layer")


def test_cli_rdf_and_errors(tmp_path, capsys):
    shaped_model(tmp_path / "s.h5")
    csv, png = tmp_path / "g.csv", tmp_path / "g.png"
    assert main(["rdf", str(tmp_path / "s.h5"), "--pixel", "0.04", "--density", "0.5", "--csv", str(csv),
                 "--png", str(png), "--volume", "--spacing", "0.08", "--replicates", "2"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "layer,t_inner_mm,t_outer_mm,g,g_sd,g_se,g_3d,g_3d_se,diff_per_se" and len(out) == 11
    text = csv.read_text().splitlines()
    assert text[0].startswith("layer,t_inner_mm,t_outer_mm,phi,g,") and "g_3d" in text[0] and len(text) == 11
    assert "volume_3d_mm3" in text[0] and "volume_slices_mm3" in text[0]
    assert png.stat().st_size > 1000
    assert main(["rdf", str(tmp_path / "s.h5"), "--volume", "--replicates", "1"]) == 1
    assert "--replicates" in capsys.readouterr().err
    assert main(["rdf", str(tmp_path / "missing.h5"), "--csv", str(csv)]) == 1
    assert "missing.h5" in capsys.readouterr().err
    assert main(["rdf", str(tmp_path / "s.h5"), "--particle", "99999"]) == 1
    assert "--particle" in capsys.readouterr().err
    assert main(["rdf", str(tmp_path / "s.h5"), "--density", "2"]) == 1
    assert "--density" in capsys.readouterr().err
    assert main(["rdf", str(tmp_path / "s.h5"), "--sieves", "0"]) == 1
    assert "small-particle sieve" in capsys.readouterr().err
    with pytest.raises(AnmPostError):
        RdfSpec(t_min=0.05, t_max=0.01)


def test_msand_wall_effect(shapes_dir, anm_bin, tmp_path):
    """On a reduced M_sand (thesis Table 3.1: the real coarse shape at order 14, real sand shapes
    0.15-0.25 mm at order 5 and 8 % of the box) in a 12 mm box with one coarse sieve at 15 %, to
    keep the test short: g < 1 next to the RDF particle, g = 1 within 3 standard errors in the
    outer layers."""
    from pathlib import Path
    nml = (Path(__file__).resolve().parents[2] / "inputs" / "msand.nml").read_text()
    nml = nml.replace("length = 20.0, 20.0, 20.0", "length = 12.0, 12.0, 12.0")
    nml = nml.replace("nsieve = 3", "nsieve = 2").replace("min_width = 9.9, 4.9, 0.15", "min_width = 9.9, 0.15")
    nml = nml.replace("max_width = 10.0, 5.0, 0.25", "max_width = 10.0, 0.25")
    nml = nml.replace("fraction = 0.20, 0.02, 0.08", "fraction = 0.15, 0.08")
    nml = nml.replace("order = 14, 14, 5", "order = 14, 5")
    nml = nml.replace("'../shared/shapes/MA111-7-coarse', '../shared/shapes/MA111-7-coarse',",
                      "'../shared/shapes/MA111-7-coarse',")
    nml = nml.replace("../shared/shapes", str(shapes_dir)).replace("directory = 'out/msand'",
                                                                   f"directory = '{tmp_path}'")
    (tmp_path / "m.nml").write_text(nml)
    subprocess.run([anm_bin, "run", str(tmp_path / "m.nml")], check=True, capture_output=True)
    model = read_model(tmp_path / "model.h5")
    # rho_s = 0.2 (about 50 slices): at 0.05 the 12 slices gave block standard errors from about 12
    # blocks, and one outer layer of this model fell 3.06 of them below 1 (z of the ten layers at
    # 0.2: -77, -19, -6.6, then within +-2.1)
    res = rdf(model, RdfSpec(pixel=0.05, density=0.2))
    print(np.round(res.g, 3), np.round(res.g_se, 3))
    assert res.g[0] + 3 * res.g_se[0] < 1
    assert np.all(np.abs(res.g[-4:] - 1) < 3 * res.g_se[-4:])


def test_sweep_table_from_run_summaries(tmp_path, capsys):
    """`anm-post sweep` collects model-summary.csv files (format of `anm run`) into one table."""
    head = "sieve,min_width_mm,max_width_mm,target_fraction,achieved_fraction,shortfall,count,shell_fraction\n"
    for t, (a1, a2, n1, n2, sh) in {0.0: (0.1, 0.2, 5, 7, 0.0), 0.01: (0.1, 0.15, 5, 6, 0.02)}.items():
        (tmp_path / f"{t}.csv").write_text(head + f"1,2,3,0.1,{a1},0,{n1},{sh / 2}\n2,1,2,0.2,{a2},0,{n2},{sh / 2}\n"
                                           f"total,,,0.3,{a1 + a2},0,{n1 + n2},{sh}\n")
    png = tmp_path / "s.png"
    assert main(["sweep", f"0.01={tmp_path / '0.01.csv'}", f"0={tmp_path / '0.0.csv'}", "--scale", "100",
                 "--shells", "--png", str(png)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[2] == "| 0 | 0.1000 | 0.2000 | 0.3000 | 5 | 7 | 12 | 0.0000 |"
    assert lines[3] == "| 1 | 0.1000 | 0.1500 | 0.2500 | 5 | 6 | 11 | 0.0200 |"
    assert png.stat().st_size > 1000
    assert main(["sweep", f"1={tmp_path / 'none.csv'}"]) == 1
    assert "none.csv" in capsys.readouterr().err


def test_rdf_particle_by_width_or_length(tmp_path, capsys):
    """The RDF particle chosen by id, by nearest width or length (the thesis: by size, section 3.4)
    or, by default, the longest: unit spheres scaled to radii 1.0, 1.4, 1.2 (sieve 0; width =
    length = 2 r) and small spheres (sieve 1, never chosen by size)."""
    from anm_post.walleffect import choose_particle, particle_widths
    path = tmp_path / "w.h5"
    radii = np.array([1.0, 1.4, 1.2, 0.1, 0.1])
    centres = np.array([[2, 2, 2], [6, 6, 6], [2, 6, 2], [6, 2, 6], [4, 4, 4.0]])
    write_model(path, [8.0] * 3, [SPHERE], [0], np.zeros(5, int), centres, np.tile(np.eye(3), (5, 1, 1)), radii,
                np.zeros(5, int), sieves=np.array([0, 0, 0, 1, 1]))
    set_widths(path, [3.0, 0.2])
    model = read_model(path)
    assert np.allclose(particle_widths(model), 2 * radii, rtol=1e-6)
    assert choose_particle(model, RdfSpec()) == 1                      # the longest
    assert choose_particle(model, RdfSpec(particle=0)) == 0
    assert choose_particle(model, RdfSpec(width=2.41)) == 2
    assert choose_particle(model, RdfSpec(length=1.9)) == 0
    assert choose_particle(model, RdfSpec(width=0.2)) == 0             # small sieves excluded
    with pytest.raises(AnmPostError, match="one of id, width and length"):
        RdfSpec(particle=0, width=2.0)
    with pytest.raises(AnmPostError, match="width must be positive"):
        RdfSpec(width=-1.0)
    assert main(["rdf", str(path), "--width", "-1"]) == 1
    assert "--width" in capsys.readouterr().err
    assert main(["rdf", str(path), "--particle", "0", "--length", "2"]) == 1
    assert "--particle/--width/--length" in capsys.readouterr().err

"""End-to-end tests of `anm shape` from Python: exact spheres, NIST's table, bad input."""
import math
import subprocess

import pytest

from anm_post import read_geometry_table, read_shape_coefficients


def write_sphere(path, radius, nmax=2):
    """A NIST-format file of a sphere: a_00 = 2 sqrt(pi) R, every other coefficient zero."""
    lines = []
    for n in range(nmax + 1):
        for m in range(n, -n - 1, -1):
            a = 2.0 * math.sqrt(math.pi) * radius if n == 0 else 0.0
            lines.append(f"{n:4d}{m:4d}{a:20.10f}{0.0:20.10f}")
    path.write_text("\n".join(lines) + "\n")


def run_shape(anm_bin, *args):
    return subprocess.run([anm_bin, "shape", *map(str, args)], capture_output=True, text=True)


def test_sphere_exact(anm_bin, tmp_path):
    radius = 3.0
    write_sphere(tmp_path / "sphere-anm-00001.dat", radius)
    res = run_shape(anm_bin, tmp_path)
    assert res.returncode == 0, res.stderr
    (tmp_path / "g.txt").write_text(res.stdout)
    t = read_geometry_table(str(tmp_path / "g.txt"))
    row = t.row("sphere-anm-00001.dat")
    assert row["volume"] == pytest.approx(4.0 / 3.0 * math.pi * radius**3, rel=1e-6)
    assert row["surf._area"] == pytest.approx(4.0 * math.pi * radius**2, rel=1e-6)
    for key in ("length(mm)", "width(mm)", "thick(mm)"):
        assert row[key] == pytest.approx(2 * radius, rel=1e-5)
    assert row["xhi"] == pytest.approx(radius, rel=1e-4)


def test_agrees_with_nist_table(anm_bin, shapes_dir, tmp_path):
    folder = shapes_dir / "MA111-7-coarse"
    nist = read_geometry_table(str(folder / "MA111-7-coarse-geom.orig.dat"))
    name = "MA111-7-coarse-anm-00002.dat"
    order = int(nist.row(name)["Nnn"])
    res = run_shape(anm_bin, folder / name, "--order", order)
    assert res.returncode == 0, res.stderr
    (tmp_path / "g.txt").write_text(res.stdout)
    ours = read_geometry_table(str(tmp_path / "g.txt")).row(name)
    ref = nist.row(name)
    assert ours["volume"] == pytest.approx(ref["volume"], rel=1e-3)
    assert ours["surf._area"] == pytest.approx(ref["surf._area"], rel=5e-3)
    assert ours["length(mm)"] == pytest.approx(ref["length(mm)"], rel=1.5e-2)
    assert ours["Itrace"] == pytest.approx(ref["Itrace"], abs=2e-3)
    n, m, a = read_shape_coefficients(str(folder / name))
    assert len(a) == 961 and n[-1] == 30 and m[-1] == -30


@pytest.mark.parametrize(
    "content, fragment",
    [
        ("   0   0        1.0000000000        0.0000000000\n   1   1        0.01\n", ":2:"),
        ("   0   0        1.0000000000        0.0000000000\n   1   1        abc        0.0\n", ":2:"),
        ("   0   0        1.0000000000        0.0000000000\n   1   0        3.0        0.0\n", ":2:"),
    ],
)
def test_bad_file_is_a_named_error(anm_bin, tmp_path, content, fragment):
    p = tmp_path / "bad.dat"
    p.write_text(content)
    res = run_shape(anm_bin, p)
    assert res.returncode != 0
    assert str(p) + fragment in res.stderr
    assert "Backtrace" not in res.stderr and "Error termination" not in res.stderr


def test_missing_path_and_bad_option(anm_bin, tmp_path):
    res = run_shape(anm_bin, tmp_path / "nope")
    assert res.returncode != 0 and "nope" in res.stderr
    res = run_shape(anm_bin, tmp_path, "--order", "x")
    assert res.returncode != 0 and "--order" in res.stderr

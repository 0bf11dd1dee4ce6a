"""Bad inputs to the `anm` program: model files (invalid ones, and valid ones written by plain
h5py with its defaults: variable-length UTF-8 strings, int64 integers), shape files and command-line
arguments. Each case asserts the exit code and a phrase of the message; no case may print a
backtrace or raw bytes (docs/reliability.md, "The anm program")."""
import math
import os
import subprocess

import h5py
import numpy as np
import pytest

TINY = "100M"   # ANM_MEMORY_LIMIT for the oversized requests (deterministic on any machine)


def run(anm_bin, *args, env=None, cwd=None):
    full = dict(os.environ)
    full.update(env or {})
    res = subprocess.run([anm_bin, *map(str, args)], capture_output=True, env=full, cwd=cwd, timeout=120)
    res.out = res.stdout.decode("utf-8", "replace")
    res.err = res.stderr.decode("utf-8", "replace")
    return res


def assert_clean_error(res, code, *phrases):
    """Exit code `code`, every phrase in stderr, no backtrace, only printable ASCII in stderr."""
    assert res.returncode == code, (res.returncode, res.out, res.err)
    for p in phrases:
        assert p in res.err, (p, res.err)
    assert "Backtrace" not in res.err and "Fortran runtime error" not in res.err, res.err
    assert all(32 <= b < 127 or b in (9, 10) for b in res.stderr), res.stderr


# ---------------------------------------------------------------- model files written by plain h5py

def plain_model(path, edit=None, n=3):
    """A valid contract-v1 model of three clear spheres, written the plain h5py way (str attributes
    and datasets: variable-length UTF-8; Python ints: int64). `edit(f)` changes it before closing."""
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "anm-model"
        f.attrs["format_version"] = 1
        f["box/length"] = [10.0, 10.0, 10.0]
        f["box"].attrs["periodic"] = 0
        c = np.zeros((1, 1, 2))
        c[0, 0, 0] = 2.0 * math.sqrt(math.pi)   # unit sphere
        f["shapes/coeffs"] = c
        f["shapes/nmax"] = [0]
        f["shapes/name"] = np.array(["sphere"], dtype=h5py.string_dtype())
        f["particles/shape"] = [0] * n
        f["particles/center"] = [[3.0, 5.0, 5.0], [5.01, 5.0, 5.0], [8.0, 8.0, 8.0]][:n]
        f["particles/rotation"] = np.stack([np.eye(3)] * n)
        f["particles/scale"] = [1.0] * n
        f["particles/nmax"] = [0] * n
        f["particles/sieve"] = [0] * n
        for k, v in [("min_width", 2.0), ("max_width", 2.0), ("target_fraction", 0.1), ("achieved_fraction", 0.1)]:
            f["sieves/" + k] = [v]
        f["sieves/count"] = [n]
        f["run/namelist"] = "&box length = 10, 10, 10 /  ! written by plain h5py"
        if edit:
            edit(f)
    return path


def replace(name, value):
    def edit(f):
        del f[name]
        f[name] = value
    return edit


def verify(anm_bin, path, *extra, env=None):
    return run(anm_bin, "verify", path, "--resolution", "24", *extra, env=env)


def test_plain_h5py_model_is_read(anm_bin, tmp_path):
    res = verify(anm_bin, plain_model(tmp_path / "plain.h5"))
    assert res.returncode == 0, res.err
    assert "result: OK" in res.out and "particles:            3" in res.out


def test_plain_h5py_strings_of_every_kind(anm_bin, tmp_path):
    """Fixed-length NUL-padded, fixed-length ASCII and variable-length strings all read."""
    def edit(f):
        f.attrs["format"] = np.bytes_("anm-model")                       # fixed, ASCII
        del f["shapes/name"]
        f["shapes/name"] = np.array([b"sphere"], dtype="S40")           # fixed, NUL-padded
        del f["run/namelist"]
        f.create_dataset("run/namelist", data="x" * 5000, dtype=h5py.string_dtype("ascii"))  # vlen ASCII
    res = verify(anm_bin, plain_model(tmp_path / "mixed.h5", edit))
    assert res.returncode == 0, res.err


def test_float32_rotation_within_tolerance(anm_bin, tmp_path):
    c, s = math.cos(0.3), math.sin(0.3)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=np.float32)
    res = verify(anm_bin, plain_model(tmp_path / "f32.h5", replace("particles/rotation", np.stack([rot] * 3))))
    assert res.returncode == 0, res.err


def _nan_center(f):
    c = f["particles/center"][...]
    c[1, 2] = np.nan
    del f["particles/center"]
    f["particles/center"] = c


def _inf_center(f):
    c = f["particles/center"][...]
    c[2, 0] = np.inf
    del f["particles/center"]
    f["particles/center"] = c


def _rot(fn):
    def edit(f):
        r = f["particles/rotation"][...]
        r[1] = fn(r[1])
        del f["particles/rotation"]
        f["particles/rotation"] = r
    return edit


def _coef_nan(f):
    c = f["shapes/coeffs"][...]
    c[0, 0, 1] = np.nan
    del f["shapes/coeffs"]
    f["shapes/coeffs"] = c


def _attr(name, value):
    def edit(f):
        f.attrs[name] = value
    return edit


def _del(name):
    def edit(f):
        del f[name]
    return edit


def _del_attr(name):
    def edit(f):
        del f.attrs[name]
    return edit


BAD_MODELS = [
    ("nan_center", _nan_center, ["/particles/center", "particle 1", "not finite"]),
    ("inf_center", _inf_center, ["/particles/center", "particle 2", "not finite"]),
    ("rotation_times_3", _rot(lambda r: 3.0 * r), ["/particles/rotation", "particle 1", "not orthonormal"]),
    ("reflection", _rot(lambda r: np.diag([1.0, 1.0, -1.0])), ["/particles/rotation", "particle 1", "determinant"]),
    ("nan_rotation", _rot(lambda r: r * np.nan), ["/particles/rotation", "particle 1", "not finite"]),
    ("negative_box", replace("box/length", [10.0, -10.0, 10.0]), ["/box/length", "edge 1", "finite and > 0"]),
    ("nan_box", replace("box/length", [np.nan, 10.0, 10.0]), ["/box/length", "edge 0"]),
    ("two_box_edges", replace("box/length", [10.0, 10.0]), ["/box/length", "expected 3 values"]),
    ("zero_scale", replace("particles/scale", [1.0, 0.0, 1.0]), ["/particles/scale", "particle 1"]),
    ("nan_scale", replace("particles/scale", [1.0, 1.0, np.nan]), ["/particles/scale", "particle 2"]),
    ("nan_coefficient", _coef_nan, ["/shapes/coeffs", "shape 0", "not a finite number"]),
    ("zero_a00", replace("shapes/coeffs", np.zeros((1, 1, 2))), ["/shapes/coeffs", "a_00"]),
    ("shape_index", replace("particles/shape", [0, 5, 0]), ["/particles/shape", "particle 1", "outside 0..0"]),
    ("negative_shape_index", replace("particles/shape", [0, 0, -2]), ["/particles/shape", "particle 2"]),
    ("particle_order", replace("particles/nmax", [0, 0, 3]), ["/particles/nmax", "particle 2", "outside 0..0"]),
    ("shape_nmax", replace("shapes/nmax", [4]), ["/shapes/nmax", "does not fit"]),
    ("sieve_index", replace("particles/sieve", [0, 1, 0]), ["/particles/sieve", "particle 1"]),
    ("short_scale", replace("particles/scale", [1.0, 1.0]), ["/particles", "inconsistent length"]),
    ("short_rotation", replace("particles/rotation", np.stack([np.eye(3)] * 2)), ["/particles/rotation", "expected shape"]),
    ("center_rank", replace("particles/center", [1.0, 2.0, 3.0]), ["/particles/center", "rank-2"]),
    ("center_strings", replace("particles/center", np.array([["a", "b", "c"]] * 3, dtype=h5py.string_dtype())),
     ["/particles/center", "read failed"]),
    ("names_count", replace("shapes/name", np.array(["a", "b"], dtype=h5py.string_dtype())), ["/shapes/name", "2 names"]),
    ("name_not_string", replace("shapes/name", [1, 2]), ["/shapes/name", "expected a string"]),
    ("format_other", _attr("format", "hdf5-something"), ["not an Anm model file", "hdf5-something"]),
    ("format_bytes", _attr("format", np.void(b"\xff\xfe\x00\x01garbage")), ["/@format"]),
    ("format_binary_string", _attr("format", np.bytes_(b"\xff\xfe\x01\x02")), ["not an Anm model file", "????"]),
    ("format_number", _attr("format", 7), ["/@format", "expected a string"]),
    ("no_format", _del_attr("format"), ["@format", "missing attribute"]),
    ("format_version_2", _attr("format_version", 2), ["unsupported format_version 2"]),
    ("format_version_0", _attr("format_version", 0), ["unsupported format_version 0"]),
    ("format_version_text", _attr("format_version", "one"), ["@format_version", "read failed"]),
    ("no_centres", _del("particles/center"), ["/particles/center", "missing dataset"]),
    ("no_namelist", _del("run/namelist"), ["/run/namelist", "missing dataset"]),
]


@pytest.mark.parametrize("name,edit,phrases", BAD_MODELS, ids=[b[0] for b in BAD_MODELS])
def test_invalid_model_is_refused(anm_bin, tmp_path, name, edit, phrases):
    path = plain_model(tmp_path / f"{name}.h5", edit)
    res = verify(anm_bin, path)
    assert_clean_error(res, 1, f"{name}.h5", *phrases)
    assert "result: OK" not in res.out


def test_model_not_hdf5_or_missing(anm_bin, tmp_path):
    (tmp_path / "text.h5").write_text("not hdf5 at all")
    assert_clean_error(verify(anm_bin, tmp_path / "text.h5"), 1, "text.h5", "not a readable HDF5 file")
    (tmp_path / "empty.h5").write_bytes(b"")
    assert_clean_error(verify(anm_bin, tmp_path / "empty.h5"), 1, "empty.h5")
    (tmp_path / "binary.h5").write_bytes(bytes(range(256)) * 8)
    assert_clean_error(verify(anm_bin, tmp_path / "binary.h5"), 1, "binary.h5")
    assert_clean_error(verify(anm_bin, tmp_path / "absent.h5"), 1, "absent.h5", "no such model file")


# ---------------------------------------------------------------- shape files

def nist_lines(nmax, a00=3.5, wide=False, extra=0.05):
    """A NIST-layout coefficient file of degree nmax (fixed %4d%4d columns unless wide)."""
    fmt = "{:5d}{:5d}{:20.10f}{:20.10f}" if wide else "{:4d}{:4d}{:20.10f}{:20.10f}"
    lines = []
    for n in range(nmax + 1):
        for m in range(n, -n - 1, -1):
            re = a00 if n == 0 else (extra / (n * n) if m == 0 else 0.0)
            lines.append(fmt.format(n, m, re, 0.0))
    return "\n".join(lines) + "\n"


def shape(anm_bin, path, *extra):
    return run(anm_bin, "shape", path, "--order", "2", *extra)


@pytest.mark.parametrize("nmax", [99, 100, 120])
def test_shape_file_high_degree(anm_bin, tmp_path, nmax):
    """Degree >= 100 in NIST's fixed columns: ' 100-100' runs together and must still be read."""
    p = tmp_path / f"deg{nmax}.dat"
    p.write_text(nist_lines(nmax))
    assert "100-100" in p.read_text() or nmax < 100
    res = shape(anm_bin, p)
    assert res.returncode == 0, res.err
    assert f"deg{nmax}" in res.out


def test_synth_writes_readable_high_degree(anm_bin, tmp_path):
    res = run(anm_bin, "synth", tmp_path / "s", "--count", "1", "--order", "100")
    assert res.returncode == 0, res.err
    files = sorted((tmp_path / "s").glob("*.dat"))
    assert len(files) == 1 and not list((tmp_path / "s").glob("*anm-tmp*"))
    lines = files[0].read_text().splitlines()
    assert len(lines) == 101 ** 2 and lines[-1].split()[:2] == ["100", "-100"]
    res = shape(anm_bin, files[0])
    assert res.returncode == 0, res.err


BAD_SHAPES = [
    ("tiny_a00", lambda: nist_lines(4, extra=0.0).replace("      3.5000000000", "1.0e-300", 1), ["degenerate shape"]),
    ("small_a00", lambda: nist_lines(4, a00=1e-9, extra=5.0), ["degenerate shape"]),
    ("nan_a00", lambda: nist_lines(2).replace("3.5000000000", "         NaN", 1), ["not a finite number"]),
    ("inf_coefficient", lambda: nist_lines(2).replace("0.0500000000", "    Infinity", 1), ["not a finite number"]),
    ("negative_a00", lambda: nist_lines(2, a00=-3.5), ["a_00 must be real and positive"]),
    ("truncated", lambda: "\n".join(nist_lines(3).splitlines()[:-2]) + "\n", ["truncated file"]),
    ("text", lambda: "hello world\n", ["expected 4 fields"]),
    ("non_numeric", lambda: "   0   0  abc  0.0\n", ["non-numeric field"]),
    ("empty", lambda: "", ["empty shape file"]),
    ("degree_201", lambda: nist_lines(201, wide=True), ["exceeds the supported maximum 200"]),
    ("binary", lambda: bytes(range(256)).decode("latin-1"), [".dat"]),
]


@pytest.mark.parametrize("name,text,phrases", BAD_SHAPES, ids=[b[0] for b in BAD_SHAPES])
def test_bad_shape_file_is_refused(anm_bin, tmp_path, name, text, phrases):
    p = tmp_path / f"{name}.dat"
    p.write_bytes(text().encode("latin-1"))
    res = shape(anm_bin, p)
    assert_clean_error(res, 1, f"{name}.dat", *phrases)


# ---------------------------------------------------------------- command line and resources

def test_no_arguments_prints_usage(anm_bin):
    res = run(anm_bin)
    assert res.returncode == 2 and "usage: anm" in res.err


# (arguments, exit code: 2 for a usage error, 1 for a bad file; phrases of the message)
CLI = [
    (["frobnicate"], 2, ["unknown command 'frobnicate'"]),
    (["verify"], 2, ["missing MODEL.h5"]),
    (["verify", "x.h5", "--resolution"], 2, ["--resolution needs a value"]),
    (["verify", "x.h5", "--resolution", "abc"], 2, ["'abc' is not an integer"]),
    (["verify", "x.h5", "--resolution", "2"], 2, ["must be >= 4"]),
    (["verify", "x.h5", "--resolution", "99999999999"], 2, ["not an integer"]),
    (["verify", "x.h5", "--tolerance", "1e"], 2, ["--tolerance"]),
    (["verify", "x.h5", "--bogus"], 2, ["unknown option '--bogus'", "anm verify --help"]),
    (["shape"], 2, ["missing FILE or DIR"]),
    (["shape", "a.dat", "b.dat"], 2, ["more than one path"]),
    (["shape", "a.dat", "--order", "-1"], 2, ["must be >= 0"]),
    (["shape", "/nonexistent/shape.dat"], 1, ["no such shape file or folder"]),
    (["synth"], 2, ["missing output DIR"]),
    (["synth", "d", "--count", "0"], 2, ["must be >= 1"]),
    (["run"], 2, ["usage: anm run FILE.nml"]),
    (["run", "a.nml", "--bogus"], 2, ["unknown option '--bogus'"]),
    (["run", "/nonexistent.nml"], 1, ["/nonexistent.nml"]),
    (["rerun"], 2, ["usage: anm rerun MODEL.h5"]),
    (["rerun", "m.h5", "--output"], 2, ["--output needs a value"]),
    (["rerun", "/nonexistent.h5"], 1, ["/nonexistent.h5"]),
    (["study", "next"], 2, ["usage: anm study"]),
]


@pytest.mark.parametrize("args,code,phrases", CLI, ids=[" ".join(c[0]) or "none" for c in CLI])
def test_bad_command_line(anm_bin, tmp_path, args, code, phrases):
    assert_clean_error(run(anm_bin, *args, cwd=tmp_path), code, *phrases)


def test_verify_resolution_beyond_memory(anm_bin, tmp_path):
    path = plain_model(tmp_path / "m.h5")
    res = run(anm_bin, "verify", path, "--resolution", "2000", env={"ANM_MEMORY_LIMIT": TINY})
    assert_clean_error(res, 1, "--resolution 2000 needs about", "ANM_MEMORY_LIMIT", "reduce --resolution")
    res = run(anm_bin, "verify", path, "--resolution", "1000000", env={"ANM_MEMORY_LIMIT": "1T"})
    assert_clean_error(res, 1, "reduce --resolution")


def test_synth_count_beyond_memory(anm_bin, tmp_path):
    res = run(anm_bin, "synth", tmp_path / "s", "--count", "1000000000", env={"ANM_MEMORY_LIMIT": "4G"})
    assert_clean_error(res, 1, "--count 1000000000 needs about", "reduce --count")
    assert not (tmp_path / "s").exists()


NML = """&box length = {box}, {box}, {box} /
&sieves nsieve = 1, min_width = 1.5, max_width = 2.0, fraction = 0.1, order = 4 /
&synthetic count = {count} /
&output directory = '{out}', name = 'm', vrml = .false. /
&run seed = 1 /
"""


def test_run_synthetic_count_beyond_memory(anm_bin, tmp_path):
    nml = tmp_path / "big.nml"
    nml.write_text(NML.format(box=6, count=1000000000, out=tmp_path / "out"))
    res = run(anm_bin, "run", nml, env={"ANM_MEMORY_LIMIT": "8G"})
    assert_clean_error(res, 1, "big.nml", "needs about", "&synthetic count")


def test_run_particle_count_beyond_memory(anm_bin, tmp_path):
    nml = tmp_path / "huge.nml"
    nml.write_text(NML.format(box=3000, count=2, out=tmp_path / "out"))
    res = run(anm_bin, "run", nml, env={"ANM_MEMORY_LIMIT": "8G"})
    assert_clean_error(res, 1, "huge.nml", "needs about", "&box length", "particles estimated")


def test_run_output_folder_unusable_before_parking(anm_bin, tmp_path):
    (tmp_path / "file").write_text("a file, not a folder")
    nml = tmp_path / "o.nml"
    nml.write_text(NML.format(box=6, count=2, out=tmp_path / "file" / "sub"))
    res = run(anm_bin, "run", nml)
    assert_clean_error(res, 1, "o.nml", "&output: directory")
    assert "sieve" not in res.err   # refused before parking (no progress line)

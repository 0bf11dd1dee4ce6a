"""Bad input to `anm-post` (issue 12): invalid model files, model files written by plain h5py
(must work), text inputs that are binary or latin-1, and bad command-line arguments of every
subcommand. Each case asserts the exit code (1: input refused at run time, 2: usage) and a
phrase of the message, and that no traceback is printed. Cases run in-process (cli.main) for
speed; a few run as a real process (python -m anm_post) to see what a user sees.

The counts of these cases are reported in docs/reliability.md ("anm-post (Python)")."""
from __future__ import annotations

import subprocess
import sys
from math import pi, sqrt
from pathlib import Path

import h5py
import numpy as np
import pytest

from synth import write_model

from anm_post import read_model
from anm_post.cli import main
from anm_post.validate import ROTATION_TOLERANCE

SPHERE = np.array([[sqrt(4 * pi), 0.0]])
#: Commands that read a model, as argument lists after the model path.
MODEL_COMMANDS = {
    "table": ["table", "{m}"],
    "slice": ["slice", "{m}", "--pixel", "0.2", "--position", "5"],
    "rdf": ["rdf", "{m}", "--pixel", "0.2", "--particle", "0"],
    "convergence": ["convergence", "{m}", "--pixel", "0.2", "--particle", "0", "--densities", "0.5"],
}


def good_model(path: Path) -> Path:
    """Three spheres (order 0) in a 10 mm box: a big one (sieve 0) and two small ones (sieve 1)."""
    write_model(path, [10.0] * 3, [SPHERE], [0], [0, 0, 0], [[5, 5, 5], [1.5, 1.5, 1.5], [8.5, 8.5, 8.5]],
                np.tile(np.eye(3), (3, 1, 1)), [2.0, 0.3, 0.3], [0, 0, 0], sieves=[0, 1, 1])
    with h5py.File(path, "r+") as fh:
        fh["sieves/max_width"][...] = [4.0, 0.6]
        fh["sieves/min_width"][...] = [3.6, 0.5]
    return path


def run(capsys, *argv) -> tuple[int, str, str]:
    """cli.main in-process: (exit code, stdout, stderr); argparse usage errors give code 2."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    assert "Traceback" not in err, err
    return code, out, err


def run_process(*argv) -> subprocess.CompletedProcess:
    res = subprocess.run([sys.executable, "-m", "anm_post", *map(str, argv)], capture_output=True, text=True)
    assert "Traceback" not in res.stderr, res.stderr
    return res


# -- invalid model files ------------------------------------------------------------------------------

def _set(name, value):
    def change(fh):
        fh[name][...] = value
    return change


def _set_row(name, row, value):
    def change(fh):
        data = fh[name][()]
        data[row] = value
        fh[name][...] = data
    return change


def _attr(name, value):
    def change(fh):
        fh.attrs[name] = value
    return change


def _delete(name):
    def change(fh):
        del fh[name]
    return change


BAD_MODELS = {
    # case: (change of a good file, phrase of the message)
    "nan_centre": (_set_row("particles/center", 1, [np.nan, 1.0, 1.0]), "particles/center: particle 1"),
    "inf_centre": (_set_row("particles/center", 2, [1.0, np.inf, 1.0]), "particles/center: particle 2"),
    "rotation_times_3": (_set_row("particles/rotation", 1, 3 * np.eye(3)), "particle 1: not orthonormal"),
    "reflection": (_set_row("particles/rotation", 2, np.diag([1.0, 1.0, -1.0])), "particle 2: determinant -1"),
    "shear": (_set_row("particles/rotation", 0, [[1, 1e-3, 0], [0, 1, 0], [0, 0, 1]]), "not orthonormal"),
    "nan_rotation": (_set_row("particles/rotation", 0, np.full((3, 3), np.nan)), "particle 0: not finite"),
    "negative_box": (_set("box/length", [10.0, -10.0, 10.0]), "box/length: edge lengths must be finite and > 0"),
    "zero_box": (_set("box/length", [10.0, 10.0, 0.0]), "box/length"),
    "nan_box": (_set("box/length", [10.0, np.nan, 10.0]), "box/length"),
    "zero_scale": (_set_row("particles/scale", 1, 0.0), "particles/scale: particle 1"),
    "negative_scale": (_set_row("particles/scale", 2, -1.0), "particles/scale: particle 2"),
    "inf_scale": (_set_row("particles/scale", 0, np.inf), "particles/scale: particle 0"),
    "nan_coefficient": (_set_row("shapes/coeffs", 0, [[np.nan, 0.0]]), "shapes/coeffs: shape 0: coefficient 0"),
    "shape_index_high": (_set_row("particles/shape", 2, 1), "particles/shape: particle 2: shape index 1"),
    "shape_index_negative": (_set_row("particles/shape", 0, -1), "particle 0: shape index -1"),
    "order_above_shape_nmax": (_set_row("particles/nmax", 1, 3), "particles/nmax: particle 1: order 3"),
    "shape_nmax_above_stored": (_set("shapes/nmax", [5]), "shapes/nmax: shape 0: nmax = 5"),
    "sieve_index_high": (_set_row("particles/sieve", 1, 7), "particles/sieve: particle 1"),
    "nan_sieve_width": (_set_row("sieves/max_width", 0, np.nan), "sieves/max_width"),
    "unknown_format_version": (_attr("format_version", 2), "unknown format_version 2"),
    "missing_format_version": (lambda fh: fh.attrs.__delitem__("format_version"), "'format_version' missing"),
    "other_format": (_attr("format", "anm-slice"), "not an Anm model file"),
    "format_not_utf8": (_attr("format", np.bytes_(b"\xff\xfe\x80garbage")), "not an Anm model file"),
    "missing_format": (lambda fh: fh.attrs.__delitem__("format"), "not an Anm model file"),
    "names_not_utf8": (lambda fh: (fh.__delitem__("shapes/name"),
                                   fh.create_dataset("shapes/name", data=np.array([b"\xe9t\xe9"], "S8"))),
                       "shapes/name[0]: not UTF-8 text"),
    "centre_shape_wrong": (lambda fh: (fh.__delitem__("particles/scale"),
                                       fh.create_dataset("particles/scale", data=np.ones(2))),
                           "particles/"),
}
MISSING = ("box/length", "shapes/coeffs", "shapes/nmax", "shapes/name", "particles/shape", "particles/center",
           "particles/rotation", "particles/scale", "particles/nmax", "particles/sieve", "sieves/count")


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("models")


def bad_model(folder: Path, case: str) -> Path:
    path = folder / (case.replace("/", "_").replace(":", "-") + ".h5")
    if not path.exists():
        good_model(path)
        change = BAD_MODELS[case][0] if case in BAD_MODELS else _delete(case.removeprefix("missing:"))
        with h5py.File(path, "r+") as fh:
            change(fh)
    return path


@pytest.mark.parametrize("command", sorted(MODEL_COMMANDS))
@pytest.mark.parametrize("case", sorted(BAD_MODELS))
def test_invalid_model_is_refused_by_every_command(capsys, model_dir, case, command):
    path = bad_model(model_dir, case)
    argv = [a.format(m=path) for a in MODEL_COMMANDS[command]]
    code, _, err = run(capsys, *argv)
    assert code == 1, (case, command, err)
    assert err.startswith("anm-post: error: ") and str(path) in err, err
    assert BAD_MODELS[case][1] in err, (case, err)
    assert "\\x" not in err and "b'" not in err, f"raw bytes in the message: {err}"


@pytest.mark.parametrize("dataset", MISSING)
def test_missing_dataset_is_named(capsys, model_dir, dataset):
    path = bad_model(model_dir, "missing:" + dataset)
    code, _, err = run(capsys, "slice", path, "--pixel", "0.2", "--position", "5")
    assert code == 1 and f"{path}::/{dataset}: dataset missing" in err, err


@pytest.mark.parametrize("content, phrase", [(b"", "not an HDF5 file"), (b"hello, not HDF5\n", "not an HDF5 file"),
                                             (bytes(range(256)) * 8, "not an HDF5 file"),
                                             (b"\x89HDF\r\n\x1a\n" + b"\0" * 100, "cannot read as HDF5")])
def test_not_hdf5(capsys, tmp_path, content, phrase):
    path = tmp_path / "model.h5"
    path.write_bytes(content)
    for command in ("slice", "rdf"):
        argv = [a.format(m=path) for a in MODEL_COMMANDS[command]]
        code, _, err = run(capsys, *argv)
        assert code == 1 and str(path) in err and phrase in err, err


def test_missing_model_and_folder(capsys, tmp_path):
    code, _, err = run(capsys, "slice", tmp_path / "none.h5", "--pixel", "0.2", "--position", "5")
    assert code == 1 and "model file not found" in err
    code, _, err = run(capsys, "rdf", tmp_path, "--pixel", "0.2")
    assert code == 1 and "not a file" in err


def test_rotation_within_tolerance_is_accepted(capsys, tmp_path):
    """A rotation off by a tenth of the stated tolerance is honest rounding: accepted."""
    path = good_model(tmp_path / "m.h5")
    with h5py.File(path, "r+") as fh:
        r = fh["particles/rotation"][()]
        r[1] = np.eye(3) + 0.05 * ROTATION_TOLERANCE * np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 0]])
        fh["particles/rotation"][...] = r
    assert read_model(path).n_particles == 3


# -- valid models written by plain h5py (variable-length and padded fixed-length strings) -------------

def plain_h5py_model(path: Path, vlen: bool) -> Path:
    """A model written the ordinary h5py way: string attributes and datasets as h5py stores
    Python str (variable-length UTF-8), or as NUL/space-padded fixed-length bytes."""
    good_model(path)
    with h5py.File(path, "r+") as fh:
        del fh["shapes/name"]
        if vlen:
            fh.attrs["format"] = "anm-model"                      # variable-length UTF-8
            fh.create_dataset("shapes/name", data=["sphère-0"], dtype=h5py.string_dtype())
            fh.create_dataset("run/namelist", data="&run seed = 1 /\n", dtype=h5py.string_dtype())
            fh["run"].attrs["program_version"] = "anm 0.2 (été)"
        else:
            fh.attrs["format"] = np.bytes_(b"anm-model\0\0\0")   # fixed-length, NUL-padded
            fh.create_dataset("shapes/name", data=np.array([b"sphere-0    "], "S12"))   # space-padded
            fh.create_dataset("run/namelist", data=np.bytes_(b"&run seed = 1 /\n"))
            fh["run"].attrs["program_version"] = np.bytes_(b"anm 0.2")
        fh.attrs["format_version"] = np.int64(1)
    return path


@pytest.mark.parametrize("vlen", [True, False], ids=["vlen", "fixed"])
def test_plain_h5py_model_works(capsys, tmp_path, vlen):
    path = plain_h5py_model(tmp_path / "m.h5", vlen)
    model = read_model(path)
    assert model.shape_names == (["sphère-0"] if vlen else ["sphere-0"])
    assert model.attrs["namelist"] == "&run seed = 1 /\n"
    assert model.attrs["program_version"].startswith("anm 0.2")
    code, out, err = run(capsys, "table", path, "--format", "csv")
    assert code == 0 and out.splitlines()[-1].endswith(",3"), (out, err)
    code, out, err = run(capsys, "slice", path, "--pixel", "0.1", "--position", "5")
    assert code == 0 and "particle area fraction 0.12" in out, (out, err)   # pi 2^2 / 100


# -- text inputs: binary, latin-1, NUL, empty ------------------------------------------------------

TEXTS = {
    "binary": (bytes(range(1, 256)) * 4, "not UTF-8 text"),
    "latin1": ("next,v_box,v_box_certified\n10,1.0,1.2\n# réglé\n".encode("latin-1"), ":3: not UTF-8 text"),
    "nul": (b"next,v_box,v_box_certified\n10,1\x00,1\n", ":2: binary data"),
    "empty": (b"", "empty"),
}


@pytest.mark.parametrize("case", sorted(TEXTS))
def test_plot_and_sweep_on_bad_text(capsys, tmp_path, case):
    content, phrase = TEXTS[case]
    path = tmp_path / "in.csv"
    path.write_bytes(content)
    code, _, err = run(capsys, "plot", path, "-o", tmp_path / "p.png")
    assert code == 1 and phrase in err and str(path) in err, err
    code, _, err = run(capsys, "sweep", f"1={path}")
    assert code == 1 and str(path) in err, err
    assert phrase in err or case == "empty", err
    assert not (tmp_path / "p.png").exists()


def test_table_on_binary_geometry_table(capsys, tmp_path):
    path = tmp_path / "geom.txt"
    path.write_bytes(bytes(range(1, 256)) * 4)
    code, _, err = run(capsys, "table", path)
    assert code == 1 and str(path) in err


def test_real_process_no_traceback(tmp_path):
    """The same as a user sees it: exit code and message of a separate process."""
    latin = tmp_path / "l.csv"
    latin.write_bytes("nbox,d_overlap\n1,0.\xe9\n".encode("latin-1"))
    res = run_process("plot", latin)
    assert res.returncode == 1 and res.stderr.startswith("anm-post: error: ") and "not UTF-8" in res.stderr
    path = good_model(tmp_path / "m.h5")
    res = run_process("slice", path, "--pixel", "1e-5", "--position", "5")
    assert res.returncode == 1 and "--pixel" in res.stderr and "memory" in res.stderr, res.stderr
    res = run_process("slice", path, "--pixel", "abc", "--position", "5")
    assert res.returncode == 2 and "invalid float value" in res.stderr


# -- command-line arguments of every subcommand ------------------------------------------------------

#: (subcommand arguments with {m} = a good model and {d} = a scratch folder, exit code, phrase)
BAD_ARGS = [
    ([], 2, "required"),
    (["bogus"], 2, "invalid choice"),
    (["table"], 2, "required"),
    (["table", "{m}", "--format", "html"], 2, "invalid choice"),
    (["table", "{d}/none.txt"], 1, "cannot read"),
    (["table", "{m}", "--csv", "{d}"], 1, "is a folder"),
    (["table", "{m}", "--csv", "{d}/no/such/folder/t.csv"], 1, "does not exist"),
    (["table", "{m}", "--csv", "{m}"], 1, "would overwrite an input"),
    (["slice", "{m}"], 2, "--pixel"),
    (["slice", "{m}", "--pixel", "x", "--position", "5"], 2, "invalid float value"),
    (["slice", "{m}", "--pixel", "-0.1", "--position", "5"], 1, "--pixel"),
    (["slice", "{m}", "--pixel", "0", "--position", "5"], 1, "--pixel"),
    (["slice", "{m}", "--pixel", "nan", "--position", "5"], 1, "--pixel"),
    (["slice", "{m}", "--pixel", "inf", "--position", "5"], 1, "--pixel"),
    (["slice", "{m}", "--pixel", "1e-5", "--position", "5"], 1, "more than the"),
    (["slice", "{m}", "--pixel", "1e-4", "--density", "1"], 1, "more than the"),
    (["slice", "{m}", "--pixel", "0.1"], 1, "--position"),
    (["slice", "{m}", "--pixel", "0.1", "--position", "50"], 1, "--position"),
    (["slice", "{m}", "--pixel", "0.1", "--position", "nan"], 1, "--position"),
    (["slice", "{m}", "--pixel", "0.1", "--axis", "w", "--position", "5"], 2, "invalid choice"),
    (["slice", "{m}", "--pixel", "0.1", "--density", "0"], 1, "--density"),
    (["slice", "{m}", "--pixel", "0.1", "--density", "2"], 1, "--density"),
    (["slice", "{m}", "--pixel", "0.1", "--density", "nan"], 1, "--density"),
    (["slice", "{m}", "--pixel", "0.1", "--position", "5", "--shells", "x"], 1, "--shells"),
    (["slice", "{m}", "--pixel", "0.1", "--position", "5", "--shells", "-0.1"], 1, "--shells"),
    (["slice", "{m}", "--pixel", "0.1", "--position", "5", "--shells", "0.2,0.1"], 1, "--shells"),
    (["slice", "{m}", "--pixel", "0.1", "--position", "5", "--shells", "nan"], 1, "--shells"),
    (["slice", "{m}", "--pixel", "0.1", "--position", "5", "--shells", "0.1", "--shell-particles", "9"], 1,
     "--shell-particles"),
    (["slice", "{m}", "--pixel", "0.1", "--position", "5", "--shells", "0.1", "--shell-particles", "a"], 1,
     "--shell-particles"),
    (["slice", "{m}", "--pixel", "0.1", "--center", "1", "1", "1"], 1, "go together"),
    (["slice", "{m}", "--pixel", "0.1", "--center", "1", "1", "1", "--normal", "0", "0", "0", "--size", "2", "2"], 1,
     "--normal"),
    (["slice", "{m}", "--pixel", "0.1", "--center", "1", "1", "1", "--normal", "0", "0", "1", "--size", "-2", "2"],
     1, "--size"),
    (["slice", "{m}", "--pixel", "0.1", "--center", "nan", "1", "1", "--normal", "0", "0", "1", "--size", "2", "2"],
     1, "--center"),
    (["slice", "{m}", "--pixel", "0.1", "--center", "a", "1", "1"], 2, "not a number"),
    (["slice", "{m}", "--pixel", "0.1", "--position", "5", "--labels", "{d}/x.txt"], 1, "must end in .npz"),
    (["slice", "{m}", "--pixel", "0.1", "--position", "5", "--png", "{d}/x.txt"], 1, "unknown picture format"),
    (["slice", "{m}", "--pixel", "0.1", "--position", "5", "--png", "{d}/a.png", "--labels", "{d}/a.png"], 1,
     "given to both"),
    (["slice", "{m}", "--pixel", "0.1", "--position", "5", "--labels", "{m}"], 1, "would overwrite an input"),
    (["plot"], 2, "required"),
    (["plot", "{d}/none.csv"], 1, "cannot read"),
    (["plot", "{d}/study.csv", "-o", "{d}/p.doc"], 1, "unknown picture format"),
    (["plot", "{d}/study.csv", "-o", "{d}/study.csv"], 1, "would overwrite an input"),
    (["plot", "{d}/badheader.csv"], 1, "header must be"),
    (["plot", "{d}/notnumber.csv"], 1, "not a number"),
    (["rdf", "{m}", "--bins", "0"], 1, "--bins"),
    (["rdf", "{m}", "--bins", "x"], 2, "invalid int value"),
    (["rdf", "{m}", "--shells", "4"], 1, "--bins"),
    (["rdf", "{m}", "--t-min", "0.1", "--t-max", "0.01"], 1, "--t-min/--t-max"),
    (["rdf", "{m}", "--t-min", "nan"], 1, "--t-min/--t-max"),
    (["rdf", "{m}", "--pixel", "0"], 1, "--pixel"),
    (["rdf", "{m}", "--pixel", "1e-6"], 1, "more than the"),
    (["rdf", "{m}", "--density", "2"], 1, "--density"),
    (["rdf", "{m}", "--particle", "9"], 1, "--particle"),
    (["rdf", "{m}", "--particle", "1"], 1, "small-particle sieve"),
    (["rdf", "{m}", "--replicates", "1"], 1, "--replicates"),
    (["rdf", "{m}", "--seed", "-1"], 1, "--seed"),
    (["rdf", "{m}", "--spacing", "0", "--volume"], 1, "--spacing"),
    (["rdf", "{m}", "--sieves", "a"], 1, "--sieves"),
    (["rdf", "{m}", "--sieves", "5"], 1, "sieve"),
    (["rdf", "{m}", "--phi-b", "2"], 1, "--phi-b"),
    (["rdf", "{m}", "--phi-b", "nan"], 1, "--phi-b"),
    (["rdf", "{m}", "--unit", "inch"], 2, "invalid choice"),
    (["rdf", "{m}", "--png", "{d}/g.xyz"], 1, "unknown picture format"),
    (["convergence", "{m}", "--densities", "a"], 1, "--densities"),
    (["convergence", "{m}", "--densities", "0,2"], 1, "--densities"),
    (["convergence", "{m}", "--densities", ","], 1, "--densities"),
    (["convergence", "{m}", "--layers", "99"], 1, "--layers"),
    (["convergence", "{m}", "--rdf-png", "{d}/c.bad"], 1, "unknown picture format"),
    (["sweep"], 2, "required"),
    (["sweep", "abc"], 1, "expected VALUE=SUMMARY.csv"),
    (["sweep", "x=s.csv"], 1, "expected VALUE=SUMMARY.csv"),
    (["sweep", "1={d}/none.csv"], 1, "cannot read"),
    (["sweep", "1={d}/study.csv"], 1, "not a model summary"),
    (["sweep", "1={d}/s2.csv", "2={d}/s3.csv"], 1, "different numbers of sieves"),
    (["sweep", "nan={d}/s2.csv"], 1, "not a finite number"),
    (["sweep", "1={d}/s2.csv", "--scale", "nan"], 1, "--scale"),
    (["sweep", "1={d}/s2.csv", "--png", "{d}/s.txt"], 1, "unknown picture format"),
    (["sweep", "1={d}/s2.csv", "--markdown", "{d}/s2.csv"], 1, "would overwrite an input"),
]


def summary_csv(path: Path, nsieve: int) -> Path:
    rows = ["sieve,achieved_fraction,count,shell_fraction"]
    rows += [f"{k + 1},0.1,{10 * (k + 1)},0.01" for k in range(nsieve)]
    rows.append(f"total,{0.1 * nsieve},{sum(10 * (k + 1) for k in range(nsieve))},0.02")
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    d = tmp_path_factory.mktemp("args")
    good_model(d / "m.h5")
    (d / "study.csv").write_text("next,v_box,v_box_certified\n10,1.0,1.2\n20,1.1,1.15\n")
    (d / "badheader.csv").write_text("foo,bar\n1,2\n")
    (d / "notnumber.csv").write_text("nbox,d_overlap\n1,abc\n")
    summary_csv(d / "s2.csv", 2)
    summary_csv(d / "s3.csv", 3)
    return d


@pytest.mark.parametrize("argv, code, phrase", BAD_ARGS, ids=[" ".join(a[0][:1] + a[0][2:])[:60] or "none"
                                                              for a in BAD_ARGS])
def test_bad_arguments(capsys, scratch, argv, code, phrase):
    before = sorted(p.name for p in scratch.iterdir())
    got, out, err = run(capsys, *[a.format(m=scratch / "m.h5", d=scratch) for a in argv])
    assert got == code, (argv, got, err)
    assert phrase in err, (argv, err)
    if code == 1:
        assert err.startswith("anm-post: error: "), err
    assert sorted(p.name for p in scratch.iterdir()) == before, "a refused command left a file"


def test_good_arguments_still_work(capsys, scratch, tmp_path):
    """The guards do not refuse the ordinary uses (each subcommand once)."""
    m = scratch / "m.h5"
    assert run(capsys, "table", m, "--csv", tmp_path / "t.csv")[0] == 0
    assert (tmp_path / "t.csv").read_text().startswith("sieve,")
    assert run(capsys, "slice", m, "--pixel", "0.2", "--position", "5", "--png", tmp_path / "s.png",
               "--labels", tmp_path / "s.npz")[0] == 0
    assert run(capsys, "slice", m, "--pixel", "0.5", "--density", "0.5", "--labels", tmp_path / "st.h5")[0] == 0
    code, out, err = run(capsys, "plot", scratch / "study.csv", "-o", tmp_path / "p.png")
    assert code == 0 and out.strip() == str(tmp_path / "p.png"), (out, err)
    assert run(capsys, "rdf", m, "--pixel", "0.2", "--density", "0.2", "--csv", tmp_path / "g.csv")[0] == 0
    assert run(capsys, "sweep", f"1={scratch / 's2.csv'}", "--markdown", tmp_path / "s.md",
               "--png", tmp_path / "s.png")[0] == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["g.csv", "p.png", "s.md", "s.npz", "s.png", "st.h5", "t.csv"], names

"""The command lines behave like their neighbours (issue 17 item 5, docs/cli.md): `--help` for
every command of `anm` and `anm-post` (usage on stdout, exit 0), `--version` for both (one
version), usage errors exit 2, `anm run` refuses a model file and points to `anm rerun`, which
re-runs the stored namelist into a new folder, and existing outputs are kept unless `--force` or
`&output overwrite = .true.`."""
import os
import pathlib
import re
import subprocess
import sys

import h5py
import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
VERSION = re.search(r'^version\s*=\s*"([^"]+)"', (ROOT / "fpm.toml").read_text(), re.M).group(1)
ANM_COMMANDS = ["run", "rerun", "verify", "shape", "synth", "study"]
POST_COMMANDS = ["table", "slice", "plot", "rdf", "convergence", "sweep", "law"]

NML = """&box length = 6, 6, 6 /
&sieves nsieve = 1, min_width = 1.5, max_width = 2.0, fraction = 0.04, order = 4, source = 'synthetic' /
&synthetic count = 2 /
&output directory = '{dir}', name = 'm', vrml = {vrml}{extra} /
&run seed = 11 /
"""


def anm(anm_bin, *args, cwd=None):
    return subprocess.run([anm_bin, *map(str, args)], capture_output=True, text=True, timeout=300, cwd=cwd)


def post(*args):
    return subprocess.run([sys.executable, "-m", "anm_post", *map(str, args)], capture_output=True, text=True,
                          timeout=120)


@pytest.mark.parametrize("command", ANM_COMMANDS)
@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_anm_command_help(anm_bin, command, flag, tmp_path):
    res = anm(anm_bin, command, flag, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert res.stdout.lstrip().startswith(command + " ") and res.stderr == ""
    assert list(tmp_path.iterdir()) == []   # nothing run, nothing written


def test_anm_help_lists_every_command(anm_bin):
    res = anm(anm_bin, "--help")
    assert res.returncode == 0
    for c in ANM_COMMANDS:
        assert re.search(rf"^  {c} ", res.stdout, re.M), c


@pytest.mark.parametrize("command", POST_COMMANDS)
def test_anm_post_command_help(command):
    res = post(command, "--help")
    assert res.returncode == 0 and res.stdout.startswith("usage: anm-post " + command), res.stderr


def test_one_version(anm_bin):
    assert anm(anm_bin, "--version").stdout.strip() == f"anm {VERSION}"
    res = post("--version")
    assert res.returncode == 0 and res.stdout.strip() == f"anm-post {VERSION}", res.stderr


def test_usage_errors_exit_2(anm_bin, tmp_path):
    for args in (["run", "x.nml", "--frob"], ["verify"], ["nope"], ["shape", "--order"]):
        res = anm(anm_bin, *args, cwd=tmp_path)
        assert res.returncode == 2 and "anm: error:" in res.stderr, (args, res.stderr)
    assert post("slice").returncode == 2
    assert post("table", "x", "--bogus").returncode == 2


def write_nml(tmp_path, vrml=".false.", extra=""):
    nml = tmp_path / "m.nml"
    nml.write_text(NML.format(dir=tmp_path / "out", vrml=vrml, extra=extra))
    return nml


def test_existing_outputs_are_kept_without_force(anm_bin, tmp_path):
    nml = write_nml(tmp_path)
    assert anm(anm_bin, "run", nml).returncode == 0
    model = tmp_path / "out" / "m.h5"
    before = model.read_bytes()
    res = anm(anm_bin, "run", nml)
    assert res.returncode == 1
    assert str(model) in res.stderr and "--force" in res.stderr and "overwrite = .true." in res.stderr
    assert model.read_bytes() == before
    res = anm(anm_bin, "run", nml, "--force")
    assert res.returncode == 0, res.stderr
    assert anm(anm_bin, "run", "--force", nml).returncode == 0


def test_overwrite_in_the_namelist(anm_bin, tmp_path):
    nml = write_nml(tmp_path, extra=", overwrite = .true.")
    assert anm(anm_bin, "run", nml).returncode == 0
    assert anm(anm_bin, "run", nml).returncode == 0
    with h5py.File(tmp_path / "out" / "m.h5") as f:
        assert "overwrite = .true." in f["run/resolved_namelist"][()].decode()


def test_any_existing_output_is_named(anm_bin, tmp_path):
    """Not only the model: a lone VRML file of an earlier run is refused as well."""
    nml = write_nml(tmp_path, vrml=".true.")
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "m.wrl").write_text("#VRML V2.0 utf8\n")
    res = anm(anm_bin, "run", nml)
    assert res.returncode == 1 and "m.wrl exists" in res.stderr
    assert not (tmp_path / "out" / "m.h5").exists()


def test_run_refuses_a_model_and_rerun_repeats_it(anm_bin, tmp_path):
    nml = write_nml(tmp_path)
    first = anm(anm_bin, "run", nml)
    assert first.returncode == 0, first.stderr
    model = tmp_path / "out" / "m.h5"
    res = anm(anm_bin, "run", model)
    assert res.returncode == 1 and "not a namelist file" in res.stderr and "anm rerun" in res.stderr
    again = tmp_path / "again"
    res = anm(anm_bin, "rerun", model, "--output", again)
    assert res.returncode == 0, res.stderr
    assert (again / "namelist.nml").read_text().strip() == nml.read_text().strip()
    with h5py.File(model) as a, h5py.File(again / "m.h5") as b:
        for name in ("particles/center", "particles/rotation", "particles/scale", "sieves/count"):
            assert np.array_equal(a[name][()], b[name][()]), name
    # the same folder again: refused, then --force
    assert anm(anm_bin, "rerun", model, "--output", again).returncode == 1
    assert anm(anm_bin, "rerun", model, "--output", again, "--force").returncode == 0
    # default folder: beside the model, MODEL-rerun
    res = anm(anm_bin, "rerun", model)
    assert res.returncode == 0 and (tmp_path / "out" / "m-rerun" / "m.h5").is_file(), res.stderr


def test_closing_line_names_the_files_written(anm_bin, tmp_path):
    nml = tmp_path / "l.nml"
    nml.write_text(NML.format(dir=tmp_path / "o", vrml=".true.", extra=", vrml_per_layer = .true.")
                   + "&shells nlayer = 1, thickness = 0.05 /\n")
    res = anm(anm_bin, "run", nml)
    assert res.returncode == 0, res.stderr
    line = res.stdout.strip().splitlines()[-1]
    names = re.findall(r"(\S+\.(?:h5|csv|wrl))", line)
    assert names and all(pathlib.Path(n).is_file() for n in names), line
    assert not (tmp_path / "o" / "m.wrl").exists() and "m.wrl" not in line.replace("-particles.wrl", "")


def test_an_earlier_vrml_goes_with_the_set(anm_bin, tmp_path):
    """A run without VRML into a folder holding an earlier run's VRML of the same name: refused
    without --force (the file would be removed); with --force the folder ends with this run's
    set only, and files of other names stay."""
    with_vrml = write_nml(tmp_path, vrml=".true.")
    assert anm(anm_bin, "run", with_vrml).returncode == 0
    out = tmp_path / "out"
    assert (out / "m.wrl").exists()
    (out / "m-layer2.wrl").write_text("#VRML V2.0 utf8\n")     # a per-layer file of another run
    (out / "other.wrl").write_text("#VRML V2.0 utf8\n")        # another name: not ours
    (out / "m-layerx.wrl").write_text("#VRML V2.0 utf8\n")     # not a name Anm writes
    without = write_nml(tmp_path, vrml=".false.")
    for name in ("m.h5", "m-summary.csv"):      # the VRML alone is left of the earlier run
        (out / name).unlink()
    res = anm(anm_bin, "run", without)
    assert res.returncode == 1 and "m-layer2.wrl exists" in res.stderr and "--force" in res.stderr, res.stderr
    assert (out / "m.wrl").exists()
    res = anm(anm_bin, "run", without, "--force")
    assert res.returncode == 0, res.stderr
    names = sorted(p.name for p in out.iterdir())
    assert names == ["m-layerx.wrl", "m-summary.csv", "m.h5", "other.wrl"], names

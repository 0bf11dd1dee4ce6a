"""The shell specification travels with the model: `anm run` stores /shells (layers, unit, mode,
colours) and every anm-post command defaults to it; --shells overrides; older files without the
group still work."""
import subprocess
import sys

import h5py
import numpy as np
import pytest

from anm_post.model import read_model
from anm_post.slicing import ShellSpec, Slicer, axis_plane

NML = """&box length = 6, 6, 6 /
&sieves nsieve = 1, min_width = 1.5, max_width = 2.0, fraction = 0.08, order = 6 /
&synthetic count = 3 /
&shells nlayer = 2, thickness = {t1}, {t2}, thickness_unit = '{unit}', mode = 'overlap',
        colour = 1, 0, 0,  0, 0, 1 /
&output directory = '{out}', name = 'm', vrml = .false. /
&run seed = 7 /
"""


def park(anm_bin, tmp_path, unit="fraction", t1=0.02, t2=0.05):
    out = tmp_path / unit
    nml = tmp_path / f"{unit}.nml"
    nml.write_text(NML.format(out=out, unit=unit, t1=t1, t2=t2))
    res = subprocess.run([anm_bin, "run", str(nml)], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    return out / "m.h5"


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "anm_post", *args], capture_output=True, text=True)


@pytest.mark.parametrize("unit,t1,t2", [("fraction", 0.02, 0.05), ("mm", 0.03, 0.08)])
def test_run_stores_the_shell_specification(anm_bin, tmp_path, unit, t1, t2):
    path = park(anm_bin, tmp_path, unit, t1, t2)
    with h5py.File(path) as f:
        g = f["shells"]
        assert int(g.attrs["nlayer"]) == 2
        assert g.attrs["unit"].decode().strip() == unit and g.attrs["mode"].decode().strip() == "overlap"
        assert np.array_equal(g["thickness"][()], [t1, t2])
        assert np.array_equal(g["colour"][()], [[1, 0, 0], [0, 0, 1]])
        per = f["particles/shell_thickness"][()]
    model = read_model(path)
    assert model.shells["unit"] == unit and model.shells["nlayer"] == 2
    assert per.shape == (model.n_particles, 2) and model.n_particles > 0
    if unit == "mm":
        assert np.all(per == [t1, t2])
    else:
        # fraction of each particle's length L (mm): t * L, L between the sieve's widths and 3 widths
        ratio = per[:, 1] / per[:, 0]
        assert np.allclose(ratio, t2 / t1)
        assert np.all(per[:, 0] > t1 * 1.5) and np.all(per[:, 0] < t1 * 6.0)


def test_slicer_uses_the_engine_thicknesses(anm_bin, tmp_path):
    path = park(anm_bin, tmp_path, "mm", 0.03, 0.08)
    model = read_model(path)
    spec = ShellSpec.stored(model)
    assert spec is not None and spec.from_model and spec.unit == "mm" and spec.thickness == (0.03, 0.08)
    slicer = Slicer(model, spec)
    tsu = slicer._shell_shape_units(np.arange(model.n_particles))
    # exactly the engine's mm values over the scale: no second rounding (the explicit --shells path
    # quantises mm thicknesses to a 2 % ladder)
    assert np.array_equal(tsu, model.shell_thickness / model.scale[:, None])
    explicit = Slicer(model, ShellSpec((0.03, 0.08), unit="mm"))._shell_shape_units(np.arange(model.n_particles))
    assert np.allclose(explicit, tsu, rtol=0.011)


def labels(tmp_path, path, *extra, name="l.npz"):
    out = tmp_path / name
    res = run_cli("slice", str(path), "--axis", "z", "--position", "3", "--pixel", "0.05", "--labels", str(out),
                  *extra)
    assert res.returncode == 0, res.stderr
    return np.load(out)


def test_slice_defaults_to_the_stored_shells(anm_bin, tmp_path):
    path = park(anm_bin, tmp_path, "fraction", 0.05, 0.1)     # layers of 2-8 pixels
    default = labels(tmp_path, path, name="d.npz")
    assert set(np.unique(default["layer"])) >= {1, 2}
    same = labels(tmp_path, path, "--shells", "model", name="m.npz")
    assert np.array_equal(default["layer"], same["layer"])
    none = labels(tmp_path, path, "--shells", "none", name="n.npz")
    assert not np.any(none["layer"])
    assert np.array_equal(none["particle"], default["particle"])
    override = labels(tmp_path, path, "--shells", "0.1", name="o.npz")
    assert set(np.unique(override["layer"])) == {0, 1}


def test_old_model_without_shells_group(anm_bin, tmp_path):
    path = park(anm_bin, tmp_path)
    old = tmp_path / "old.h5"
    with h5py.File(path) as src, h5py.File(old, "w") as dst:
        for k, v in src.attrs.items():
            dst.attrs[k] = v
        for name in ("box", "shapes", "particles", "sieves", "run"):
            src.copy(src[name], dst, name)
    model = read_model(old)
    assert model.shells is None and ShellSpec.stored(model) is None
    assert not np.any(labels(tmp_path, old, name="a.npz")["layer"])          # no shells by default
    assert set(np.unique(labels(tmp_path, old, "--shells", "0.05", name="b.npz")["layer"])) == {0, 1}
    res = run_cli("slice", str(old), "--position", "3", "--pixel", "0.05", "--shells", "model")
    assert res.returncode == 1 and "stores no shell layers" in res.stderr and "--shells 0.02" in res.stderr


def test_one_meaning_of_shells(anm_bin, tmp_path):
    path = park(anm_bin, tmp_path)
    res = run_cli("rdf", str(path), "--shells", "10")
    assert res.returncode == 1 and "--bins" in res.stderr and "Traceback" not in res.stderr
    res = run_cli("sweep", f"0.02={tmp_path / 'fraction' / 'm-summary.csv'}", "--shells", "0.02")
    assert res.returncode == 1 and "--shells" in res.stderr and "Traceback" not in res.stderr

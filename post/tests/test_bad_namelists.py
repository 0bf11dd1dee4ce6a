"""Bad namelists given to the `anm` program: each is refused with a non-zero exit, a message that
names the file (and the line where there is one) and no backtrace (issue 12, namelist part)."""
import subprocess

import pytest

GOOD = """&box length = 6, 6, 6 /
&sieves nsieve = 1, min_width = 1.5, max_width = 2.0, fraction = 0.05, order = 4 /
&synthetic count = 2 /
&output directory = '{out}', name = 'm', vrml = .false. /
"""


def run_anm(anm_bin, path):
    return subprocess.run([anm_bin, "run", str(path)], capture_output=True, text=True, timeout=120)


def refused(anm_bin, tmp_path, text, *phrases, name="bad.nml"):
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text.replace("{out}", str(tmp_path / "out")))
    res = run_anm(anm_bin, path)
    assert res.returncode != 0, res.stdout + res.stderr
    msg = res.stderr
    assert name in msg, msg
    for phrase in phrases:
        assert phrase in msg, (phrase, msg)
    assert "Backtrace" not in msg and "Traceback" not in msg, msg
    assert not (tmp_path / "out" / "m.h5").exists()
    return msg


@pytest.mark.parametrize("group", ["parkng", "ouptut", "shell"])
def test_unknown_group(anm_bin, tmp_path, group):
    refused(anm_bin, tmp_path, GOOD + "! a comment line\n&" + group + " x = 1 /\n",
            f"bad.nml:6: unknown namelist group &{group}")


def test_duplicate_group(anm_bin, tmp_path):
    refused(anm_bin, tmp_path, GOOD + "&run seed = 1 /\n&run seed = 2 /\n", "bad.nml:6:", "&run given twice",
            "first at line 5")


@pytest.mark.parametrize("value", ["NaN", "Inf", "-Infinity", "nan"])
def test_not_finite_reals(anm_bin, tmp_path, value):
    text = GOOD.replace("length = 6, 6, 6 /", f"length = 6,\n   {value}, 6 /")
    refused(anm_bin, tmp_path, text, "bad.nml:1: &box: length(2)", "not a finite number")


@pytest.mark.parametrize("name,value", [("fraction", "NaN"), ("min_width", "Inf")])
def test_not_finite_sieves(anm_bin, tmp_path, name, value):
    sieves = {"nsieve": "1", "min_width": "1.5", "max_width": "2.0", "fraction": "0.05"}
    sieves[name] = value
    text = GOOD.replace("&sieves nsieve = 1, min_width = 1.5, max_width = 2.0, fraction = 0.05, order = 4 /",
                        "&sieves\n" + "\n".join(f"  {k} = {v}" for k, v in sieves.items()) + " /")
    line = 3 + list(sieves).index(name)
    refused(anm_bin, tmp_path, text, f"bad.nml:{line}: &sieves: {name}", "not a finite number")


def test_not_finite_shells_and_synthetic(anm_bin, tmp_path):
    refused(anm_bin, tmp_path, GOOD + "&shells nlayer = 1, thickness = Inf /\n", "bad.nml:5: &shells: thickness(1)",
            "not a finite number")
    refused(anm_bin, tmp_path, GOOD.replace("count = 2 /", "count = 2, bc_mean = NaN /"),
            "bad.nml:3: &synthetic: bc_mean", "not a finite number")


def test_line_of_a_bad_value_is_named(anm_bin, tmp_path):
    text = GOOD + "&parking\n  max_locations = 100\n  n_ext = forty\n  n_box = 64\n/\n"
    refused(anm_bin, tmp_path, text, "bad.nml:7: &parking", "n_ext = forty")


def test_line_of_a_misspelt_variable_is_named(anm_bin, tmp_path):
    text = GOOD + "&parking\n  max_locations = 100\n  max_orientatoins = 3\n/\n"
    refused(anm_bin, tmp_path, text, "bad.nml:7: &parking", "max_orientatoins")


def test_line_of_a_range_error_is_named(anm_bin, tmp_path):
    text = GOOD + "&parking\n  max_locations = 100\n\n  n_box = 1\n/\n"
    refused(anm_bin, tmp_path, text, "bad.nml:8: &parking: n_box = 1 must be >= 2")


@pytest.mark.parametrize("value", ["1.0", "-0.5", "1.5"])
def test_dense_grow_scale_out_of_range_is_named(anm_bin, tmp_path, value):
    text = GOOD + f"&parking strategy = 'dense',\n  dense_grow_scale = {value} /\n"
    refused(anm_bin, tmp_path, text, "bad.nml:6: &parking: dense_grow_scale", "must be 0 (no growth) or in (0, 1)")


@pytest.mark.parametrize("value", ["-0.1", "1.5"])
def test_dense_overfill_out_of_range_is_named(anm_bin, tmp_path, value):
    text = GOOD + f"&parking strategy = 'dense', dense_grow_scale = 0.7,\n  dense_overfill = {value} /\n"
    refused(anm_bin, tmp_path, text, "bad.nml:6: &parking: dense_overfill", "must be in [0, 1]")


def test_dense_max_failures_negative_is_named(anm_bin, tmp_path):
    text = GOOD + "&parking strategy = 'dense',\n  dense_max_failures = -1 /\n"
    refused(anm_bin, tmp_path, text, "bad.nml:6: &parking: dense_max_failures = -1 must be >= 0")


@pytest.mark.parametrize("value", ["0", "0.2", "-1e-3"])
def test_contact_gap_out_of_range_is_named(anm_bin, tmp_path, value):
    text = GOOD + f"&parking max_locations = 100,\n  contact_gap = {value} /\n"
    refused(anm_bin, tmp_path, text, "bad.nml:6: &parking: contact_gap", "must be in [1e-4, 0.05]")


def test_unknown_vrml_layout_is_named(anm_bin, tmp_path):
    text = GOOD.replace("vrml = .false. /", "vrml = .true.,\n  vrml_layout = 'flattened' /")
    refused(anm_bin, tmp_path, text, "bad.nml:5: &output: vrml_layout = 'flattened' must be 'instanced' or 'flat'")


def test_model_file_is_not_a_namelist(anm_bin, tmp_path):
    import h5py
    path = tmp_path / "model.h5"
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "anm-model"
    res = run_anm(anm_bin, path)
    assert res.returncode != 0 and "model.h5: not a namelist file" in res.stderr and "HDF5" in res.stderr
    assert "Backtrace" not in res.stderr


def test_binary_file_is_not_a_namelist(anm_bin, tmp_path):
    refused(anm_bin, tmp_path, bytes(range(256)) * 4, "not a namelist file", "binary content", name="blob.nml")


def test_text_that_is_not_a_namelist(anm_bin, tmp_path):
    refused(anm_bin, tmp_path, "x,y,z\n1,2,3\n", "bad.nml:1: text outside a namelist group")
    refused(anm_bin, tmp_path, "   \n\n", "not a namelist file", name="empty.nml")


def test_unclosed_group(anm_bin, tmp_path):
    refused(anm_bin, tmp_path, GOOD + "&run seed = 3\n", "bad.nml:5: namelist group &run is not closed")


def test_good_namelist_runs_and_large_seed_is_kept(anm_bin, tmp_path):
    """The counterpart: the same file without the fault runs; a seed above 2^31 is stored whole."""
    import h5py
    seed = 2**40 + 12345
    path = tmp_path / "good.nml"
    path.write_text(GOOD.replace("{out}", str(tmp_path / "out")) + f"&run seed = {seed} /\n")
    res = run_anm(anm_bin, path)
    assert res.returncode == 0, res.stderr
    with h5py.File(tmp_path / "out" / "m.h5") as f:
        stored = f["run"].attrs["seed"]
        assert stored.dtype.itemsize == 8 and int(stored) == seed
        assert f"seed = {seed}" in f["run/resolved_namelist"][()].decode()

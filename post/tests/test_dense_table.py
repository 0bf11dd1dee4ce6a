"""scripts/dense_table.py writes, for each gradation, an RSA and a dense namelist that differ only
in `&parking`, with shares of the requested total (shares summing to 1 as anm requires)."""
import importlib.util
import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("dense_table", ROOT / "scripts" / "dense_table.py")
dt = importlib.util.module_from_spec(spec)
spec.loader.exec_module(dt)


def _group(text, name):
    a, b = dt._span(text, name)
    return text[a:b]


def test_rsa_and_dense_differ_only_in_parking(tmp_path):
    for g in ("concrete", "msand", "table2_3"):
        rsa = dt.namelist(g, "rsa", 0.6, 300, tmp_path)
        dense = dt.namelist(g, "dense", 0.6, 300, tmp_path)
        assert "strategy" not in _group(rsa, "parking")
        assert "strategy = 'dense'" in _group(dense, "parking")
        assert "dense_time_limit = 300" in _group(dense, "parking")
        assert rsa.replace(_group(rsa, "parking"), "") == dense.replace(_group(dense, "parking"), "")
        assert f"directory = '{tmp_path}'" in _group(rsa, "output")


def test_shares_of_the_total():
    text = dt.namelist("msand", "rsa", 0.55, 300, pathlib.Path("/tmp/x"))
    sieves = _group(text, "sieves")
    shares = [float(v) for v in re.search(r"^\s*fraction\s*=\s*([^\n]+)$", sieves, re.M).group(1).split(",")]
    assert abs(sum(shares) - 1.0) < 1e-9
    assert abs(shares[0] / shares[2] - 0.20 / 0.08) < 1e-6
    assert "total_fraction = 0.55" in sieves
    # a '/' inside a quoted shape folder does not end the group
    assert "MA107-6-fine'" in sieves
    t23 = _group(dt.namelist("table2_3", "dense", 0.62, 300, pathlib.Path("/tmp/x")), "sieves")
    assert "total_fraction = 0.62" in t23 and "0.18, 0.18" in t23

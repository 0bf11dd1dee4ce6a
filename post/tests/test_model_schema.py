"""The model file describes itself: every group and dataset a run writes carries `units` and
`description` attributes, and docs/model-file.md lists exactly those rows (the table between the
`model-schema` markers), so the file and the document cannot drift apart. Integer counts are
stored as integers."""
import pathlib
import re
import subprocess

import h5py
import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]

NML = """&box length = 6, 6, 6, periodic = .true. /
&sieves nsieve = 1, min_width = 1.5, max_width = 2.0, fraction = 0.05, order = 6, source = 'synthetic' /
&synthetic count = 2 /
&shells nlayer = 1, thickness = 0.1, thickness_unit = 'mm' /
&run seed = 3 /
&output directory = '{dir}', name = 'm', vrml = .false. /
"""


def doc_table():
    """Rows of the schema table in docs/model-file.md: path -> (units, description)."""
    text = (ROOT / "docs" / "model-file.md").read_text()
    block = text.split("<!-- model-schema: begin", 1)[1].split("<!-- model-schema: end", 1)[0]
    rows = {}
    for line in block.splitlines():
        m = re.match(r"\|\s*`([^`]+)`\s*\|([^|]*)\|([^|]*)\|(.*)\|\s*$", line)
        if m:
            rows[m.group(1)] = (m.group(3).strip(), m.group(4).strip())
    return rows


def text(value):
    return value.decode() if isinstance(value, bytes) else str(value)


@pytest.fixture(scope="module")
def model(anm_bin, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("schema")
    nml = tmp / "m.nml"
    nml.write_text(NML.format(dir=tmp))
    res = subprocess.run([anm_bin, "run", str(nml)], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    return tmp / "m.h5"


def test_every_object_is_described_as_the_document_says(model):
    rows = doc_table()
    assert len(rows) >= 20
    seen = []
    with h5py.File(model, "r") as f:
        objects = [("/", f)]
        f.visititems(lambda name, obj: objects.append(("/" + name, obj)))
        for path, obj in objects:
            assert path in rows, f"{path} is written but not listed in docs/model-file.md"
            assert "units" in obj.attrs and "description" in obj.attrs, f"{path} lacks units/description"
            assert (text(obj.attrs["units"]), text(obj.attrs["description"])) == rows[path], path
            seen.append(path)
    # the run had shells: every documented object is written
    assert sorted(seen) == sorted(rows)


def test_counts_are_integers(model):
    with h5py.File(model, "r") as f:
        attempts = f["run"].attrs["attempts"]
        assert np.asarray(attempts).dtype == np.int64
        assert int(attempts) > 0
        assert f["sieves/count"].dtype.kind == "i"
        assert np.asarray(f["run"].attrs["seed"]).dtype == np.int64


def test_old_float_attempts_still_read(model, tmp_path):
    from anm_post.model import read_model
    old = tmp_path / "old.h5"
    old.write_bytes(model.read_bytes())
    with h5py.File(old, "r+") as f:
        n = int(f["run"].attrs["attempts"])
        del f["run"].attrs["attempts"]
        f["run"].attrs["attempts"] = np.float64(n)
    assert read_model(str(old)).attrs["attempts"] == n
    assert read_model(str(model)).attrs["attempts"] == n

"""The on-disk kind cache (ANM_CACHE, docs/shells.md "Kind cache"): a second run reads the kinds
instead of building them, a damaged entry is rejected and rebuilt, and the model is the same with
and without the cache."""
import os
import re
import subprocess

import h5py
import numpy as np

NML = """&box length = 6, 6, 6, periodic = .true. /
&sieves nsieve = 1, min_width = 1.5, max_width = 2.0, fraction = 0.06, order = 6 /
&synthetic count = 3 /
&shells nlayer = 1, thickness = 0.05, thickness_unit = 'mm', mode = 'exclude' /
&output directory = '{out}', name = 'm', vrml = .false., overwrite = .true. /
&run seed = 11 /
"""


def park(anm_bin, tmp_path, name, cache):
    out = tmp_path / name
    nml = tmp_path / f"{name}.nml"
    nml.write_text(NML.format(out=out))
    env = dict(os.environ, OMP_NUM_THREADS="2")
    env.pop("ANM_CACHE", None)
    if cache is not None:
        env["ANM_CACHE"] = str(cache)
    res = subprocess.run([anm_bin, "run", str(nml)], capture_output=True, text=True, timeout=300, env=env)
    assert res.returncode == 0, res.stderr
    return out / "m.h5", res.stderr


def datasets(path):
    found = {}
    with h5py.File(path) as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset) and not name.startswith("run/"):
                found[name] = obj[()]
        f.visititems(visit)
    return found


def same_models(a, b):
    da, db = datasets(a), datasets(b)
    assert da.keys() == db.keys()
    for k in da:
        assert np.array_equal(da[k], db[k]), k


def counts(stderr):
    m = re.search(r"kinds: (\d+) bases and (\d+) shells built; cache .*?: (\d+) read, (\d+) written, "
                  r"(\d+) rejected", stderr)
    assert m, stderr
    return tuple(int(g) for g in m.groups())


def test_cache_reused_rejected_when_damaged_and_models_identical(anm_bin, tmp_path):
    cache = tmp_path / "cache"
    plain, err0 = park(anm_bin, tmp_path, "plain", "off")
    assert "cache" not in err0
    cold, err1 = park(anm_bin, tmp_path, "cold", cache)
    bases, shells, read, written, rejected = counts(err1)
    assert bases > 0 and shells > 0 and read == 0 and written == bases + shells and rejected == 0
    warm, err2 = park(anm_bin, tmp_path, "warm", cache)
    assert counts(err2) == (0, 0, bases + shells, 0, 0)
    # damage two entries: one byte flipped, one truncated; a third replaced by another's content
    entries = sorted(cache.glob("*.kind"), key=lambda p: p.stat().st_size)
    assert len(entries) == bases + shells >= 3
    data = bytearray(entries[-1].read_bytes())
    data[-50] ^= 0xFF
    entries[-1].write_bytes(bytes(data))
    entries[0].write_bytes(entries[0].read_bytes()[:-4])
    entries[1].write_bytes(entries[-2].read_bytes())
    damaged, err3 = park(anm_bin, tmp_path, "damaged", cache)
    b3, s3, read3, written3, rejected3 = counts(err3)
    assert rejected3 == 3 and written3 == 3 and b3 + s3 == 3 and read3 == bases + shells - 3
    for m in (cold, warm, damaged):
        same_models(plain, m)

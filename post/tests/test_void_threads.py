"""Void placement gives the same model with 1 and 2 threads (the void grid advances at fixed
stream numbers, so batching cannot change which grid a centre is drawn from)."""
import os
import subprocess

import h5py
import numpy as np

NML = """&box length = 9.0, 9.0, 9.0, periodic = .true. /
&sieves nsieve = 2, min_width = 2.0, 1.0, max_width = 2.4, 1.2, fraction = 0.3, 0.1,
   source = 'sphere', 'sphere', order = 0, 0 /
&parking max_locations = 300, placement = 'void', max_failures = 5 /
&output directory = '{dir}', name = 'model', vrml = .false. /
&run seed = 7 /
"""


def run(anm_bin, tmp_path, threads):
    out = tmp_path / f"t{threads}"
    nml = tmp_path / f"void{threads}.nml"
    nml.write_text(NML.format(dir=out))
    env = dict(os.environ, OMP_NUM_THREADS=str(threads))
    res = subprocess.run([anm_bin, "run", str(nml)], capture_output=True, text=True, timeout=600, env=env)
    assert res.returncode == 0, res.stdout + res.stderr
    with h5py.File(out / "model.h5", "r") as f:
        return {k: f["particles"][k][()] for k in ("center", "rotation", "scale", "sieve")}


def test_void_placement_same_model_with_1_and_2_threads(anm_bin, tmp_path):
    one = run(anm_bin, tmp_path, 1)
    two = run(anm_bin, tmp_path, 2)
    assert one["scale"].size > 50
    for key in one:
        assert np.array_equal(one[key], two[key]), key

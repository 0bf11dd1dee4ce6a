"""The model file contract from the outside: a model written by Python with h5py is read and
audited by `anm verify`; two runs of one namelist and seed give equal files."""
import math
import subprocess

import h5py
import numpy as np
import pytest


def write_sphere_model(path, centers, box, periodic, radius=1.0):
    """A contract-v1 model of spheres (order 0) written independently of the Fortran code."""
    n = len(centers)
    with h5py.File(path, "w") as f:
        f.attrs["format"] = np.bytes_("anm-model")
        f.attrs["format_version"] = np.int32(1)
        f.create_dataset("box/length", data=np.array(box, dtype=np.float64))
        f["box"].attrs["periodic"] = np.int32(1 if periodic else 0)
        coeffs = np.zeros((1, 1, 2))
        coeffs[0, 0, 0] = 2.0 * math.sqrt(math.pi) * radius
        f.create_dataset("shapes/coeffs", data=coeffs)
        f.create_dataset("shapes/nmax", data=np.zeros(1, dtype=np.int32))
        f.create_dataset("shapes/name", data=np.array([b"sphere"], dtype="S16"))
        f.create_dataset("particles/shape", data=np.zeros(n, dtype=np.int32))
        f.create_dataset("particles/center", data=np.array(centers, dtype=np.float64))
        rot = np.zeros((n, 3, 3))
        rot[:] = np.eye(3)
        f.create_dataset("particles/rotation", data=rot)
        f.create_dataset("particles/scale", data=np.ones(n))
        f.create_dataset("particles/nmax", data=np.zeros(n, dtype=np.int32))
        f.create_dataset("particles/sieve", data=np.zeros(n, dtype=np.int32))
        for name, val in [("min_width", 2.0), ("max_width", 2.0), ("target_fraction", 0.1), ("achieved_fraction", 0.1)]:
            f.create_dataset(f"sieves/{name}", data=np.array([val]))
        f.create_dataset("sieves/count", data=np.array([n], dtype=np.int32))
        f.create_dataset("run/namelist", data=np.bytes_("written by the test"))


def verify(anm_bin, path):
    return subprocess.run([anm_bin, "verify", str(path), "--resolution", "40"], capture_output=True, text=True)


def test_verify_accepts_clear_model(anm_bin, tmp_path):
    p = tmp_path / "clear.h5"
    write_sphere_model(p, [[3, 5, 5], [5.01, 5, 5], [8, 8, 8]], [10, 10, 10], False)
    res = verify(anm_bin, p)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "overlapping pairs:    0" in res.stdout


def test_verify_fails_on_overlap_and_wall(anm_bin, tmp_path):
    p = tmp_path / "overlap.h5"
    write_sphere_model(p, [[3, 5, 5], [4.9, 5, 5]], [10, 10, 10], False)
    res = verify(anm_bin, p)
    assert res.returncode == 3 and "FAIL" in res.stdout
    p = tmp_path / "wall.h5"
    write_sphere_model(p, [[0.5, 5, 5]], [10, 10, 10], False)
    res = verify(anm_bin, p)
    assert res.returncode == 3 and "wall violations:      1" in res.stdout


def test_verify_bad_file_is_named(anm_bin, tmp_path):
    p = tmp_path / "junk.h5"
    p.write_text("not hdf5")
    res = verify(anm_bin, p)
    assert res.returncode == 1 and "junk.h5" in res.stderr and "Backtrace" not in res.stderr


NML = """&box length = 6, 6, 6 /
&sieves nsieve = 2, min_width = 1.5, 0.6, max_width = 2.0, 0.8, fraction = 0.1, 0.05, order = 8, 4 /
&synthetic count = 4 /
&output directory = '{out}', name = 'm', vrml = .true. /
&run seed = {seed} /
"""


def run(anm_bin, tmp_path, name, seed):
    nml = tmp_path / f"{name}.nml"
    nml.write_text(NML.format(out=tmp_path / name, seed=seed))
    res = subprocess.run([anm_bin, "run", str(nml)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return tmp_path / name / "m.h5"


def collect(path):
    """Every dataset and attribute of a file, except wall-time figures."""
    out = {}
    with h5py.File(path) as f:
        def visit(name, obj):
            for k, v in obj.attrs.items():
                if k != "wall_time":
                    out[f"{name}@{k}"] = np.asarray(v)
            if isinstance(obj, h5py.Dataset):
                out[name] = obj[()]
        f.visititems(visit)
        for k, v in f.attrs.items():
            out[f"/@{k}"] = np.asarray(v)
    return out


def test_same_seed_same_file(anm_bin, tmp_path):
    a = collect(run(anm_bin, tmp_path, "a", 5))
    b = collect(run(anm_bin, tmp_path, "b", 5))
    c = collect(run(anm_bin, tmp_path, "c", 6))
    assert a.keys() == b.keys()
    for k in a:
        if k == "run/namelist" or k == "run/resolved_namelist":
            continue   # they name the output folder, which differs
        assert np.array_equal(a[k], b[k]), k
    assert not np.array_equal(a["particles/center"], c["particles/center"]) or \
        a["particles/center"].shape != c["particles/center"].shape


def test_model_contract_shapes_and_rotations(anm_bin, tmp_path):
    path = run(anm_bin, tmp_path, "d", 7)
    with h5py.File(path) as f:
        n = f["particles/center"].shape[0]
        assert f["particles/rotation"].shape == (n, 3, 3)
        R = f["particles/rotation"][:]
        assert np.allclose(R @ np.transpose(R, (0, 2, 1)), np.eye(3), atol=1e-12)
        assert np.allclose(np.linalg.det(R), 1.0)
        assert (f["particles/center"][:] >= 0).all() and (f["particles/center"][:] <= 6).all()
        assert f["shapes/coeffs"].shape[2] == 2 and f["particles/shape"][:].max() < f["shapes/nmax"].shape[0]
        assert f["sieves/count"][:].sum() == n
    assert (tmp_path / "d" / "m-summary.csv").read_text().startswith("sieve,")
    assert (tmp_path / "d" / "m.wrl").read_text().startswith("#VRML V2.0 utf8")


def test_rotation_convention_world_equals_R_at_body(anm_bin, tmp_path):
    """An egg r = 1 + 0.5 cos(theta) whose body +z is turned to world +x by R (world = R @ body)
    reaches 1.5 mm along +x: a sphere 2.3 mm away along +x overlaps it, one along -x does not."""
    def model(path, offset):
        write_sphere_model(path, [[5, 5, 5], [5 + offset, 5, 5]], [10, 10, 10], False)
        with h5py.File(path, "r+") as f:
            coeffs = np.zeros((2, 4, 2))
            coeffs[:, 0, 0] = 2.0 * math.sqrt(math.pi)
            coeffs[0, 2, 0] = 0.5 / math.sqrt(3.0 / (4.0 * math.pi))   # line 3 of NIST order: n=1, m=0
            del f["shapes/coeffs"], f["shapes/nmax"], f["shapes/name"], f["particles/shape"], f["particles/rotation"]
            del f["particles/nmax"]
            f.create_dataset("shapes/coeffs", data=coeffs)
            f.create_dataset("shapes/nmax", data=np.array([1, 0], dtype=np.int32))
            f.create_dataset("shapes/name", data=np.array([b"egg", b"sphere"], dtype="S16"))
            f.create_dataset("particles/shape", data=np.array([0, 1], dtype=np.int32))
            f.create_dataset("particles/nmax", data=np.array([1, 0], dtype=np.int32))
            R = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])   # body +z -> world +x
            f.create_dataset("particles/rotation", data=np.stack([R, np.eye(3)]))
    model(tmp_path / "plus.h5", 2.3)
    model(tmp_path / "minus.h5", -2.3)
    assert verify(anm_bin, tmp_path / "plus.h5").returncode == 3
    assert verify(anm_bin, tmp_path / "minus.h5").returncode == 0

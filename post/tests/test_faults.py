"""Faults during the output of `anm run` (docs/reliability.md, "The anm program"): a full disk
during each kind of output (a small tmpfs), a file-size limit (`ulimit -f`), a run killed
(SIGKILL) while writing, two runs writing the same output at once. After each: a non-zero exit
where it failed, the earlier files byte-identical, no temporary file left, never a final file
from two runs.

The full-disk test mounts a tmpfs, which needs root: it is skipped when mounting is not permitted,
except under CI=true where it must run."""
import hashlib
import os
import pathlib
import resource
import signal
import subprocess
import time

import h5py
import numpy as np
import pytest

NML = """&box length = 6, 6, 6 /
&sieves nsieve = 2, min_width = 1.5, 0.6, max_width = 2.0, 0.8, fraction = 0.1, 0.05, order = 8, 4 /
&synthetic count = 4 /
&shells nlayer = 1, thickness = 0.05, mode = 'overlap' /
&output directory = '{out}', name = 'm', vrml = .true., vrml_per_layer = .true., tessellation = {tess}, {tess} /
&run seed = {seed} /
"""
OUTPUTS = ["m.h5", "m-summary.csv", "m-particles.wrl", "m-layer1.wrl"]
CI = os.environ.get("CI", "").lower() in ("true", "1")


def digest(path):
    return hashlib.sha256(pathlib.Path(path).read_bytes()).hexdigest()


def h5_digest(path):
    """Digest of a model's particle datasets (the file itself also holds the wall time)."""
    with h5py.File(path, "r") as f:
        return hashlib.sha256(b"".join(np.ascontiguousarray(f[f"particles/{k}"][...]).tobytes()
                                       for k in ("center", "rotation", "scale", "shape"))).hexdigest()


def fingerprint(folder):
    """Per output: the file's digest (the model: of its particle datasets)."""
    folder = pathlib.Path(folder)
    return {n: (h5_digest if n.endswith(".h5") else digest)(folder / n) for n in OUTPUTS}


def temporaries(folder):
    return sorted(p.name for p in pathlib.Path(folder).iterdir() if ".anm-tmp-" in p.name or p.name.endswith(".tmp"))


def start(anm_bin, workdir, out, seed, tess=12, limit=None):
    nml = pathlib.Path(workdir) / f"run-{seed}-{tess}-{time.monotonic_ns()}.nml"
    nml.write_text(NML.format(out=out, seed=seed, tess=tess))

    def preexec():
        signal.signal(signal.SIGXFSZ, signal.SIG_DFL)   # as from a shell: the program must ignore it itself
        if limit is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    env = dict(os.environ, OMP_NUM_THREADS="1")
    return subprocess.Popen([anm_bin, "run", "--force", str(nml)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            preexec_fn=preexec, env=env)


def finish(proc, timeout=120):
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out.decode(errors="replace"), err.decode(errors="replace")


@pytest.fixture(scope="module")
def refs(anm_bin, tmp_path_factory):
    """Reference outputs of seeds 1 and 2, written to ordinary folders."""
    base = tmp_path_factory.mktemp("refs")
    procs = {s: start(anm_bin, base, base / f"seed{s}", s) for s in (1, 2)}
    result = {}
    for s, p in procs.items():
        rc, out, err = finish(p)
        assert rc == 0, err
        folder = base / f"seed{s}"
        result[s] = {"folder": folder, "fp": fingerprint(folder),
                     "size": {n: (folder / n).stat().st_size for n in OUTPUTS}}
    return result


def copy_earlier(refs, folder):
    folder.mkdir(parents=True, exist_ok=True)
    for n in OUTPUTS:
        (folder / n).write_bytes((refs[1]["folder"] / n).read_bytes())


def pages(n, page=4096):
    return -(-n // page) * page


@pytest.fixture
def tmpfs(tmp_path):
    mnt = tmp_path / "disk"
    mnt.mkdir()
    res = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=4m", "tmpfs", str(mnt)], capture_output=True, text=True)
    if res.returncode != 0:
        if CI:
            pytest.fail(f"cannot mount a tmpfs under CI=true: {res.stderr.strip()}")
        pytest.skip(f"mounting a tmpfs is not permitted here ({res.stderr.strip()}); runs under CI=true as root")
    yield mnt
    subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


# free space (bytes) left for the new outputs, per output that must fail: less than it needs
def _free_for(size, failing):
    before = sum(pages(size[n]) for n in OUTPUTS[:OUTPUTS.index(failing)])
    return before + (pages(size[failing]) // 2 // 4096) * 4096 if failing.endswith(".wrl") or failing.endswith(".h5") \
        else before


@pytest.mark.parametrize("failing", OUTPUTS)
def test_full_disk_during_output(anm_bin, refs, tmpfs, tmp_path, failing):
    out = tmpfs / "out"
    copy_earlier(refs, out)
    free = _free_for(refs[2]["size"], failing)
    st = os.statvfs(tmpfs)
    fill = st.f_bavail * st.f_frsize - free
    assert fill > 0
    with open(tmpfs / "filler", "wb") as f:
        f.write(b"\0" * fill)
    rc, _, err = finish(start(anm_bin, tmp_path, out, 2))
    assert rc == 1, err
    assert "anm: error:" in err and failing in err and "Backtrace" not in err, err
    assert fingerprint(out) == refs[1]["fp"]                    # earlier files byte-identical
    assert temporaries(out) == [] and sorted(os.listdir(out)) == sorted(OUTPUTS)


def test_file_size_limit(anm_bin, refs, tmp_path):
    """ulimit -f below the VRML size: EFBIG reported as an error (SIGXFSZ ignored by anm)."""
    out = tmp_path / "out"
    copy_earlier(refs, out)
    limit = refs[2]["size"]["m-particles.wrl"] // 2
    assert limit > refs[2]["size"]["m.h5"]
    rc, _, err = finish(start(anm_bin, tmp_path, out, 2, limit=limit))
    assert rc == 1 and "m-particles.wrl" in err and "Backtrace" not in err, (rc, err)
    assert fingerprint(out) == refs[1]["fp"]
    assert temporaries(out) == []


def test_killed_during_output(anm_bin, refs, tmp_path):
    """SIGKILL while the VRML is being written: the earlier set stays whole; the next run in the
    folder removes the killed run's temporaries."""
    out = tmp_path / "out"
    copy_earlier(refs, out)
    proc = start(anm_bin, tmp_path, out, 2, tess=160)   # a large VRML: a long output phase
    seen = []
    deadline = time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < deadline:
        seen = [n for n in temporaries(out) if ".wrl.anm-tmp-" in n]
        if seen:
            proc.send_signal(signal.SIGKILL)
            break
        time.sleep(0.002)
    proc.communicate(timeout=60)
    assert seen, "the run ended before its VRML output could be caught"
    assert proc.returncode == -signal.SIGKILL
    assert fingerprint(out) == refs[1]["fp"]                    # no new file under a final name
    assert all(n.split(".anm-tmp-")[1] == str(proc.pid) for n in temporaries(out))
    rc, _, err = finish(start(anm_bin, tmp_path, out, 2))      # the next run cleans up
    assert rc == 0, err
    assert temporaries(out) == [] and fingerprint(out) == refs[2]["fp"]


def test_two_runs_to_one_output(anm_bin, refs, tmp_path):
    """Two runs (seeds 1 and 2) writing the same names at once: both succeed and the folder holds
    one run's complete set, never files from both."""
    out = tmp_path / "out"
    for attempt in range(2):
        procs = [start(anm_bin, tmp_path, out, s) for s in (1, 2)]
        results = [finish(p) for p in procs]
        assert all(r[0] == 0 for r in results), results
        fp = fingerprint(out)
        assert fp in (refs[1]["fp"], refs[2]["fp"]), fp
        assert temporaries(out) == []


def test_study_csv_on_a_full_disk(anm_bin, tmpfs, tmp_path):
    """`anm study` writes its CSV like every other output: on a full disk it fails with a message,
    the earlier CSV stays byte-identical and no temporary is left."""
    shape = tmp_path / "sphere-anm-00001.dat"
    lines = ["0 0 3.5449077018110318 0.0"] + [f"{n} {m} 0.0 0.0" for n in range(1, 5) for m in range(n, -n - 1, -1)]
    shape.write_text("\n".join(lines) + "\n")
    out = tmpfs / "study"
    out.mkdir()
    csv = out / "next.csv"
    rc = subprocess.run([anm_bin, "study", "next", str(shape), "--csv", str(csv)], capture_output=True, text=True)
    assert rc.returncode == 0, rc.stderr
    earlier = csv.read_bytes()
    st = os.statvfs(tmpfs)
    with open(tmpfs / "filler", "wb") as f:
        f.write(b"\0" * (st.f_bavail * st.f_frsize))
    res = subprocess.run([anm_bin, "study", "next", str(shape), "--csv", str(csv)], capture_output=True, text=True)
    assert res.returncode == 1 and "next.csv" in res.stderr and "Backtrace" not in res.stderr, res.stderr
    assert csv.read_bytes() == earlier
    assert sorted(os.listdir(out)) == ["next.csv"]

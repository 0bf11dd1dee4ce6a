"""The MPI build (scripts/build_mpi.sh, docs/mpi.md) parks the serial model: the default job (VRML
off) run with `mpirun -np N` for N = 1..4 ranks and 1 and 2 threads per rank gives every dataset of /box,
/shapes, /particles and /sieves identical (SHA-256 of dtype, shape and bytes) to the serial
model's recorded digests (data/identical_models.json, which test_identical_models.py checks the
serial program against). A small M_sand-like job (a coarse and a sand sieve of real shapes,
overlapping shells) gives the serial program's model file, dataset by dataset and attribute by
attribute (scripts/compare_models.py; the run's threads and times aside), for the other rank and
thread combinations. The model file is written by all ranks together (parallel HDF5): it is read
by h5py and anm_post (Python validation), and by the serial program's reader (`anm verify`).
`anm verify` under mpirun (each rank audits its slab) reports what the serial audit reports.

Needs $ANM_MPI_BIN (scripts/test.sh sets it); skipped without it, a failure under CI=true.
"""
import math
import os
import pathlib
import re
import shutil
import subprocess
import sys

import h5py
import numpy as np
import pytest

from test_identical_models import compare as compare_recorded, model_digest

ROOT = pathlib.Path(__file__).resolve().parents[2]
# every rank count and both thread counts in four runs (the CI time on 2 cores); ANM_MPI_CASES=all
# runs the eight combinations
ALL_CASES = [(1, 1), (1, 2), (2, 1), (2, 2), (3, 1), (3, 2), (4, 1), (4, 2)]
CASES = ALL_CASES if os.environ.get("ANM_MPI_CASES") == "all" else [(1, 2), (2, 1), (3, 2), (4, 1)]
# the small job: the other four combinations by default
SMALL_CASES = ALL_CASES if os.environ.get("ANM_MPI_CASES") == "all" else [(1, 1), (2, 2), (3, 1), (4, 2)]
# M_sand itself: 2 ranks x 1 thread by default
MSAND_CASES = ALL_CASES if os.environ.get("ANM_MPI_CASES") == "all" else [(2, 1)]
# the reduced concrete job (dense strategy): 2 and 3 ranks by default
CONCRETE_CASES = ALL_CASES if os.environ.get("ANM_MPI_CASES") == "all" else [(2, 1), (3, 1)]
# and in a walled box too with ANM_MPI_CASES=all (2 minutes more)
CONCRETE_BOXES = ["periodic", "walls"] if os.environ.get("ANM_MPI_CASES") == "all" else ["periodic"]
MPIRUN = ["mpirun", "--allow-run-as-root", "--oversubscribe"]
# the run's own attributes, which differ between runs of one model
RUN_ATTRIBUTES = ("wall_time", "threads", "program_version")
SMALL_NML = """&box length = 4.0, 4.0, 4.0, periodic = .true. /
&sieves
   nsieve = 2
   min_width = 1.9, 0.15
   max_width = 2.0, 0.25
   fraction = 0.15, 0.03
   source = '{shapes}/MA111-7-coarse/MA111-7-coarse-anm-00002.dat', '{shapes}/MA107-6-fine/MA107-6-fine-anm-00002.dat'
   order = 8, 5
/
&parking max_locations = 2000 /
&shells nlayer = 1, thickness = 0.02, thickness_unit = 'fraction', mode = 'overlap' /
&output directory = '{out}', name = 'model', vrml = .false. /
&run seed = 1 /
"""


@pytest.fixture(scope="module")
def mpi_bin():
    path = os.environ.get("ANM_MPI_BIN")
    if not path or not os.access(path, os.X_OK) or shutil.which("mpirun") is None:
        if os.environ.get("CI", "").lower() in ("true", "1"):
            pytest.fail("ANM_MPI_BIN (scripts/build_mpi.sh) or mpirun is missing (required when CI=true)")
        pytest.skip("no MPI build: set ANM_MPI_BIN (scripts/build_mpi.sh)")
    return path


def recorded_job_on_ranks(job, ranks, threads, mpi_bin, tmp_path):
    """inputs/JOB.nml (VRML off, output in tmp_path) run on `ranks` x `threads`: every dataset of
    the model equals the serial model's recorded digests (test_identical_models.py)."""
    text = (ROOT / "inputs" / f"{job}.nml").read_text()
    text = re.sub(r"directory\s*=\s*'[^']*'", f"directory = '{tmp_path}'", text)
    text = re.sub(r"vrml\s*=\s*\.true\.", "vrml = .false.", text)
    nml = tmp_path / f"{job}.nml"
    nml.write_text(text)
    env = dict(os.environ, OMP_NUM_THREADS=str(threads))
    res = subprocess.run(MPIRUN + ["-np", str(ranks), mpi_bin, "run", str(nml)], capture_output=True, text=True,
                         timeout=600, cwd=ROOT, env=env)
    assert res.returncode == 0, res.stdout + res.stderr
    # one summary (rank 0 alone writes and prints)
    assert res.stdout.count("model: ") == 1, res.stdout
    name = re.search(r"name\s*=\s*'([^']*)'", text).group(1)
    digest = model_digest(tmp_path / f"{name}.h5")
    changed, missing = compare_recorded(job, digest)
    assert not changed and not missing, (f"{job}, {ranks} ranks x {threads} threads: datasets that differ from the "
                                         f"serial model: {changed + missing}")


@pytest.mark.parametrize("ranks,threads", CASES, ids=[f"{r}x{t}" for r, t in CASES])
def test_mpi_default_job_is_the_serial_model(ranks, threads, mpi_bin, tmp_path):
    recorded_job_on_ranks("default", ranks, threads, mpi_bin, tmp_path)


@pytest.mark.parametrize("ranks,threads", MSAND_CASES, ids=[f"{r}x{t}" for r, t in MSAND_CASES])
def test_mpi_msand_is_the_serial_model(ranks, threads, mpi_bin, shapes_dir, tmp_path):
    """M_sand itself (inputs/msand.nml, about 171,000 particles, slabs and their load balance)."""
    recorded_job_on_ranks("msand", ranks, threads, mpi_bin, tmp_path)


def compare(a, b):
    """scripts/compare_models.py a b, the run's own attributes and the namelist text aside."""
    cmd = [sys.executable, str(ROOT / "scripts" / "compare_models.py"), str(a), str(b),
           "--skip", "run/namelist", "--skip", "run/resolved_namelist"]
    for name in RUN_ATTRIBUTES:
        cmd += ["--ignore", name]
    return subprocess.run(cmd, capture_output=True, text=True)


@pytest.fixture(scope="module")
def small_serial(anm_bin, shapes_dir, tmp_path_factory):
    """The small M_sand-like job run by the serial program: (namelist text template, model path)."""
    out = tmp_path_factory.mktemp("small-serial")
    nml = out / "small.nml"
    nml.write_text(SMALL_NML.format(shapes=shapes_dir, out=out))
    res = subprocess.run([anm_bin, "run", str(nml)], capture_output=True, text=True, timeout=600,
                         env=dict(os.environ, OMP_NUM_THREADS="1"))
    assert res.returncode == 0, res.stdout + res.stderr
    return out / "model.h5"


def run_mpi(mpi_bin, ranks, threads, args, extra_env=None, **kw):
    env = dict(os.environ, OMP_NUM_THREADS=str(threads), **(extra_env or {}))
    return subprocess.run(MPIRUN + ["-np", str(ranks), mpi_bin] + args, capture_output=True, text=True,
                          timeout=600, cwd=ROOT, env=env, **kw)


@pytest.mark.parametrize("ranks,threads", SMALL_CASES, ids=[f"{r}x{t}" for r, t in SMALL_CASES])
def test_mpi_small_msand_job_is_the_serial_model_file(ranks, threads, mpi_bin, shapes_dir, small_serial, tmp_path):
    nml = tmp_path / "small.nml"
    nml.write_text(SMALL_NML.format(shapes=shapes_dir, out=tmp_path))
    res = run_mpi(mpi_bin, ranks, threads, ["run", str(nml)])
    assert res.returncode == 0, res.stdout + res.stderr
    assert res.stdout.count("model: ") == 1, res.stdout
    # the safe-output contract: no temporary left, the final names only
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model-summary.csv", "model.h5", "small.nml"]
    cmp = compare(small_serial, tmp_path / "model.h5")
    assert cmp.returncode == 0, f"{ranks} ranks x {threads} threads:\n" + cmp.stdout + cmp.stderr
    assert (tmp_path / "model-summary.csv").read_bytes() == (small_serial.parent / "model-summary.csv").read_bytes()
    with h5py.File(tmp_path / "model.h5", "r") as f:
        assert int(f["run"].attrs["threads"]) == threads


def test_mpi_parallel_file_is_read_by_the_serial_readers(mpi_bin, anm_bin, shapes_dir, small_serial, tmp_path):
    """The file written by 3 ranks through parallel HDF5: h5py reads the same arrays as from the
    serial file; anm_post reads and validates it; the serial program's reader audits it (`anm
    verify`, which validates the file on reading) with the serial file's report."""
    from anm_post import read_model
    nml = tmp_path / "small.nml"
    nml.write_text(SMALL_NML.format(shapes=shapes_dir, out=tmp_path))
    res = run_mpi(mpi_bin, 3, 1, ["run", str(nml)])
    assert res.returncode == 0, res.stdout + res.stderr
    par = tmp_path / "model.h5"
    with h5py.File(par, "r") as f, h5py.File(small_serial, "r") as g:
        assert f.attrs["format"] == g.attrs["format"]
        for name in ("particles/center", "particles/rotation", "particles/shell_thickness", "particles/shape"):
            a, b = f[name], g[name]
            assert a.dtype == b.dtype and a.shape == b.shape and a[()].tobytes() == b[()].tobytes(), name
    model = read_model(par)
    assert len(model.center) == len(read_model(small_serial).center) > 600
    reports = []
    for path in (small_serial, par):
        v = subprocess.run([anm_bin, "verify", str(path), "--resolution", "24"], capture_output=True, text=True)
        assert v.returncode == 0, v.stdout + v.stderr
        reports.append(v.stdout.split("\n", 1)[1])
    assert reports[0] == reports[1]


def write_spheres(path, centers, radii, box, periodic):
    """A contract-v1 model of spheres of one shape (order 0) with per-particle scales, from h5py."""
    n = len(centers)
    with h5py.File(path, "w") as f:
        f.attrs["format"] = np.bytes_("anm-model")
        f.attrs["format_version"] = np.int32(1)
        f.create_dataset("box/length", data=np.array(box, dtype=np.float64))
        f["box"].attrs["periodic"] = np.int32(1 if periodic else 0)
        coeffs = np.zeros((1, 1, 2))
        coeffs[0, 0, 0] = 2.0 * math.sqrt(math.pi)
        f.create_dataset("shapes/coeffs", data=coeffs)
        f.create_dataset("shapes/nmax", data=np.zeros(1, dtype=np.int32))
        f.create_dataset("shapes/name", data=np.array([b"sphere"], dtype="S16"))
        f.create_dataset("particles/shape", data=np.zeros(n, dtype=np.int32))
        f.create_dataset("particles/center", data=np.asarray(centers, dtype=np.float64))
        rot = np.zeros((n, 3, 3))
        rot[:] = np.eye(3)
        f.create_dataset("particles/rotation", data=rot)
        f.create_dataset("particles/scale", data=np.asarray(radii, dtype=np.float64))
        f.create_dataset("particles/nmax", data=np.zeros(n, dtype=np.int32))
        f.create_dataset("particles/sieve", data=np.zeros(n, dtype=np.int32))
        for name, val in [("min_width", 0.4), ("max_width", 1.0), ("target_fraction", 0.1), ("achieved_fraction", 0.1)]:
            f.create_dataset(f"sieves/{name}", data=np.array([val]))
        f.create_dataset("sieves/count", data=np.array([n], dtype=np.int32))
        f.create_dataset("run/namelist", data=np.bytes_("written by the test"))


@pytest.mark.parametrize("periodic", [False, True], ids=["walls", "periodic"])
def test_mpi_verify_reports_the_serial_audit(periodic, mpi_bin, anm_bin, tmp_path):
    """Spheres of several sizes at random in a 10 mm box, many overlapping (pairs across slab
    borders and periodic images included) and, with walls, crossing them: `anm verify` on 2 and 3
    ranks prints the serial report line by line (pairs, overlaps, walls, the largest penetration
    and the deepest pair) and exits with its status."""
    rng = np.random.default_rng(7)
    n = 300
    centers = rng.uniform(0.0, 10.0, (n, 3))
    radii = rng.uniform(0.2, 0.5, n)
    path = tmp_path / "spheres.h5"
    write_spheres(path, centers, radii, [10.0, 10.0, 10.0], periodic)
    args = ["verify", str(path), "--resolution", "16"]
    serial = subprocess.run([anm_bin] + args, capture_output=True, text=True, env=dict(os.environ, OMP_NUM_THREADS="2"))
    assert serial.returncode == 3 and "FAIL" in serial.stdout, serial.stdout + serial.stderr
    assert "deepest pair" in serial.stdout
    for ranks in (2, 3):
        res = run_mpi(mpi_bin, ranks, 1, args)
        assert res.returncode == 3, res.stdout + res.stderr
        assert res.stdout == serial.stdout, f"{ranks} ranks"


# Slabs (the spatial decomposition) on the edges of the attempt sequences: a walled box with void
# placement, exclusion shells in mm (lazy kinds in width levels, so the reach grows as kinds are
# built) and particles that exhaust their attempts (the particle arrays whole on every rank, as
# void placement needs); the same in a periodic box with random placement (divided arrays); a
# periodic box with two shapes and two orientations per particle (kinds built per sieve; divided
# arrays). Synthetic shapes: no shapes folder needed.
SLAB_NML = """&box length = 8.0, 8.0, 8.0, periodic = {periodic} /
&sieves
   nsieve = 3
   min_width = 2.0, 1.0, 0.5
   max_width = 2.4, 1.2, 0.6
   fraction = 0.12, 0.08, 0.06
   source = 'synthetic', 'synthetic', 'synthetic'
   order = 8, 6, 5
/
&synthetic count = 6 /
&parking {parking} /
&shells {shells} /
&output directory = '{out}', name = 'model', vrml = .false. /
&run seed = 7 /
"""
DENSE_NML = """&box length = 6.0, 6.0, 6.0, periodic = .true. /
&sieves
   nsieve = 2
   min_width = 1.0, 0.5
   max_width = 1.2, 0.6
   fraction = 0.30, 0.14
   source = 'synthetic', 'synthetic'
   order = 6, 5
/
&synthetic count = 4 /
&parking max_locations = 200, strategy = 'dense', dense_rounds = 4, dense_sweeps = 4, dense_grow_scale = 0.7 /
&shells nlayer = 1, thickness = 0.02, thickness_unit = 'fraction', mode = 'exclude' /
&output directory = '{out}', name = 'model', vrml = .false. /
&run seed = 3 /
"""
SLAB_JOBS = {
    "walls-void-exclusion-mm": dict(periodic=".false.", parking="max_locations = 300, placement = 'void', max_failures = 5",
                                    shells="nlayer = 1, thickness = 0.05, thickness_unit = 'mm', mode = 'exclude'"),
    "periodic-exclusion-mm": dict(periodic=".true.", parking="max_locations = 300, max_failures = 5",
                                  shells="nlayer = 1, thickness = 0.05, thickness_unit = 'mm', mode = 'exclude'"),
    "periodic-shapes-orientations": dict(periodic=".true.",
                                         parking="max_shapes = 2, max_orientations = 2, max_locations = 100",
                                         shells="nlayer = 1, thickness = 0.03, thickness_unit = 'fraction', "
                                                "mode = 'exclude'"),
}


@pytest.mark.parametrize("job", sorted(SLAB_JOBS) + ["dense"])
def test_mpi_slabs_give_the_serial_model_on_edge_jobs(job, mpi_bin, anm_bin, tmp_path):
    """The serial model for 2 and 3 ranks in slabs and for 2 ranks with replicated data
    (`--replicated`), dataset by dataset (scripts/compare_models.py), with the kinds built in
    shares by the ranks and exchanged. The walled job's last sieve
    exhausts attempts (particles not parked), which ends a spatial search with no fit anywhere.
    With slabs and random placement each rank's particle arrays hold part of the particles
    (`--comm-stats`), and with 3 ranks the forced moves of the slabs send particles between them.
    The dense strategy (relaxation sweeps and growth, a small periodic job that ends by itself)
    runs with replicated data whatever is asked, and gives the serial model too."""
    def write(out):
        out.mkdir()
        nml = out / "job.nml"
        if job == "dense":
            nml.write_text(DENSE_NML.format(out=out))
        else:
            nml.write_text(SLAB_NML.format(out=out, **SLAB_JOBS[job]))
        return nml
    ser = write(tmp_path / "serial")
    res = subprocess.run([anm_bin, "run", str(ser)], capture_output=True, text=True, timeout=600,
                         env=dict(os.environ, OMP_NUM_THREADS="2"))
    assert res.returncode == 0, res.stdout + res.stderr
    if job.startswith("walls"):
        assert "particles not parked" in res.stderr and not re.search(r"sieve 3 done: .* 0 particles not parked",
                                                                          res.stderr), res.stderr
    for ranks, extra in ((2, []), (3, []), (2, ["--replicated"])):
        out = tmp_path / f"np{ranks}{''.join(extra)}"
        nml = write(out)
        # with 3 ranks the slabs move every 4 batches (the load balance, forced): the cell lists
        # are rebuilt for the new slabs while a sieve runs, which must not change the model
        env = {"ANM_MPI_BALANCE_EVERY": "4"} if ranks == 3 else {}
        res = run_mpi(mpi_bin, ranks, 1, ["run", str(nml), "--comm-stats"] + extra, extra_env=env)
        assert res.returncode == 0, res.stdout + res.stderr
        if ranks == 3 and job != "dense":
            moves = re.search(r"the slabs moved (\d+) times", res.stderr)
            assert moves and int(moves.group(1)) >= 3, res.stderr
        # divided particle arrays with slabs unless void placement needs them whole: each rank
        # then holds part of the particles, and the moved slabs' particles came from their owners
        held = re.findall(r"sieve \d+ end: each rank's particle arrays hold (\d+) to (\d+) of them", res.stderr)
        total = re.findall(r"cell list holds \d+ to \d+ of the (\d+) particles", res.stderr)
        if extra or job == "dense" or "void" in job:
            assert not held, res.stderr
        else:
            assert held and int(held[-1][1]) < int(total[-1]), res.stderr
            if ranks == 3:
                exchanges = re.search(r"divided arrays: (\d+) exchanges", res.stderr)
                assert exchanges and int(exchanges.group(1)) >= 3, res.stderr
        assert ("first-fit reductions" in res.stderr) == (not extra and job != "dense"), res.stderr
        # the kinds were built in shares: rank 0 received some from the others
        shares = rf"kinds: built in shares by {ranks} processes: \d+ parts \(bodies, shells\) built by this one, "
        assert re.search(shares + r"[1-9]\d* received", res.stderr), res.stderr
        cmp = compare(tmp_path / "serial" / "model.h5", out / "model.h5")
        assert cmp.returncode == 0, f"{ranks} ranks {extra}:\n" + cmp.stdout + cmp.stderr


def test_mpi_memory_check_counts_the_ranks_on_the_machine(mpi_bin, anm_bin, tmp_path):
    """`anm run`'s memory check before parking (ANM_MEMORY_LIMIT stands for the memory available)
    counts every rank on the machine: with a limit the serial estimate fits in but twice it does
    not, the serial run goes ahead and two replicated ranks on this machine (each holding the
    whole packing) are refused with the estimate named, before any output is written."""
    out = tmp_path / "out"
    out.mkdir()
    nml = out / "job.nml"
    nml.write_text(SLAB_NML.format(out=out, **SLAB_JOBS["periodic-shapes-orientations"]))
    probe = subprocess.run([anm_bin, "run", str(nml)], capture_output=True, text=True, timeout=600,
                           env=dict(os.environ, ANM_MEMORY_LIMIT="1000"))
    need = re.search(r"needs about ([\d.]+) (MB|GB|kB)", probe.stderr)
    assert probe.returncode != 0 and need, probe.stderr
    scale = {"kB": 1e3, "MB": 1e6, "GB": 1e9}[need.group(2)]
    limit = str(int(1.5 * float(need.group(1)) * scale))
    ser = subprocess.run([anm_bin, "run", str(nml)], capture_output=True, text=True, timeout=600,
                         env=dict(os.environ, ANM_MEMORY_LIMIT=limit, OMP_NUM_THREADS="2"))
    assert ser.returncode == 0, ser.stderr
    (out / "model.h5").unlink()
    (out / "model-summary.csv").unlink()
    res = run_mpi(mpi_bin, 2, 1, ["run", str(nml), "--replicated"], extra_env={"ANM_MEMORY_LIMIT": limit})
    assert res.returncode != 0 and "needs about" in res.stdout + res.stderr, res.stdout + res.stderr
    assert sorted(p.name for p in out.iterdir()) == ["job.nml"]


def concrete_fines_nml(shapes_dir, out, box=6.0, nfine=3, first_fraction=0.45, periodic=True):
    """inputs/concrete.nml reduced to a test's size: its `nfine` finest sieves (widths, orders and
    shapes as committed) in a periodic box of `box` mm, the first of them asked for
    `first_fraction` (it stands in for the coarser sieves: 0.61 of the box in all, beyond RSA, so
    that the rounds and the growth run), the others for their committed fractions; its &parking
    group as committed except that no wall-clock limit ends the search (a limit would end serial
    and parallel runs at different points) and at most two rounds per sieve run."""
    text = (ROOT / "inputs" / "concrete.nml").read_text()
    body = "\n".join(line.split("!")[0] for line in text.splitlines())

    def values(name):
        m = re.search(rf"\b{name}\s*=\s*([^\n]*)", body)
        assert m, name
        return [v.strip() for v in m.group(1).split(",") if v.strip()]

    def last(name):
        return ", ".join(values(name)[-nfine:])

    fractions = ", ".join([str(first_fraction)] + values("fraction")[-nfine + 1:])

    parking = re.search(r"&parking\b.*?/", body, re.S).group(0)
    parking = re.sub(r"dense_time_limit\s*=\s*[\d.]+", "dense_time_limit = 0", parking)
    parking = re.sub(r"dense_rounds\s*=\s*\d+", "dense_rounds = 2", parking)
    assert "strategy = 'dense'" in parking and "dense_time_limit = 0" in parking, parking
    fine = re.search(r"'[^']*/(MA107-6-fine)'", body).group(1)
    return (f"&box length = {box}, {box}, {box}, periodic = {'.true.' if periodic else '.false.'} /\n"
            f"&sieves\n   nsieve = {nfine}\n   min_width = {last('min_width')}\n"
            f"   max_width = {last('max_width')}\n   fraction = {fractions}\n"
            f"   source = {nfine}*'{shapes_dir}/{fine}'\n   order = {last('order')}\n/\n"
            f"{parking}\n&output directory = '{out}', name = 'model', vrml = .false. /\n&run seed = 1 /\n")


@pytest.mark.parametrize("box", CONCRETE_BOXES)
def test_mpi_concrete_namelist_fines_are_the_serial_model(box, mpi_bin, anm_bin, shapes_dir, tmp_path):
    """The concrete namelist's dense strategy (growth, overfill, contact gap, the failures its RSA
    passes may spend) on its three finest sieves in a 6 mm box at 0.61 (`concrete_fines_nml`):
    2 ranks x 1 thread and 3 ranks x 1 thread (all eight combinations with ANM_MPI_CASES=all),
    whose ranks evaluate the sweeps' trials in shares (`--comm-stats`: "dense sweeps"), give the
    serial model file (2 threads) dataset by dataset; with ANM_MPI_CASES=all also in a walled box."""
    def write(out):
        out.mkdir()
        nml = out / "job.nml"
        nml.write_text(concrete_fines_nml(shapes_dir, out, periodic=box == "periodic"))
        return nml
    ser = write(tmp_path / "serial")
    res = subprocess.run([anm_bin, "run", str(ser)], capture_output=True, text=True, timeout=600,
                         env=dict(os.environ, OMP_NUM_THREADS="2"))
    assert res.returncode == 0, res.stdout + res.stderr
    assert "growth ended" in res.stderr, res.stderr
    for ranks, threads in CONCRETE_CASES:
        out = tmp_path / f"np{ranks}x{threads}"
        res = run_mpi(mpi_bin, ranks, threads, ["run", str(write(out)), "--comm-stats"])
        assert res.returncode == 0, res.stdout + res.stderr
        shared = re.search(r"mpi: dense sweeps: (\d+) batches of trials evaluated in shares, (\d+) trials", res.stderr)
        assert bool(shared and int(shared.group(2)) > 1000) == (ranks > 1), res.stderr
        cmp = compare(tmp_path / "serial" / "model.h5", out / "model.h5")
        assert cmp.returncode == 0, f"{ranks} ranks x {threads} threads:\n" + cmp.stdout + cmp.stderr


def test_mpi_dense_time_limit_is_decided_alike_on_every_rank(mpi_bin, anm_bin, shapes_dir, tmp_path):
    """With a wall-clock limit (`dense_time_limit`, which the concrete namelists set), the ranks
    take the longest of their clocks, so that all end the search at the same point: a run of the
    reduced concrete job on 2 ranks cut short after 2 s ends with exit 0, the summary's particle
    count and fractions are those of the file the ranks wrote together, and the serial audit
    finds no overlap in it."""
    text = concrete_fines_nml(shapes_dir, tmp_path).replace("dense_time_limit = 0", "dense_time_limit = 2")
    nml = tmp_path / "job.nml"
    nml.write_text(text)
    res = run_mpi(mpi_bin, 2, 1, ["run", str(nml)])
    assert res.returncode == 0, res.stdout + res.stderr
    total = re.search(r"^total\s+([\d.]+)\s+([\d.]+)\s+(\d+)", res.stdout, re.M)
    assert total, res.stdout
    # cut short: the job asks 0.61, which the rounds and growth reach only after about 15 s
    assert float(total.group(2)) < 0.605, res.stdout
    with h5py.File(tmp_path / "model.h5", "r") as f:
        assert f["particles/center"].shape[0] == int(total.group(3))
    v = subprocess.run([anm_bin, "verify", str(tmp_path / "model.h5"), "--resolution", "16"],
                       capture_output=True, text=True, timeout=600)
    assert v.returncode == 0 and re.search(r"overlapping pairs:\s+0\n", v.stdout), v.stdout + v.stderr

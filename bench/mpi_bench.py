"""Benchmarks of the MPI build (docs/mpi.md): a job run by the serial program on 1 thread and by
the MPI build with ranks x threads = 1x2 and 2x1 (slabs, the default) and 2x1 with `--replicated` (CPU and wall time with GNU time, the bytes
communicated per sieve and batch and the peak memory per rank from `anm run --comm-stats`, the
models compared dataset by dataset), and the halo fraction per slab subdomain size computed from
the model: for n slabs of width L/n along x and each sieve s, the particles of sieves 1..s outside
a slab whose bounding spheres come within the largest bounding radius of sieve s of the slab
(what a rank owning the slab would need as halo while parking sieve s), relative to the particles
of sieves 1..s it owns.

Usage (from the repository root; builds with scripts/build.sh and scripts/build_mpi.sh first):

    python3 bench/mpi_bench.py [--job inputs/msand.nml] [--slabs 2 4 8 16 32 64] [--halo-only MODEL.h5]
                               [--serial-threads 2] [--no-halo]
    python3 bench/mpi_bench.py --project CPU PHASE1_CPU PARTICLES PEAK_MB SLAB_SHARE   # the scaling model only
    python3 bench/mpi_bench.py --project-dense CPU SHARED_CPU PARTICLES PEAK_MB        # the same, dense strategy

Prints markdown tables (pasted into docs/mpi.md). Jobs with ../shared/shapes need the folder.
"""
from __future__ import annotations

import argparse
import os
import re
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
# Open MPI binds each rank to one core when there are at most 2 ranks: a rank's threads would share
# that core (1x2 ran at one core's speed), hence --bind-to none
MPIRUN = "mpirun --allow-run-as-root --oversubscribe --bind-to none"
# anm_post (the halo table reads the model with it)
sys.path.insert(0, str(ROOT / "post"))


def timed(cmd: str, threads: int) -> tuple[float, float, str, str, int, float]:
    """Wall and CPU (user + system) seconds, stdout, stderr, exit code and the largest peak resident
    memory (MB) of one process of a shell command (GNU time's %M: the largest over the processes
    it waited for, so one rank's peak under mpirun)."""
    env = dict(os.environ, OMP_NUM_THREADS=str(threads))
    with tempfile.NamedTemporaryFile("r", suffix=".time") as tf:
        p = subprocess.run(f"/usr/bin/time -f '%e %U %S %M' -o {tf.name} bash -c {shlex.quote(cmd)}", shell=True,
                           cwd=ROOT, env=env, capture_output=True, text=True)
        fields = tf.read().strip().splitlines()[-1].split()
    return (float(fields[0]), float(fields[1]) + float(fields[2]), p.stdout, p.stderr, p.returncode,
            float(fields[3]) / 1024.0)


def job_copy(job: Path, out: Path) -> Path:
    text = job.read_text()
    text = re.sub(r"directory\s*=\s*'[^']*'", f"directory = '{out}'", text)
    text = re.sub(r"vrml\s*=\s*\.true\.", "vrml = .false.", text)
    out.mkdir(parents=True, exist_ok=True)
    nml = out / "job.nml"
    nml.write_text(text)
    return nml


def model_name(nml: Path) -> str:
    m = re.search(r"name\s*=\s*'([^']*)'", nml.read_text())
    return (m.group(1) if m else "model") + ".h5"


def bounding_radii(model) -> np.ndarray:
    """Bounding radius (mm) of every particle: scale x the largest sampled radius of its (shape,
    order), times 1.02 (anm verify's margin)."""
    from anm_post.kernels import geometry, GEOMETRY_COLUMNS
    keys = np.unique(np.stack([model.shape, model.nmax], axis=1), axis=0)
    props = geometry(model.shape_coeffs, model.shape_nmax, keys[:, 0], keys[:, 1])
    rmax = props[:, GEOMETRY_COLUMNS.index("rmax")]
    lookup = {(int(s), int(o)): r for (s, o), r in zip(keys, rmax)}
    per = np.array([lookup[(int(s), int(o))] for s, o in zip(model.shape, model.nmax)])
    return 1.02 * per * model.scale


def halo_table(path: Path, slabs: list[int]) -> str:
    """Markdown table of the halo fraction per sieve and slab count."""
    from anm_post import read_model
    m = read_model(path)
    rb = bounding_radii(m)
    L = float(m.box[0])
    x = np.mod(m.center[:, 0], L)
    sieve = np.asarray(m.sieve)
    nsieve = int(sieve.max()) + 1
    rows = ["| sieve | interaction range (mm) | " + " | ".join(f"{n} slabs ({L / n:.3g} mm)" for n in slabs) + " |",
            "|---:|---:|" + "---:|" * len(slabs)]
    for s in range(nsieve):
        present = sieve <= s
        reach = float(rb[sieve == s].max())   # the largest bounding radius of the sieve being parked
        xs, rs = x[present], rb[present]
        cells = []
        for n in slabs:
            w = L / n
            owned_total = 0
            halo_total = 0
            for k in range(n):
                lo, hi = k * w, (k + 1) * w
                own = (xs >= lo) & (xs < hi)
                # distance from a centre to the slab along x (periodic)
                mid = 0.5 * (lo + hi)
                d = np.abs(xs - mid)
                if m.periodic:
                    d = np.minimum(d, L - d)
                d = np.maximum(0.0, d - 0.5 * w)
                halo = (~own) & (d < rs + reach)
                owned_total += int(own.sum())
                halo_total += int(halo.sum())
            cells.append(f"{halo_total / max(1, owned_total):.3f}")
        rows.append(f"| {s + 1} | {2 * reach:.3f} | " + " | ".join(cells) + " |")
    return "\n".join(rows)


#: The concrete gradation of inputs/concrete.nml (width range mm, fraction, per-particle volume
#: factor kappa = volume / mean(w^3): 0.32 coarse, 0.48 fine, as measured on M_sand's model) plus
#: a sand sieve 0.15-0.3 mm at 0.05, in a 100 mm cube.
CONCRETE = [(9.5, 12.5, 0.15, 0.32), (4.75, 9.5, 0.22, 0.32), (2.36, 4.75, 0.09, 0.48), (1.18, 2.36, 0.08, 0.48),
            (0.6, 1.18, 0.08, 0.48), (0.3, 0.6, 0.08, 0.48), (0.15, 0.3, 0.05, 0.48)]


def block_halo(edges: list[float], reach: float) -> float:
    """Halo fraction of a block subdomain with these edges (mm) for an interaction range `reach`
    (mm): the shell of width `reach` around it over its volume, to first order 2 reach sum(1/a).
    On M_sand's sand sieve (slabs of 10 and 2.5 mm, reach 0.468 mm) it gives 0.094 and 0.37 where
    the model gives 0.072 and 0.30: an upper estimate."""
    return 2.0 * reach * sum(1.0 / a for a in edges)


def projection(cpu1: float, phase1: float, n_ref: int, peak_mb: float, slab_share: float | None,
               cores_per_node: int = 64, ranks_per_node: int = 2, efficiency: float = 0.8,
               decision_share: float = 0.1, reach: float = 0.56, array_bytes: float = 128.0,
               kinds_mb: float = 0.0) -> str:
    """The scaling model of docs/mpi.md from measured figures: CPU seconds of the job on one rank
    and one thread, the CPU seconds within it that the ranks share when replicated (RSA's phase 1,
    and with the dense strategy the sweeps' trials: `--comm-stats`), its particle count and peak
    memory per rank, and the share of the one-core time that every rank repeats with slabs
    (measured: a rank's CPU outside phase 1 over the one-core CPU; None for the dense strategy,
    which runs replicated: no slab column). `kinds_mb`: the part of the peak that is the particle
    kinds, which every rank holds whole with slabs (taken as the cube's too)."""
    per_particle = cpu1 / n_ref
    rho = 1.0 - phase1 / cpu1
    volume = 100.0 ** 3
    counts = []
    for a, b, f, kappa in CONCRETE:
        mean_w3 = (b ** 4 - a ** 4) / (4.0 * (b - a))
        counts.append(f * volume / (kappa * mean_w3))
    n = sum(counts)
    work = n * per_particle
    mem_gb = peak_mb * n / n_ref / 1024.0
    arrays_gb = array_bytes * n / 1024.0 ** 3
    dense = slab_share is None
    shared = "RSA's phase 1 and the sweeps' trials are" if dense else "phase 1 is"
    slabs = "" if dense else f"; with slabs, every rank repeats {slab_share:.2f}"
    cost = f"{per_particle * 1e3:.2f} ms" if dense else f"{per_particle * 1e6:.0f} us"
    lines = [f"Measured: {cost} CPU per particle (one rank, one thread); replicated, {shared} "
             f"{1 - rho:.2f} of it and the rest (rho = {rho:.2f}) is repeated by every rank{slabs}. The 100 mm "
             f"concrete cube to 0.15 mm: {n / 1e6:.1f} million particles "
             f"({', '.join(f'{c:,.0f}' for c in counts)} per sieve, coarse to fine), {duration(work)} CPU at "
             f"that cost; the whole model's memory about {mem_gb:.0f} GB, of which the particle arrays "
             f"{arrays_gb:.1f} GB.", ""]
    if dense:
        lines += ["| nodes | ranks x threads | replicated, trials shared (built) | designed: checkerboard slabs or "
                  "blocks, divided arrays and kinds | memory per rank: replicated / designed (blocks, halo) |",
                  "|---:|---:|---:|---:|---:|"]
    else:
        lines += ["| nodes | ranks x threads | replicated | slabs (built) | designed: blocks, divided kinds | "
                  "memory per rank: replicated / slabs (halo) / designed (blocks, halo) |",
                  "|---:|---:|---:|---:|---:|---:|"]
    blocks = {1: [50.0, 100.0, 100.0], 8: [25.0, 50.0, 50.0], 64: [12.5, 25.0, 25.0]}
    for nodes in (1, 8, 64):
        cores = nodes * cores_per_node
        ranks = ranks_per_node * nodes
        spread = cores * efficiency
        t_rep = rho * work + (1 - rho) * work / spread
        t_sp = decision_share * rho * work + (1 - decision_share * rho) * work / spread
        h = block_halo(blocks[nodes], reach)
        mem_sp = mem_gb / ranks * (1 + h)
        edges = ' x '.join(f'{e:g}' for e in blocks[nodes])
        if dense:
            lines.append(f"| {nodes} | {ranks} x {cores // ranks} | {duration(t_rep)} | {duration(t_sp)} | "
                         f"{mem_gb:.0f} GB / {mem_sp:.2f} GB ({edges} mm, {h:.2f}) |")
            continue
        t_slab = slab_share * work + (1 - slab_share) * work / spread
        h_slab = 2.0 * reach / (100.0 / ranks)
        # the particle arrays are divided like the cell lists (each rank: its slab and halo); the
        # kinds are whole on every rank
        kinds_gb = kinds_mb / 1024.0
        mem_slab = kinds_gb + max(0.0, mem_gb - kinds_gb) / ranks * (1 + h_slab)
        lines.append(f"| {nodes} | {ranks} x {cores // ranks} | {t_rep / 60:.1f} min | {t_slab / 60:.1f} min | "
                     f"{t_sp / 60:.2f} min | {mem_gb:.0f} GB / {mem_slab:.1f} GB ({h_slab:.2f}) / {mem_sp:.2f} GB "
                     f"({edges} mm, {h:.2f}) |")
    return "\n".join(lines)


def duration(seconds: float) -> str:
    """Seconds as minutes below an hour, else hours."""
    return f"{seconds / 60:.1f} min" if seconds < 3600 else f"{seconds / 3600:.1f} h"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--job", default="inputs/msand.nml")
    ap.add_argument("--anm", default=str(ROOT / "build/install/bin/anm"))
    ap.add_argument("--anm-mpi", default=str(ROOT / "build/install-mpi/bin/anm"))
    ap.add_argument("--slabs", type=int, nargs="+", default=[2, 4, 8, 16, 32, 64])
    ap.add_argument("--serial-threads", type=int, default=1, help="threads of the serial run (default 1)")
    ap.add_argument("--no-halo", action="store_true", help="skip the halo table (large models)")
    ap.add_argument("--halo-only", help="only the halo table of this model file")
    ap.add_argument("--project", type=float, nargs=5,
                    metavar=("CPU", "PHASE1_CPU", "PARTICLES", "PEAK_MB", "SLAB_SHARE"),
                    help="only the scaling model from measured figures (docs/mpi.md)")
    ap.add_argument("--kinds-mb", type=float, default=0.0,
                    help="with --project: the part of PEAK_MB that is the particle kinds (whole on every rank)")
    ap.add_argument("--project-dense", type=float, nargs=4, metavar=("CPU", "SHARED_CPU", "PARTICLES", "PEAK_MB"),
                    help="only the scaling model of the dense strategy (replicated; SHARED_CPU: what the ranks "
                         "share, RSA's phase 1 and the sweeps' trials, one-core seconds)")
    args = ap.parse_args()
    if args.project:
        c1, c2, n_ref, peak, share = args.project
        print(projection(c1, c2, int(n_ref), peak, share, kinds_mb=args.kinds_mb))
        return 0
    if args.project_dense:
        c1, c2, n_ref, peak = args.project_dense
        print(projection(c1, c2, int(n_ref), peak, None))
        return 0
    if args.halo_only:
        print(halo_table(Path(args.halo_only), args.slabs))
        return 0
    job = (ROOT / args.job).resolve()
    tmp = Path(tempfile.mkdtemp(prefix="anm-mpi-bench-"))
    # the serial program on 1 thread: CPU(2x1) - CPU(serial) is the work every rank repeats
    runs = [("serial", 1, 1, f"{shlex.quote(args.anm)} run {{nml}}"),
            ("MPI 1x2", 1, 2, f"{MPIRUN} -np 1 {shlex.quote(args.anm_mpi)} run {{nml}} --comm-stats"),
            ("MPI 2x1", 2, 1, f"{MPIRUN} -np 2 {shlex.quote(args.anm_mpi)} run {{nml}} --comm-stats"),
            ("MPI 2x1 replicated", 2, 1,
             f"{MPIRUN} -np 2 {shlex.quote(args.anm_mpi)} run {{nml}} --comm-stats --replicated")]
    if args.serial_threads != 1:
        runs[0] = (f"serial {args.serial_threads} threads", 1, args.serial_threads, runs[0][3])
    load = os.getloadavg()[0]
    print(f"Job: `{args.job}`; load average before: {load:.1f} on {os.cpu_count()} cores\n")
    print("| run | ranks x threads | wall (s) | CPU (s) | peak per process (MB) | particles | model = serial |")
    print("|---|---:|---:|---:|---:|---:|---|")
    stats = {}
    models = {}
    for label, ranks, threads, cmd in runs:
        out = tmp / label.replace(" ", "_")
        nml = job_copy(job, out)
        wall, cpu, so, se, rc, peak = timed(cmd.format(nml=shlex.quote(str(nml))), threads)
        if rc != 0:
            print(f"| {label} | {ranks}x{threads} | failed (exit {rc}) | | | | |")
            print(se[-2000:], file=sys.stderr)
            continue
        models["serial" if label.startswith("serial") else label] = out / model_name(nml)
        m = re.search(r"^total\s+\S+\s+\S+\s+(\d+)", so, re.M)
        same = "-"
        if not label.startswith("serial") and "serial" in models:
            c = subprocess.run([sys.executable, str(ROOT / "scripts/compare_models.py"), str(models["serial"]),
                                str(models[label]), "--skip", "run/namelist", "--skip", "run/resolved_namelist",
                                "--ignore", "wall_time", "--ignore", "threads", "--ignore", "program_version"],
                               capture_output=True, text=True)
            same = "yes" if c.returncode == 0 else "**no**"
        print(f"| {label} | {ranks}x{threads} | {wall:.1f} | {cpu:.1f} | {peak:.0f} | {m.group(1) if m else '?'} | "
              f"{same} |", flush=True)
        stats[label] = [line for line in se.splitlines() if line.startswith("mpi:")]
    for label, lines in stats.items():
        if lines:
            print(f"\n`--comm-stats` of {label}:\n\n    " + "\n    ".join(lines))
    if "serial" in models and not args.no_halo:
        print(f"\nHalo fraction (halo particles / owned particles, slabs along x) of the model:\n")
        print(halo_table(models["serial"], args.slabs))
    return 0


if __name__ == "__main__":
    sys.exit(main())

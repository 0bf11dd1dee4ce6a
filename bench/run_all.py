"""The benchmark suite: runs every benchmark and rewrites docs/performance.md.

Benchmarks print figures; they are not timed tests. This program runs them one after the other
(never two at once), times the parking jobs with GNU time (wall time and peak memory), checks every
parked model with `anm verify`, runs the reference RSA loop of ../shared/bench side by side with
Anm, and writes the figures, the exact commands and the machine (core count, CPU, load average)
into docs/performance.md. The analysis of the figures stays in docs/performance-notes.md.

Usage (from the repository root; `bash scripts/benchmarks.sh` installs and builds first):

    python3 bench/run_all.py [--out docs/performance.md] [--skip NAME ...] [--only NAME ...]

NAME is one of: sh, shells, contact, default, msand, table23, rsa, million, slicing, verify,
shellsmm, finesieves, ten_million, dense (verify: `anm verify` of M_sand against its parking; shellsmm:
`inputs/shells_mm.nml`, its first sieve alone (start-up) without and with a warm kind cache, the
whole job with shells and without shells (each with no cache and a warm cache), the kinds' memory; finesieves:
`inputs/concrete.nml` with `strategy = 'rsa'`, attempts per second (wall and CPU) of each sieve,
the three finest being the dense-regime figure; `--concrete-box L` runs it in an L mm box instead
of 40 mm for a quicker look; all beside the reference loop's time in the same run). Every job runs
with ANM_CACHE=off unless it tests the cache.
dense: `inputs/concrete.nml` and `inputs/concrete_mould.nml` (dense strategy, 0.70 asked, about 10
minutes each), fractions per sieve, wall and CPU time, peak memory and `anm verify`, beside the
reference loop's time in the same run.
ten_million: `inputs/ten_million.nml`, 10^7 sand grains, parking and `anm verify` with CPU time,
wall time and peak memory of each, about 10 minutes on 2 quiet cores and 1.2 GB of disk for the
model, beside the reference loop's time in the same run.
Jobs that need ../shared/shapes (msand, table23, million with real shapes, slicing of M_sand)
are reported as "not run" when the folder is missing.
"""
from __future__ import annotations

import argparse
import datetime
import os
import platform
import re
import resource
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared"
SHAPES = SHARED / "shapes"
ALL = ("sh", "shells", "contact", "default", "msand", "table23", "rsa", "million", "slicing", "verify", "shellsmm",
       "finesieves", "ten_million", "dense")


@dataclass
class Run:
    """One timed command: its output, wall time (s) and peak memory (MB)."""
    command: str
    stdout: str
    stderr: str
    wall: float
    peak_mb: float
    rc: int
    cpu: float = float("nan")   # user + system (s)


@dataclass
class Report:
    """Sections of the generated page, in order."""
    summary: list[tuple[str, str, str, str]] = field(default_factory=list)   # figure, value, target, met
    sections: list[str] = field(default_factory=list)

    def target(self, what: str, value: str, target: str, met: bool | None) -> None:
        self.summary.append((what, value, target, "-" if met is None else ("yes" if met else "**no**")))


def sh(cmd: str, env: dict[str, str] | None = None, cwd: Path = ROOT) -> Run:
    """Run a shell command under GNU time; never raises on a non-zero exit."""
    e = dict(os.environ)
    if env:
        e.update(env)
    with tempfile.NamedTemporaryFile("r", suffix=".time") as tf:
        full = f"/usr/bin/time -f '%e %M %U %S' -o {tf.name} bash -c {shlex.quote(cmd)}"
        p = subprocess.run(full, shell=True, cwd=cwd, env=e, capture_output=True, text=True)
        fields = (tf.read().strip().splitlines() or ["nan nan"])[-1].split()
    try:
        wall, peak = float(fields[0]), float(fields[1]) / 1024.0
    except (ValueError, IndexError):
        wall, peak = float("nan"), float("nan")
    try:
        cpu = float(fields[2]) + float(fields[3])
    except (ValueError, IndexError):
        cpu = float("nan")
    return Run(cmd, p.stdout, p.stderr, wall, peak, p.returncode, cpu)


def machine() -> str:
    cpu = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = ""
    try:
        kb = int(Path("/proc/meminfo").read_text().split()[1])
        mem = f", {kb / 1024 ** 2:.0f} GiB"
    except (OSError, ValueError, IndexError):
        pass
    return f"{os.cpu_count()} cores ({cpu}){mem}, {platform.system()} {platform.release()}"


def load() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "unknown"


def block(title: str, cmd: str, text: str, note: str = "") -> str:
    body = text.strip() or "(no output)"
    out = f"### {title}\n\nCommand: `{cmd}`  \nLoad average before the run: {load()}\n\n"
    if note:
        out += note.strip() + "\n\n"
    return out + "```\n" + body + "\n```\n"


def fpm_bench(rep: Report, name: str, title: str, anm_flags: str, args: str = "") -> str:
    cmd = f'OMP_NUM_THREADS=1 fpm run --profile release --flag "$ANM_FFLAGS" {name} {args}'.strip()
    r = sh(f"fpm run --profile release --flag {shlex.quote(anm_flags)} {name} {args} 2>/dev/null",
           env={"OMP_NUM_THREADS": "1"})
    text = r.stdout if r.rc == 0 else r.stdout + "\n(exit code %d)\n" % r.rc + r.stderr[-2000:]
    rep.sections.append(block(title, cmd, text))
    return text if r.rc == 0 else ""


def sh_targets(rep: Report, text: str) -> None:
    m = re.search(r"grid 120x240 degree 14: r only\s+([\d.]+) ms", text)
    if m:
        v = float(m.group(1))
        rep.target("SH synthesis, 120 x 240 grid, degree 14, 1 thread", f"{v:.3f} ms", "<= 0.3 ms", v <= 0.3)


def shells_targets(rep: Report, text: str) -> None:
    cpu, wall = [], []
    for line in text.splitlines():
        f = line.split()
        if line.startswith("#") or len(f) < 4 or f[1] == "layers":
            continue
        try:
            wall.append(float(f[2]))
            cpu.append(float(f[3]))
        except ValueError:
            continue
    if cpu:
        rep.target(f"shell construction, degree 14, 120-point grid, 1 thread: slowest of {len(cpu)} shells "
                   "(0.1 / 2 / 10 % L)", f"{max(cpu):.1f} ms CPU ({max(wall):.1f} ms wall)", "<= 20 ms",
                   max(cpu) <= 20)


def contact_targets(rep: Report, text: str) -> None:
    degree = None
    for line in text.splitlines():
        m = re.match(r"# contact, degree (\d+)", line)
        if m:
            degree = int(m.group(1))
            continue
        m = re.match(r"\s+(.*?)\s+EOB\s+([\d.]+)\s+[\d.]+\s+hits\s+\d+\s+certified\s+([\d.]+)", line)
        if m and degree == 14 and m.group(1).startswith("near"):
            eob, cert = float(m.group(2)), float(m.group(3))
            rep.target("contact, near-but-not-touching pairs, degree 14: median EOB / certified",
                       f"{eob:.1f} / {cert:.1f} us", "<= 20 us", max(eob, cert) <= 20)


# --------------------------------------------------------------------------------------------
# parking jobs


@dataclass
class Job:
    """A parking run: summary table parsed from `anm run`'s stdout."""
    run: Run
    total_target: float = float("nan")
    total: float = float("nan")
    particles: int = 0
    sieves: list[tuple[int, float, float, int]] = field(default_factory=list)   # id, target, achieved, n
    verify: str = "not run"
    verify_ok: bool = False
    model: Path | None = None


def parse_summary(text: str) -> tuple[list[tuple[int, float, float, int]], tuple[float, float, int] | None]:
    sieves, total = [], None
    for line in text.splitlines():
        m = re.match(r"\s*(\d+)\s+[\d.]+\s+-\s+[\d.]+\s+([\d.]+)\s+([\d.]+)\s+[-\d.]+\s+(\d+)\s*$", line)
        if m:
            sieves.append((int(m.group(1)), float(m.group(2)), float(m.group(3)), int(m.group(4))))
        m = re.match(r"total\s+([\d.]+)\s+([\d.]+)\s+(\d+)\s*$", line)
        if m:
            total = (float(m.group(1)), float(m.group(2)), int(m.group(3)))
    return sieves, total


def park(anm: str, nml: Path, tmp: Path, name: str, threads: int, edits: dict[str, str] | None = None,
         verify: bool = True, cache: str = "off") -> Job:
    """Run `anm run` on a copy of a namelist whose output directory is a temporary folder (the kind
    cache off unless `cache` names its folder: ANM_CACHE)."""
    text = nml.read_text()
    text = re.sub(r"directory\s*=\s*'[^']*'", f"directory = '{tmp / name}'", text)
    for old, new in (edits or {}).items():
        if old not in text:
            raise SystemExit(f"bench/run_all.py: {nml}: cannot find {old!r} to edit")
        text = text.replace(old, new)
    copy = tmp / f"{name}.nml"
    copy.write_text(text)
    r = sh(f"{shlex.quote(anm)} run --force {shlex.quote(str(copy))}",
           env={"OMP_NUM_THREADS": str(threads), "ANM_CACHE": cache})
    job = Job(r)
    job.sieves, total = parse_summary(r.stdout)
    if total:
        job.total_target, job.total, job.particles = total
    m = re.search(r"model:\s*(\S+\.h5)", r.stdout)
    job.model = Path(m.group(1)) if m else None
    if verify and r.rc == 0 and job.model and job.model.exists():
        v = sh(f"{shlex.quote(anm)} verify {shlex.quote(str(job.model))}", env={"OMP_NUM_THREADS": "2"})
        last = [ln for ln in (v.stdout + v.stderr).strip().splitlines() if ln.strip()]
        job.verify_ok = v.rc == 0
        job.verify = f"{'passed' if v.rc == 0 else 'FAILED'} in {v.wall:.1f} s" + (f" ({last[-1].strip()})" if last else "")
    return job


def job_row(label: str, threads: int, job: Job) -> str:
    r = job.run
    res = f"PD {job.total:.4f} of {job.total_target:.4f}" if job.particles else f"failed (exit {r.rc})"
    return (f"| {label} | {threads} | {r.wall:.2f} s | {r.peak_mb:.0f} MB | {job.particles:,} | {res} | "
            f"{job.verify} |")


def same_model(a: Job, b: Job) -> str:
    if not (a.model and b.model and a.model.exists() and b.model.exists()):
        return "not compared"
    code = ("import h5py,numpy as np,sys\n"
            "a,b=h5py.File(sys.argv[1]),h5py.File(sys.argv[2])\n"
            "names=[]\n"
            "a.visit(lambda n: names.append(n) if isinstance(a[n],h5py.Dataset) else None)\n"
            "skip={'run/namelist','run/resolved_namelist'}\n"
            "bad=[n for n in names if n not in skip and (n not in b or not np.array_equal(a[n][()],b[n][()]))]\n"
            "print('identical' if not bad else 'DIFFERENT: '+','.join(bad[:5]))\n")
    p = subprocess.run([sys.executable, "-c", code, str(a.model), str(b.model)], capture_output=True, text=True)
    # the namelist texts differ only in the output directory
    return (p.stdout.strip() or p.stderr.strip()[-200:]) + " (all datasets but the namelist texts)"


def parking_section(rep: Report, anm: str, tmp: Path, which: set[str]) -> None:
    rows, notes = [], []
    header = ("| job | threads | wall time | peak memory | particles | result | `anm verify` |\n"
              "|---|---|---|---|---|---|---|")
    speedups: dict[str, tuple[float, float]] = {}

    if "default" in which:
        j1 = park(anm, ROOT / "inputs/default.nml", tmp, "default1", 1)
        j2 = park(anm, ROOT / "inputs/default.nml", tmp, "default2", 2)
        rows += [job_row("default job (`inputs/default.nml`)", 1, j1), job_row("default job", 2, j2)]
        speedups["default job"] = (j1.run.wall, j2.run.wall)
        notes.append(f"Default job, 1 vs 2 threads: model datasets {same_model(j1, j2)}.")

    if "msand" in which:
        if SHAPES.is_dir():
            j1 = park(anm, ROOT / "inputs/msand.nml", tmp, "msand1", 1)
            j2 = park(anm, ROOT / "inputs/msand.nml", tmp, "msand2", 2)
            rows += [job_row("M_sand (`inputs/msand.nml`)", 1, j1), job_row("M_sand", 2, j2)]
            speedups["M_sand"] = (j1.run.wall, j2.run.wall)
            notes.append(f"M_sand, 1 vs 2 threads: model datasets {same_model(j1, j2)}.")
            eff = j1.run.wall / (2 * j2.run.wall)
            rep.target("M_sand wall time, 2 threads", f"{j2.run.wall:.1f} s ({j2.particles:,} particles)", "<= 10 s",
                       j2.run.wall <= 10 and j2.verify_ok)
            rep.target("M_sand parallel efficiency at 2 threads", f"{eff:.2f}", ">= 0.85", eff >= 0.85)
        else:
            rows.append("| M_sand | - | not run: ../shared/shapes missing | | | | |")

    if "table23" in which:
        if SHAPES.is_dir():
            base = "&parking max_locations = 1500 /"
            ju = park(anm, ROOT / "inputs/table2_3.nml", tmp, "table23", 2)
            jv = park(anm, ROOT / "inputs/table2_3_void.nml", tmp, "table23void", 2) \
                if (ROOT / "inputs/table2_3_void.nml").exists() else \
                park(anm, ROOT / "inputs/table2_3.nml", tmp, "table23void", 2,
                     {base: "&parking max_locations = 1500, placement = 'void' /"})
            rows += [job_row("Table 2.3 setup, uniform placement (`inputs/table2_3.nml`)", 2, ju),
                     job_row("Table 2.3 setup, void placement (`inputs/table2_3_void.nml`)", 2, jv)]
            dev = max((abs(a - t) / t for _, t, a, _ in jv.sieves), default=float("nan"))
            per = ", ".join(f"{a:.4f}/{t:.4f}" for _, t, a, _ in jv.sieves)
            notes.append(f"Table 2.3 with void placement, achieved/target per sieve: {per}; largest relative "
                         f"deviation {100 * dev:.1f} %. Uniform placement per sieve: "
                         + ", ".join(f"{a:.4f}" for _, _, a, _ in ju.sieves) + ".")
            rep.target("Table 2.3 setup, void placement: total PD", f"{jv.total:.4f}", ">= 0.355",
                       jv.total >= 0.355 - 5e-4 and jv.verify_ok)
            rep.target("Table 2.3 setup, void placement: worst sieve", f"{100 * dev:.1f} % off its volume",
                       "every sieve within 2 %", dev <= 0.02)
        else:
            rows.append("| Table 2.3 setup | - | not run: ../shared/shapes missing | | | | |")

    if "million" in which:
        nml = ROOT / "inputs/million.nml"
        if nml.exists():
            j = park(anm, nml, tmp, "million", 2)
            rows.append(job_row("10^6 sand-like particles (`inputs/million.nml`)", 2, j))
            rep.target("10^6 particles (order 5), 2 threads", f"{j.particles:,} particles in {j.run.wall:.0f} s, "
                       f"{j.run.peak_mb / 1024:.2f} GB peak", "<= 2 min, <= 4 GB",
                       j.particles >= 1_000_000 and j.run.wall <= 120 and j.run.peak_mb <= 4096 and j.verify_ok)
        else:
            rows.append("| 10^6 particles | - | not run: inputs/million.nml missing | | | | |")

    if "rsa" in which:
        rsa_section(rep, anm, tmp, rows, speedups)

    if rows:
        txt = ("## Parking\n\nEach job: `anm run` on the namelist (output directory moved to a temporary "
               "folder) under `/usr/bin/time` with `OMP_NUM_THREADS` = threads, then `anm verify` on the "
               f"model. Load average before the parking runs: {load()}.\n\n" + header + "\n" + "\n".join(rows)
               + "\n\n" + "\n".join(f"- {n}" for n in notes) + "\n")
        if speedups:
            txt += ("\nSpeed-up S = T1 / T2 and efficiency E = S / 2 with 2 threads (our version of the thesis' "
                    "Figs 2.18-2.20, which parallelised one contact test, not the parking):\n\n"
                    "| job | T1 | T2 | speed-up | efficiency |\n|---|---|---|---|---|\n")
            for k, (t1, t2) in speedups.items():
                txt += f"| {k} | {t1:.2f} s | {t2:.2f} s | {t1 / t2:.2f} | {t1 / (2 * t2):.2f} |\n"
            plot_speedup(speedups)
            txt += "\n![speed-up](figures/speedup.png)\n"
        rep.sections.append(txt)


def reference_loop(tmp: Path) -> tuple[str, float]:
    """The bare C loop of ../shared/bench (200,000 spheres to 0.30): its time in this run, so that a
    figure from a busy machine can be read as a ratio."""
    src = SHARED / "bench/rsa_spheres.c"
    if not src.exists():
        return "reference loop not run (../shared/bench/rsa_spheres.c missing)", float("nan")
    ref = tmp / "rsa_spheres"
    if not ref.exists():
        subprocess.run(["gcc", "-O2", "-march=native", "-o", str(ref), str(src), "-lm"], check=True)
    r = sh(f"{ref} 200000 0.30 1000000 1")
    m = re.search(r"seconds\s+([\d.]+)", r.stdout)
    t = float(m.group(1)) if m else float("nan")
    return (f"reference loop (`rsa_spheres 200000 0.30 1000000 1`, gcc -O2 -march=native): {t:.2f} s "
            f"(load before: {load()})"), t


def verify_section(rep: Report, anm: str, tmp: Path) -> None:
    """`anm verify` of M_sand against the parking of M_sand (2 threads each)."""
    if not SHAPES.is_dir():
        rep.sections.append("### `anm verify` of M_sand\n\nnot run: ../shared/shapes missing\n")
        return
    ref_text, _ = reference_loop(tmp)
    job = park(anm, ROOT / "inputs/msand.nml", tmp, "verify_msand", 2, verify=False)
    v = sh(f"{shlex.quote(anm)} verify {shlex.quote(str(job.model))}", env={"OMP_NUM_THREADS": "2"}) \
        if job.model else None
    ref2, _ = reference_loop(tmp)
    if v is None:
        rep.sections.append(f"### `anm verify` of M_sand\n\nparking failed (exit {job.run.rc})\n")
        return
    ratio = v.wall / job.run.wall
    rep.target("`anm verify` of M_sand / parking M_sand (wall, 2 threads)",
               f"{v.wall:.1f} s / {job.run.wall:.1f} s = {ratio:.2f}", "<= 1", ratio <= 1 and v.rc == 0)
    rep.sections.append(block("`anm verify` of M_sand", "OMP_NUM_THREADS=2 anm run inputs/msand.nml; "
                              "OMP_NUM_THREADS=2 anm verify out/msand/model.h5",
                              f"parking: {job.run.wall:.2f} s wall, {job.run.cpu:.2f} s CPU, {job.run.peak_mb:.0f} MB\n"
                              f"verify:  {v.wall:.2f} s wall, {v.cpu:.2f} s CPU, {v.peak_mb:.0f} MB, exit {v.rc}\n"
                              + v.stdout.strip() + "\n" + ref_text + "\n" + ref2))


def dense_section(rep: Report, anm: str, tmp: Path) -> None:
    """inputs/concrete.nml and inputs/concrete_mould.nml (`strategy = 'dense'`, 0.70 asked, the
    time limit of the namelist): total and per-sieve fractions reached, wall and CPU time, peak
    memory and `anm verify`, between two runs of the reference loop (issue 14's target: 0.70, every
    sieve within 2 %, at most 10 minutes on 2 cores)."""
    title = "Dense concrete (`inputs/concrete.nml`, `inputs/concrete_mould.nml`)"
    if not SHAPES.is_dir():
        rep.sections.append(f"### {title}\n\nnot run: ../shared/shapes missing\n")
        return
    ref_text, _ = reference_loop(tmp)
    lines = []
    for name in ("concrete", "concrete_mould"):
        job = park(anm, ROOT / "inputs" / f"{name}.nml", tmp, name, 2)
        r = job.run
        worst = max((abs(a - t) / t for _, t, a, _ in job.sieves if t > 0), default=float("nan"))
        met = (job.particles > 0 and job.total >= 0.70 - 1e-4 and worst <= 0.02 and r.wall <= 600
               and job.verify_ok)
        rep.target(f"dense `inputs/{name}.nml`, 2 threads", f"PD {job.total:.4f} of 0.70 in {r.wall:.0f} s "
                   f"({r.cpu:.0f} s CPU), worst sieve {100 * worst:.1f} % off, verify "
                   f"{'OK' if job.verify_ok else 'not OK'}", "0.70, every sieve within 2 %, <= 10 min", met)
        lines.append(f"{name}: {r.wall:.1f} s wall, {r.cpu:.1f} s CPU, {r.peak_mb:.0f} MB peak, "
                     f"{job.particles:,} particles, PD {job.total:.4f} of {job.total_target:.4f}, verify {job.verify}")
        lines += [f"  sieve {i}: {a:.5f} of {t:.5f} ({n:,} particles)" for i, t, a, n in job.sieves]
        if job.model:
            job.model.unlink(missing_ok=True)
    ref2, _ = reference_loop(tmp)
    rep.sections.append(block(title, "OMP_NUM_THREADS=2 anm run inputs/concrete.nml; "
                              "OMP_NUM_THREADS=2 anm run inputs/concrete_mould.nml (each then anm verify)",
                              "\n".join(lines) + "\n" + ref_text + "\n" + ref2))


def ten_million_section(rep: Report, anm: str, tmp: Path) -> None:
    """inputs/ten_million.nml (10^7 sand grains): parking, then `anm verify` of the model, each with
    CPU time, wall time and peak memory, between two runs of the reference loop."""
    nml = ROOT / "inputs/ten_million.nml"
    title = "10^7 sand grains (`inputs/ten_million.nml`)"
    if not SHAPES.is_dir() or not nml.exists():
        rep.sections.append(f"### {title}\n\nnot run: ../shared/shapes or the namelist missing\n")
        return
    ref_text, _ = reference_loop(tmp)
    job = park(anm, nml, tmp, "ten_million", 2, verify=False)
    v = sh(f"{shlex.quote(anm)} verify {shlex.quote(str(job.model))}", env={"OMP_NUM_THREADS": "2"}) \
        if job.model else None
    if job.model:
        job.model.unlink(missing_ok=True)   # 1.2 GB
    ref2, _ = reference_loop(tmp)
    r = job.run
    if v is None:
        rep.sections.append(f"### {title}\n\nparking failed (exit {r.rc})\n{r.stderr[-1500:]}\n")
        return
    rep.target("10^7 particles (order 5), 2 threads: parking", f"{job.particles:,} particles in {r.wall:.0f} s "
               f"({r.cpu:.0f} s CPU), {r.peak_mb / 1024:.2f} GB peak", "<= 3 min, <= 6 GB",
               job.particles >= 9_500_000 and r.wall <= 180 and r.peak_mb <= 6144)
    rep.target("10^7 particles: `anm verify`", f"{'passed' if v.rc == 0 else 'FAILED'} in {v.wall:.0f} s "
               f"({v.cpu:.0f} s CPU), {v.peak_mb / 1024:.2f} GB peak", "passes", v.rc == 0)
    per = f"{1048576 * r.peak_mb / job.particles:.0f}" if job.particles else "-"
    rep.sections.append(block(title, "OMP_NUM_THREADS=2 anm run inputs/ten_million.nml; "
                              "OMP_NUM_THREADS=2 anm verify out/ten_million/model.h5",
                              f"parking: {r.wall:.2f} s wall, {r.cpu:.2f} s CPU, {r.peak_mb:.0f} MB peak "
                              f"({per} bytes per particle), {job.particles:,} particles, exit {r.rc}\n"
                              f"verify:  {v.wall:.2f} s wall, {v.cpu:.2f} s CPU, {v.peak_mb:.0f} MB peak, "
                              f"exit {v.rc}\n" + v.stdout.strip() + "\n" + ref_text + "\n" + ref2))


def shellsmm_section(rep: Report, anm: str, tmp: Path) -> None:
    """inputs/shells_mm.nml: the first sieve alone (start-up) without and with a warm kind cache,
    then the job with shells (cache off, then warm) and without shells (cache off, then warm); the
    kinds' memory. The CPU ratios compare like with like: no cache with no cache, warm with warm."""
    nml = ROOT / "inputs/shells_mm.nml"
    if not SHAPES.is_dir():
        rep.sections.append("### Shells in mm\n\nnot run: ../shared/shapes missing\n")
        return
    first = {"nsieve = 3": "nsieve = 1", "min_width = 4.75, 3.35, 2.36": "min_width = 4.75",
             "max_width = 6.3, 4.75, 3.35": "max_width = 6.3", "fraction = 0.12, 0.10, 0.08": "fraction = 0.12",
             "'../shared/shapes/MA111-7-coarse', '../shared/shapes/MA111-7-coarse', '../shared/shapes/MA111-7-coarse'":
             "'../shared/shapes/MA111-7-coarse'", "order = 14, 14, 14": "order = 14"}
    noshell = {"&shells nlayer = 1, thickness = 0.1, thickness_unit = 'mm', mode = 'exclude' /": ""}
    cache = tmp / "kind-cache"
    shutil.rmtree(cache, ignore_errors=True)

    def sieve1(j: Job) -> float:
        m = re.search(r"sieve 1 done:.*?([\d.]+) s\s*$", j.run.stderr + j.run.stdout, re.M)
        return float(m.group(1)) if m else float("nan")

    def kinds(j: Job) -> str:
        m = re.search(r"^kinds: \d+ of \d+ built, .*$", j.run.stderr, re.M)
        return m.group(0) if m else "kinds: no line"

    def line(label: str, j: Job) -> str:
        return (f"{label}: {j.run.wall:.2f} s wall, {j.run.cpu:.2f} s CPU, {j.run.peak_mb:.0f} MB; "
                f"sieve 1 done at {sieve1(j):.2f} s\n  {kinds(j)}")

    ref_text, _ = reference_loop(tmp)
    j1 = park(anm, nml, tmp, "shellsmm_first", 2, edits=first, verify=False)
    j1c = park(anm, nml, tmp, "shellsmm_first_cold", 2, edits=first, verify=False, cache=str(cache))
    j1w = park(anm, nml, tmp, "shellsmm_first_warm", 2, edits=first, verify=False, cache=str(cache))
    rep.target("shells in mm: first sieve (start-up), 2 threads, no cache", f"sieve done at {sieve1(j1):.1f} s, "
               f"whole run {j1.run.cpu:.1f} s CPU", "<= 1 s", sieve1(j1) <= 1)
    rep.target("shells in mm: first sieve (start-up), 2 threads, warm kind cache",
               f"sieve done at {sieve1(j1w):.1f} s, whole run {j1w.run.cpu:.1f} s CPU", "<= 1 s", sieve1(j1w) <= 1)
    jw = park(anm, nml, tmp, "shellsmm", 2, verify=True)
    jwc = park(anm, nml, tmp, "shellsmm_cached", 2, verify=False, cache=str(cache))     # fills the cache
    jww = park(anm, nml, tmp, "shellsmm_warm", 2, verify=False, cache=str(cache))
    jn = park(anm, nml, tmp, "shellsmm_noshell", 2, edits=noshell, verify=False)
    park(anm, nml, tmp, "shellsmm_noshell_cached", 2, edits=noshell, verify=False, cache=str(cache))  # fills it
    jnw = park(anm, nml, tmp, "shellsmm_noshell_warm", 2, edits=noshell, verify=False, cache=str(cache))
    ref2, _ = reference_loop(tmp)
    ratio = jw.run.cpu / jn.run.cpu
    # like with like: both jobs read their kinds from a warm cache
    ratio_w = jww.run.cpu / jnw.run.cpu
    rep.target("shells in mm: CPU with / without shells, no cache", f"{jw.run.cpu:.1f} s / {jn.run.cpu:.1f} s = "
               f"{ratio:.1f}", "<= 2", ratio <= 2)
    rep.target("shells in mm: CPU with / without shells, both with a warm kind cache",
               f"{jww.run.cpu:.1f} s / {jnw.run.cpu:.1f} s = {ratio_w:.1f}", "<= 2", ratio_w <= 2)
    rep.target("shells in mm: peak memory", f"{jw.run.peak_mb:.0f} MB (warm cache {jww.run.peak_mb:.0f} MB, "
               f"without shells {jn.run.peak_mb:.0f} MB)", "<= 1024 MB", max(jw.run.peak_mb, jww.run.peak_mb) <= 1024)
    models = f"models: no cache vs warm cache {same_model(jw, jww)}; first sieve no cache vs warm {same_model(j1, j1w)}"
    rep.sections.append(block("Shells in mm (`inputs/shells_mm.nml`)", "OMP_NUM_THREADS=2 anm run inputs/shells_mm.nml "
                              "(and its first sieve alone, and without the &shells line; ANM_CACHE=off or a "
                              "temporary folder)",
                              line("first sieve alone, no cache", j1) + "\n"
                              + line("first sieve alone, cache filled", j1c) + "\n"
                              + line("first sieve alone, warm cache", j1w) + "\n"
                              + f"with shells, no cache:    {job_row('shells_mm', 2, jw)}\n  CPU {jw.run.cpu:.1f} s; "
                              f"{kinds(jw)}\n"
                              f"with shells, cache filled: CPU {jwc.run.cpu:.1f} s, {jwc.run.peak_mb:.0f} MB\n"
                              f"with shells, warm cache:  {job_row('shells_mm', 2, jww)}\n  CPU {jww.run.cpu:.1f} s\n"
                              f"without shells: {job_row('shells_mm without shells', 2, jn)}\n  CPU {jn.run.cpu:.1f} s\n"
                              f"without shells, warm cache: {job_row('shells_mm without shells', 2, jnw)}\n"
                              f"  CPU {jnw.run.cpu:.1f} s\n"
                              + models + "\n" + ref_text + "\n" + ref2))


def cpu_seconds(pid: int) -> float:
    """User + system CPU time (s) of a running process, from /proc (nan when unreadable)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return float("nan")


def sieve_times(anm: str, nml: Path, threads: int) -> tuple[list[tuple[int, int, float, float]], float, float, int]:
    """Run `anm run` and read, as each sieve ends, its attempts and the process's wall and CPU time:
    [(sieve, attempts, wall at its end, CPU at its end)], total wall, total CPU, exit code."""
    env = dict(os.environ, OMP_NUM_THREADS=str(threads))
    t0 = time.time()
    p = subprocess.Popen([anm, "run", "--force", str(nml)], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True)
    rows = []
    assert p.stdout is not None
    for line in p.stdout:
        m = re.match(r"sieve (\d+) done: .*?, (\d+) attempts,", line)
        if m:
            rows.append((int(m.group(1)), int(m.group(2)), time.time() - t0, cpu_seconds(p.pid)))
    rc = p.wait()
    wall = time.time() - t0
    return rows, wall, resource_children_cpu(), rc


def finesieves_section(rep: Report, anm: str, tmp: Path, box: float) -> None:
    """inputs/concrete.nml with `strategy = 'rsa'`: attempts per second of every sieve (wall and per
    CPU second), beside the reference loop run just before and after."""
    if not SHAPES.is_dir():
        rep.sections.append("### Fine sieves among coarse particles\n\nnot run: ../shared/shapes missing\n")
        return
    text = (ROOT / "inputs/concrete.nml").read_text()
    text = re.sub(r"strategy\s*=\s*'dense'[^/]*/", "strategy = 'rsa' /", text)
    text = re.sub(r"directory\s*=\s*'[^']*'", f"directory = '{tmp / 'finesieves'}'", text)
    if box != 40.0:
        text = text.replace("length = 40.0, 40.0, 40.0", f"length = {box}, {box}, {box}")
    nml = tmp / "finesieves.nml"
    nml.write_text(text)
    ref_text, tr = reference_loop(tmp)
    before = resource_children_cpu()
    rows, wall, cpu_all, rc = sieve_times(anm, nml, 2)
    cpu_run = cpu_all - before
    ref2, tr2 = reference_loop(tmp)
    lines = ["| sieve | attempts | wall (s) | CPU (s) | attempts/s (wall) | attempts per CPU s |", "|---|---|---|---|---|---|"]
    w0, c0 = 0.0, 0.0
    fine = []
    for s, n, w, c in rows:
        dw, dc = w - w0, c - c0
        lines.append(f"| {s} | {n:,} | {dw:.1f} | {dc:.1f} | {n / max(dw, 1e-9):,.0f} | {n / max(dc, 1e-9):,.0f} |")
        if s >= 4:
            fine.append((n, dw, dc))
        w0, c0 = w, c
    label = "inputs/concrete.nml" + ("" if box == 40.0 else f" in a {box:g} mm box")
    if fine:
        n = sum(f[0] for f in fine)
        dw = sum(f[1] for f in fine)
        dc = sum(f[2] for f in fine)
        tref = statistics.mean([t for t in (tr, tr2) if t == t] or [float("nan")])
        rep.target(f"fine sieves (4-6) of {label}, rsa, 2 threads: attempts/s",
                   f"{n / dw:,.0f} per wall s, {n / dc:,.0f} per CPU s; reference loop {tref:.1f} s", ">= 10x 10,000",
                   None)
    rep.sections.append(block(f"Fine sieves among coarse particles ({label}, `strategy = 'rsa'`)",
                              f"OMP_NUM_THREADS=2 anm run concrete_rsa.nml (inputs/concrete.nml, strategy = 'rsa')",
                              "\n".join(lines) + f"\nwhole run: {wall:.1f} s wall, {cpu_run:.1f} s CPU, exit {rc}\n"
                              + ref_text + "\n" + ref2))


def resource_children_cpu() -> float:
    """CPU time (s) of the waited-for children so far."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def rsa_section(rep: Report, anm: str, tmp: Path, rows: list[str], speedups: dict) -> None:
    src = SHARED / "bench/rsa_spheres.c"
    edge = 140.82046803408818   # 200,000 spheres of radius 1 at a packing fraction of 0.30
    nml = tmp / "rsa_base.nml"
    nml.write_text(f"&box length = {edge}, {edge}, {edge}, periodic = .true. /\n"
                   "&sieves nsieve = 1, min_width = 2, max_width = 2, fraction = 0.30, source = 'sphere', "
                   "order = 0 /\n&parking max_locations = 1000000 /\n"
                   "&output directory = 'x', name = 'model', vrml = .false. /\n")
    ref = None
    if src.exists():
        ref = tmp / "rsa_spheres"
        subprocess.run(["gcc", "-O2", "-march=native", "-o", str(ref), str(src), "-lm"], check=True)
    anm1, anm2, refs = [], [], []
    for rep_i in range(3):   # alternate the programs: the machine's speed drifts
        if ref:
            r = sh(f"{ref} 200000 0.30 1000000 1")
            m = re.search(r"seconds\s+([\d.]+)", r.stdout)
            if m:
                refs.append(float(m.group(1)))
        anm1.append(park(anm, nml, tmp, f"rsa1_{rep_i}", 1, verify=rep_i == 0))
        anm2.append(park(anm, nml, tmp, f"rsa2_{rep_i}", 2, verify=rep_i == 0))
    t1 = statistics.median(j.run.wall for j in anm1)
    t2 = statistics.median(j.run.wall for j in anm2)
    rows.append(job_row("RSA, 200,000 order-0 spheres to 0.30, periodic (median of 3)", 1, anm1[0])
                .replace(f"{anm1[0].run.wall:.2f} s", f"{t1:.2f} s"))
    rows.append(job_row("RSA (median of 3)", 2, anm2[0]).replace(f"{anm2[0].run.wall:.2f} s", f"{t2:.2f} s"))
    speedups["RSA 200,000 spheres"] = (t1, t2)
    if refs:
        tr = statistics.median(refs)
        rows.append(f"| reference `../shared/bench/rsa_spheres.c` (gcc -O2 -march=native; `rsa_spheres 200000 "
                    f"0.30 1000000 1`, median of 3, its own loop time) | 1 | {tr:.2f} s | | 200,000 | | |")
        rep.target("RSA 200,000 spheres, 1 thread / reference", f"{t1 / tr:.2f} ({t1:.2f} s / {tr:.2f} s)",
                   "<= 1.5", t1 / tr <= 1.5)
        rep.target("RSA 200,000 spheres, 2 threads / reference", f"{t2 / tr:.2f} ({t2:.2f} s / {tr:.2f} s)",
                   "< 1 (faster)", t2 < tr)


def plot_speedup(speedups: dict[str, tuple[float, float]]) -> None:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(8, 3.2))
    for k, (t1, t2) in speedups.items():
        a1.plot([1, 2], [1, t1 / t2], "o-", label=k)
        a2.plot([1, 2], [1, t1 / (2 * t2)], "o-", label=k)
    a1.plot([1, 2], [1, 2], "k:", label="ideal")
    a1.set_xlabel("threads"); a1.set_ylabel("speed-up T1/Tn"); a1.set_xticks([1, 2])
    a2.axhline(0.85, color="k", ls=":", label="target 0.85")
    a2.set_xlabel("threads"); a2.set_ylabel("efficiency"); a2.set_xticks([1, 2]); a2.set_ylim(0, 1.1)
    a1.legend(fontsize=7); a2.legend(fontsize=7)
    fig.tight_layout()
    out = ROOT / "docs/figures/speedup.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------------------------


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=str(ROOT / "docs/performance.md"))
    ap.add_argument("--skip", nargs="*", default=[], choices=ALL)
    ap.add_argument("--only", nargs="*", default=[], choices=ALL)
    ap.add_argument("--anm", default=str(ROOT / "build/install/bin/anm"))
    ap.add_argument("--concrete-box", type=float, default=40.0,
                    help="box edge (mm) of the finesieves job (default 40, inputs/concrete.nml's)")
    args = ap.parse_args()
    which = set(args.only or ALL) - set(args.skip)
    flags = os.environ.get("ANM_FFLAGS", "-march=native -ffpe-summary=none")
    if not Path(args.anm).exists():
        print(f"bench/run_all.py: {args.anm} missing: run `bash scripts/build.sh` first", file=sys.stderr)
        return 1
    start = time.time()
    rep = Report()
    tmp = Path(tempfile.mkdtemp(prefix="anm-bench-"))
    try:
        if "sh" in which:
            print("== bench-sh", file=sys.stderr)
            sh_targets(rep, fpm_bench(rep, "bench-sh", "Spherical-harmonic synthesis (`bench-sh`)", flags))
        if "shells" in which:
            print("== bench-shells", file=sys.stderr)
            shells_targets(rep, fpm_bench(rep, "bench-shells", "Shell construction (`bench-shells`)", flags))
        if "contact" in which:
            print("== bench-contact", file=sys.stderr)
            contact_targets(rep, fpm_bench(rep, "bench-contact",
                                           "Contact per pair, EOB and Newton-Raphson (`bench-contact`)", flags))
        if which & {"default", "msand", "table23", "million", "rsa"}:
            print("== parking", file=sys.stderr)
            parking_section(rep, args.anm, tmp, which)
        if "verify" in which:
            print("== verify", file=sys.stderr)
            verify_section(rep, args.anm, tmp)
        if "shellsmm" in which:
            print("== shellsmm", file=sys.stderr)
            shellsmm_section(rep, args.anm, tmp)
        if "finesieves" in which:
            print("== finesieves", file=sys.stderr)
            finesieves_section(rep, args.anm, tmp, args.concrete_box)
        if "dense" in which:
            dense_section(rep, args.anm, tmp)
        if "ten_million" in which:
            print("== ten_million", file=sys.stderr)
            ten_million_section(rep, args.anm, tmp)
        if "slicing" in which:
            model = ROOT / "out/msand/model.h5"
            if SHAPES.is_dir():
                print("== slicing", file=sys.stderr)
                if not model.exists():
                    sh(f"{shlex.quote(args.anm)} run inputs/msand.nml")
                r = sh(f"{sys.executable} bench/bench_slicing.py {model}", env={"OMP_NUM_THREADS": "2"})
                rep.sections.append(block("Slices of M_sand (`bench/bench_slicing.py`)",
                                          "OMP_NUM_THREADS=2 python3 bench/bench_slicing.py out/msand/model.h5",
                                          r.stdout + (r.stderr[-1500:] if r.rc else "")))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    write_page(Path(args.out), rep, which, time.time() - start)
    print(f"wrote {args.out}", file=sys.stderr)
    return 0


def write_page(out: Path, rep: Report, which: set[str], seconds: float) -> None:
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                            text=True).stdout.strip() or "unknown"
    # the run's own outputs (this page, the speed-up figure) do not count as changes
    dirty = [ln for ln in subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT,
                                         capture_output=True, text=True).stdout.splitlines()
             if not ln.endswith(("docs/performance.md", "docs/figures/speedup.png"))]
    lines = [
        "# Performance",
        "",
        "<!-- Generated by `bash scripts/benchmarks.sh` (bench/run_all.py). Do not edit by hand: "
        "analysis goes to performance-notes.md. -->",
        "",
        "Benchmark figures (not timed tests), rewritten by one command:",
        "",
        "    bash scripts/benchmarks.sh            # all; --only NAME ... or --skip NAME ... for a part",
        "",
        f"Machine: {machine()}. Run: {datetime.datetime.now():%Y-%m-%d %H:%M}, commit {commit}"
        f"{' (with uncommitted changes)' if dirty else ''}, {seconds / 60:.1f} min for the benchmarks run "
        f"({', '.join(n for n in ALL if n in which)}). The machine may be shared: the load average before each "
        "run is printed with it. How the figures were reached, profiles and history: "
        "[performance-notes.md](performance-notes.md).",
        "",
    ]
    if rep.summary:
        lines += ["## Targets", "", "| figure | measured | target | met |", "|---|---|---|---|"]
        lines += [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rep.summary]
        lines += [""]
    lines += rep.sections
    out.write_text("\n".join(lines).rstrip() + "\n")


if __name__ == "__main__":
    sys.exit(main())

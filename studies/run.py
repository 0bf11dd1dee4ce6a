"""Run the ensemble jobs (in parallel, one OpenMP thread each) and gather their summaries.

Each job runs in SCRATCH/<study>/<value>/seed<k>/ and leaves run.nml, run.log, model-summary.csv
and result.json (the summary's numbers, the CPU time, the commit). A job whose result.json
holds the same namelist and engine commit is not run again, so an interrupted ensemble resumes.
"""
from __future__ import annotations

import concurrent.futures
import csv
import json
import os
import pathlib
import subprocess
import sys
import time

from . import jobs as J

SCRATCH = J.ROOT / "out" / "studies" / "ensemble"


#: what builds the engine: a run's numbers depend on these paths only (and on the namelist)
ENGINE_PATHS = ("src", "app", "include", "fpm.toml")


def _git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=J.ROOT, check=True, capture_output=True,
                          text=True).stdout.strip()


def commit() -> str:
    """HEAD of the checkout, with '-dirty' when a tracked file differs from it."""
    dirty = _git("status", "--porcelain", "--untracked-files=no")
    return _git("rev-parse", "HEAD") + ("-dirty" if dirty else "")


def engine_commit() -> str:
    """The last commit that changed the engine's sources, '-dirty' when they differ from it now."""
    dirty = _git("status", "--porcelain", "--untracked-files=no", "--", *ENGINE_PATHS)
    return _git("log", "-1", "--format=%H", "--", *ENGINE_PATHS) + ("-dirty" if dirty else "")


def read_summary(path: pathlib.Path) -> dict:
    """The numbers of an `anm run` summary CSV: per sieve and total, as floats and ints."""
    sieves, total = [], None
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            rec = {"target": float(row["target_fraction"]), "fraction": float(row["achieved_fraction"]),
                   "count": int(row["count"]), "shell_fraction": float(row["shell_fraction"])}
            if row["sieve"] == "total":
                total = rec
            else:
                rec["min_width"] = float(row["min_width_mm"])
                rec["max_width"] = float(row["max_width_mm"])
                sieves.append(rec)
    if total is None:
        raise ValueError(f"{path}: no total row")
    return {"sieves": sieves, "total": total}


def run_job(anm: str, job: J.Job, scratch: pathlib.Path, head: str, engine: str, force: bool = False,
            shapes: str | None = None, any_engine: bool = False) -> dict:
    """Run one job (unless its result is there for this namelist and engine, or for this namelist
    and any engine with `any_engine`); its result record."""
    folder = scratch / job.name
    folder.mkdir(parents=True, exist_ok=True)
    try:
        where = str(folder.relative_to(J.ROOT))     # anm runs in the repository root
    except ValueError:
        where = str(folder)
    text = J.namelist(job, where, shapes)
    done = folder / "result.json"
    if done.is_file() and not force:
        old = json.loads(done.read_text())
        if old.get("namelist") == text and (any_engine or old.get("engine") == engine):
            return old
    (folder / "run.nml").write_text(text)
    env = dict(os.environ, OMP_NUM_THREADS="1")
    for attempt in range(3):        # a run killed by a signal (not by its own error) is run again
        start = time.time()
        with open(folder / "run.log", "w") as log:
            proc = subprocess.Popen([anm, "run", "--force", str(folder / "run.nml")], cwd=J.ROOT,
                                    stdout=log, stderr=subprocess.STDOUT, env=env)
            _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = code = os.waitstatus_to_exitcode(status)
        if code >= 0:
            break
    if code != 0:
        raise RuntimeError(f"{job.name}: anm run failed ({code}), see {folder / 'run.log'}")
    result = {"study": job.study, "value": job.value, "seed": job.seed, "commit": head,
              "engine": engine,
              "namelist": text, "cpu_s": round(usage.ru_utime + usage.ru_stime, 2),
              "wall_s": round(time.time() - start, 2),
              **read_summary(folder / "model-summary.csv")}
    if job.study != "msand" or job.seed != J.SEEDS[0]:
        (folder / "model.h5").unlink(missing_ok=True)   # only M_sand seed 1 is needed afterwards
    tmp = done.with_suffix(".tmp")
    tmp.write_text(json.dumps(result, indent=1))
    tmp.replace(done)
    return result


def run_all(anm: str, workers: int = 2, seeds=J.SEEDS, force: bool = False,
            scratch: pathlib.Path = SCRATCH, any_engine: bool = False) -> list[dict]:
    """Every job (seed by seed), `workers` at a time; the results in job order."""
    head, engine = commit(), engine_commit()
    todo = J.all_jobs(seeds)
    results = [None] * len(todo)
    failed = []
    with concurrent.futures.ThreadPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(run_job, anm, job, scratch, head, engine, force, None, any_engine): i for i, job in enumerate(todo)}
        for n, fut in enumerate(concurrent.futures.as_completed(futures), 1):
            i = futures[fut]
            try:
                results[i] = r = fut.result()
            except Exception as exc:        # report, go on with the other jobs, fail at the end
                failed.append(todo[i].name)
                print(f"[{n}/{len(todo)}] {todo[i].name}: FAILED: {exc}", file=sys.stderr, flush=True)
                continue
            print(f"[{n}/{len(todo)}] {todo[i].name}: PD {r['total']['fraction']:.4f}, "
                  f"{r['total']['count']} particles, {r['cpu_s']} s CPU", file=sys.stderr, flush=True)
    if failed:
        raise RuntimeError(f"{len(failed)} jobs failed: {', '.join(failed)}")
    return results

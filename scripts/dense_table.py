#!/usr/bin/env python3
"""Total packing fractions reached by RSA and by the dense strategy for three gradations (issue 14).

For each gradation the script writes two namelists that differ only in `&parking` and runs
`anm run` on each (2 OpenMP threads unless OMP_NUM_THREADS is set), then reads the model's
summary table (`NAME-summary.csv`, row `total`):

- `concrete`: inputs/concrete.nml as it is (six sieves, 0.70 of a 40 mm periodic box);
- `msand`: inputs/msand.nml's gradation (shares 0.20 : 0.02 : 0.08 of its three sieves) asked for
  `--total` of the box;
- `table2_3`: inputs/table2_3_void.nml's gradation (thesis Table 2.3, six coarse sieves) asked for
  `--total` of the box.

Both strategies use void placement, 2,000 locations and `max_failures = 100` (RSA's own stopping
rule); the dense runs add `strategy = 'dense'`, `dense_sweeps = 4`, `dense_grow_scale = 0.7`,
`dense_overfill = 0.2`, `contact_gap = 0.003`, `dense_max_failures = 400` (as inputs/concrete.nml) and
`dense_time_limit = --time-limit` seconds. Each row gives the target, the total reached, the
particles and the wall and CPU seconds of the run; each run's progress lines are kept in
`WORK/GRADATION-STRATEGY.log`.

    python3 scripts/dense_table.py --anm build/install/bin/anm --out table.md [--only concrete,msand]
        [--total 0.60] [--time-limit 540] [--work DIR]
"""
from __future__ import annotations

import argparse
import csv
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

PARKING = {
    "rsa": "&parking max_locations = 2000, placement = 'void', max_failures = 100 /",
    "dense": ("&parking max_locations = 2000, placement = 'void', max_failures = 100,\n"
              "   strategy = 'dense', dense_rounds = 20, dense_sweeps = 4, dense_grow_scale = 0.7,\n"
              "   dense_overfill = 0.2, contact_gap = 0.003, dense_max_failures = 400,\n"
              "   dense_time_limit = {limit} /"),
}


def _span(text: str, name: str) -> tuple[int, int]:
    """Start and end of the group `&name ... /` (a `/` inside quotes does not end it)."""
    m = re.search(r"&" + name + r"\b", text, flags=re.I)
    if not m:
        raise SystemExit(f"dense_table: no &{name} group in the namelist")
    quote = None
    for k in range(m.end(), len(text)):
        c = text[k]
        if quote:
            if c == quote:
                quote = None
        elif c in "'\"":
            quote = c
        elif c == "/":
            return m.start(), k + 1
    raise SystemExit(f"dense_table: the &{name} group does not end")


def _replace_group(text: str, name: str, new: str) -> str:
    a, b = _span(text, name)
    return text[:a] + new + text[b:]


def _share(text: str, total: float) -> str:
    """Turn a namelist's `fraction` into shares of `total` (box fractions become shares)."""
    a, b = _span(text, "sieves")
    body = text[a:b]
    if re.search(r"fraction_mode\s*=\s*'share'", body, flags=re.I):
        body = re.sub(r"total_fraction\s*=\s*[0-9.eEdD+-]+", f"total_fraction = {total}", body)
    else:
        f = re.search(r"^\s*fraction\s*=\s*([^\n]+)$", body, flags=re.M)
        values = [float(v) for v in f.group(1).replace(",", " ").split()]
        shares = ", ".join(f"{v / sum(values):.10f}" for v in values)
        body = (body[:f.start(1)] + shares + f"\n   fraction_mode = 'share', total_fraction = {total}"
                + body[f.end(1):])
    return text[:a] + body + text[b:]


def namelist(gradation: str, strategy: str, total: float, limit: float, outdir: Path) -> str:
    """The namelist text of one run."""
    source = {"concrete": "inputs/concrete.nml", "msand": "inputs/msand.nml",
              "table2_3": "inputs/table2_3_void.nml"}[gradation]
    text = (ROOT / source).read_text()
    text = "\n".join(line for line in text.splitlines() if not line.lstrip().startswith("!")) + "\n"
    if gradation != "concrete":
        text = _share(text, total)
    text = _replace_group(text, "parking", PARKING[strategy].format(limit=limit))
    text = _replace_group(text, "output",
                          f"&output directory = '{outdir}', name = 'model', vrml = .false. /")
    # the inputs name shape folders relative to the repository root
    return text.replace("'../shared/", f"'{ROOT.parent / 'shared'}/")


def run(anm: str, nml: Path, outdir: Path) -> dict:
    """Run one namelist; the total row of its summary with wall and CPU seconds."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.monotonic()
    env = dict(os.environ)
    env.setdefault("OMP_NUM_THREADS", "2")
    proc = subprocess.run([anm, "run", "--force", str(nml)], env=env, capture_output=True, text=True)
    wall = time.monotonic() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    nml.with_suffix(".log").write_text(proc.stderr)
    if proc.returncode != 0:
        sys.stderr.write(proc.stderr[-2000:])
        raise SystemExit(f"dense_table: anm run {nml} failed (exit {proc.returncode})")
    with open(outdir / "model-summary.csv", newline="") as fh:
        total = [r for r in csv.DictReader(fh) if r["sieve"] == "total"][0]
    return {"target": float(total["target_fraction"]), "achieved": float(total["achieved_fraction"]),
            "count": int(total["count"]), "wall": wall,
            "cpu": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--anm", default=str(ROOT / "build" / "install" / "bin" / "anm"))
    ap.add_argument("--out", help="markdown table to write (also printed)")
    ap.add_argument("--only", default="concrete,msand,table2_3")
    ap.add_argument("--strategies", default="rsa,dense")
    ap.add_argument("--total", type=float, default=0.60, help="total fraction asked of msand and table2_3")
    ap.add_argument("--time-limit", type=float, default=570.0, help="dense_time_limit of the dense runs (s)")
    ap.add_argument("--work", help="folder for the namelists and models (default: a temporary one)")
    args = ap.parse_args(argv)
    work = Path(args.work) if args.work else Path(tempfile.mkdtemp(prefix="dense-table-"))
    work.mkdir(parents=True, exist_ok=True)
    rows = ["| gradation | strategy | target | reached | particles | wall (s) | CPU (s) |",
            "|---|---|---|---|---|---|---|"]
    for g in args.only.split(","):
        for s in args.strategies.split(","):
            outdir = work / f"{g}-{s}"
            nml = work / f"{g}-{s}.nml"
            nml.write_text(namelist(g, s, args.total, args.time_limit, outdir))
            r = run(args.anm, nml, outdir)
            rows.append(f"| {g} | {s} | {r['target']:.3f} | {r['achieved']:.4f} | {r['count']:,} | "
                        f"{r['wall']:.0f} | {r['cpu']:.0f} |")
            print(rows[-1], flush=True)
    text = "\n".join(rows) + "\n"
    if args.out:
        Path(args.out).write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())

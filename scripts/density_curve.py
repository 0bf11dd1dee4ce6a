#!/usr/bin/env python3
"""Density against time of one `anm run` (issue 14: the density-versus-time curve).

Runs `anm run NAMELIST`, stamps every progress line on stderr with the time since the start,
and follows the packing fraction of the whole model from them:

- while a sieve is parked by RSA, its `sieve S: placed N, fraction F of T; ...` lines give its
  fraction, and its first `sieve S done: ..., fraction F ...` line the fraction RSA reached;
- after that only `sieve S: dense round R, N particles, fraction F ...` and `sieve S: growth ended
  after N sweeps, M particles short of their size, fraction F` lines (and the `growth sweep N, ...`
  lines every 10 sweeps) change it (the RSA
  passes inside a dense round print their own `placed`/`done` lines for the round's request only,
  which are ignored).

The total is the sum over the sieves of their latest fraction. Writes a CSV (seconds, total, the
line's sieve, event) and, with --png, the curve. With --time-limit the run is stopped after that
many seconds (the curve up to then is kept; the stopped run writes no model).

    python3 scripts/density_curve.py inputs/concrete.nml --csv curve.csv --png curve.png [--time-limit 1800]
    python3 scripts/density_curve.py --parse LOG --csv curve.csv    # a log of `[seconds] line` lines
"""
from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

PLACED = re.compile(r"^sieve (\d+): placed \d+, fraction\s+([0-9.Ee+-]+) of")
DONE = re.compile(r"^sieve (\d+) done: \d+ particles, fraction\s+([0-9.Ee+-]+)")
ROUND = re.compile(r"^sieve (\d+): dense round \d+, \d+ particles, fraction\s+([0-9.Ee+-]+)")
GROWTH = re.compile(r"^sieve (\d+): growth (?:ended after \d+ sweeps|sweep \d+), \d+ particles short of their size, "
                    r"fraction\s+([0-9.Ee+-]+)")


class Curve:
    """The packing fraction followed through the progress lines of one run."""

    def __init__(self) -> None:
        self.latest: dict[int, float] = {}
        self.rsa_done: set[int] = set()
        self.points: list[tuple[float, float, int, str]] = []

    def feed(self, seconds: float, line: str) -> None:
        """Take one progress line printed `seconds` after the start."""
        for pattern, event in ((ROUND, "dense round"), (GROWTH, "growth"), (DONE, "sieve done"), (PLACED, "placed")):
            m = pattern.match(line.strip())
            if not m:
                continue
            sieve, frac = int(m.group(1)), float(m.group(2))
            if event not in ("dense round", "growth") and sieve in self.rsa_done:
                return                      # an RSA pass inside a dense round: the round's own request
            if event == "sieve done":
                self.rsa_done.add(sieve)
            self.latest[sieve] = frac
            self.points.append((seconds, sum(self.latest.values()), sieve, event))
            return

    def csv(self) -> str:
        rows = ["seconds,total_fraction,sieve,event"]
        rows += [f"{t:.2f},{f:.6f},{s},{e}" for t, f, s, e in self.points]
        return "\n".join(rows) + "\n"


def write_atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def plot(curve: Curve, path: Path, title: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import io

    fig, ax = plt.subplots(figsize=(7, 4.2))
    t = [p[0] for p in curve.points]
    f = [p[1] for p in curve.points]
    ax.step(t, f, where="post", color="tab:blue")
    dense = [(p[0], p[1]) for p in curve.points if p[3] == "dense round"]
    if dense:
        ax.plot(*zip(*dense), "o", ms=3, color="tab:red", label="after a dense round")
        ax.legend()
    ax.set_xlabel("time since start (s)")
    ax.set_ylabel("packing fraction of the model")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=120)
    plt.close(fig)
    write_atomic(path, buf.getvalue())


def run(anm: str, namelist: str, limit: float | None, curve: Curve, log) -> int:
    start = time.monotonic()
    proc = subprocess.Popen([anm, "run", "--force", namelist], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, bufsize=1, start_new_session=True)
    stopped = False
    assert proc.stdout is not None
    for line in proc.stdout:
        now = time.monotonic() - start
        log.write(f"[{now:9.2f}] {line}")
        log.flush()
        curve.feed(now, line)
        if limit is not None and now > limit and proc.poll() is None:
            os.killpg(proc.pid, signal.SIGTERM)
            stopped = True
            break
    code = proc.wait()
    if stopped:
        log.write(f"[{time.monotonic() - start:9.2f}] stopped by --time-limit {limit} s\n")
        return 0
    return code


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("namelist", nargs="?", help="namelist to run")
    ap.add_argument("--parse", metavar="LOG", help="read a log of '[seconds] line' lines instead of running")
    ap.add_argument("--anm", default=str(Path(__file__).resolve().parents[1] / "build/install/bin/anm"))
    ap.add_argument("--time-limit", type=float, metavar="S", help="stop the run after S seconds")
    ap.add_argument("--csv", required=True, help="the curve as CSV")
    ap.add_argument("--png", help="the curve as a picture")
    ap.add_argument("--log", help="the stamped progress lines (default: stderr)")
    args = ap.parse_args(argv)
    curve = Curve()
    if args.parse:
        for line in Path(args.parse).read_text().splitlines():
            m = re.match(r"^\[\s*([0-9.]+)\]\s?(.*)$", line)
            if m:
                curve.feed(float(m.group(1)), m.group(2))
        code = 0
        title = Path(args.parse).name
    else:
        if not args.namelist:
            ap.error("give a namelist (or --parse LOG)")
        log = open(args.log, "w") if args.log else sys.stderr
        try:
            code = run(args.anm, args.namelist, args.time_limit, curve, log)
        finally:
            if args.log:
                log.close()
        title = Path(args.namelist).name
    write_atomic(Path(args.csv), curve.csv().encode())
    if args.png:
        plot(curve, Path(args.png), title)
    if curve.points:
        t, f, _, _ = curve.points[-1]
        print(f"largest total fraction {max(p[1] for p in curve.points):.4f}; last {f:.4f} at {t:.1f} s")
    return code


if __name__ == "__main__":
    sys.exit(main())

"""Slicing benchmark: one 400 x 400-pixel slice and a stack of 400 parallel slices of a model
(default: the M_sand model of inputs/msand.nml, out/msand/model.h5). Prints wall times and the
kernel's work counters. Usage: python3 bench/bench_slicing.py [MODEL.h5] [--shells FRACTION]"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

from anm_post import ShellSpec, Slicer, axis_plane, read_model


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("model", nargs="?", default="out/msand/model.h5")
    ap.add_argument("--shells", type=float, help="also grow shells of this fraction of the length")
    args = ap.parse_args()
    t0 = time.perf_counter()
    model = read_model(args.model)
    t1 = time.perf_counter()
    slicer = Slicer(model, ShellSpec((args.shells,)) if args.shells else None)
    pixel = float(model.box[0]) / 400
    slicer.slice(axis_plane(model, "z", 0.5 * float(model.box[2]), pixel))   # forms (and shells) built once
    t2 = time.perf_counter()
    print(f"# {model.n_particles} particles, box {model.box.tolist()} mm, OMP_NUM_THREADS="
          f"{os.environ.get('OMP_NUM_THREADS', 'unset')}, nproc {os.cpu_count()}")
    print(f"read model: {t1 - t0:.2f} s; particle forms{' and shells' if args.shells else ''} + first slice: "
          f"{t2 - t1:.2f} s")
    times = []
    for z in (3.1, 7.7, 10.3, 14.9, 18.2):
        t = time.perf_counter()
        res = slicer.slice(axis_plane(model, "z", z * float(model.box[2]) / 20, pixel))
        times.append(time.perf_counter() - t)
    print(f"one 400 x 400 slice: median {np.median(times):.3f} s (max {max(times):.3f} s); "
          f"counters of the last: {res.stats}")
    t = time.perf_counter()
    fr = [r.particle_fraction for r in slicer.stack("z", pixel, 1.0)]
    dt = time.perf_counter() - t
    print(f"stack of {len(fr)} slices (rho_s = 1): {dt:.1f} s; mean particle area fraction {np.mean(fr):.4f} "
          f"(model volume fraction {model.sieves['achieved_fraction'].sum():.4f})")


if __name__ == "__main__":
    main()

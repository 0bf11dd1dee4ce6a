"""Compare two model files dataset by dataset (and attributes), e.g. a job's model before and
after a change that must not alter it:

    python3 scripts/compare_models.py out/before/model.h5 out/after/model.h5 [--skip run/namelist]

Exit status 0 when every dataset is bit-identical (SHA-256 of its bytes) and the sets of datasets
agree, 1 otherwise. Attributes named with --ignore (run timings by default) are skipped.
"""
import argparse
import hashlib
import sys

import h5py
import numpy as np


def digests(path, ignore, skip=()):
    out = {}
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset) and name not in skip:
                data = obj[()]
                out["dataset " + name] = hashlib.sha256(np.asarray(data).tobytes()).hexdigest()
            for key, val in obj.attrs.items():
                if key in ignore:
                    continue
                out[f"attribute {name}@{key}"] = hashlib.sha256(np.asarray(val).tobytes()).hexdigest()
        f.visititems(visit)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--skip", action="append", default=[],
                    help="datasets to skip (e.g. run/namelist when the output folders differ)")
    ap.add_argument("--ignore", action="append", default=None,
                    help="attribute names to skip (default: wall_time, created, version)")
    args = ap.parse_args()
    ignore = set(args.ignore or ["wall_time", "created", "version", "date", "time"])
    skip = set(args.skip)
    da, db = digests(args.a, ignore, skip), digests(args.b, ignore, skip)
    bad = 0
    for key in sorted(set(da) | set(db)):
        if da.get(key) != db.get(key):
            bad += 1
            print("differs:", key)
    nd = sum(1 for k in da if k.startswith("dataset"))
    print(f"{nd} datasets, {len(da) - nd} attributes compared, {bad} differ")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env bash
# The component benchmarks only (SH synthesis, shells, contact, slicing), printed to stdout; they
# are not timed tests. `bash scripts/benchmarks.sh` runs these and the parking jobs and rewrites
# docs/performance.md.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
bash scripts/setup.sh
source scripts/flags.sh
fpm build --profile release --flag "$ANM_FFLAGS" >/dev/null 2>&1
echo "# machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
OMP_NUM_THREADS=1 fpm run --profile release --flag "$ANM_FFLAGS" bench-sh 2>/dev/null
OMP_NUM_THREADS=1 fpm run --profile release --flag "$ANM_FFLAGS" bench-shells 2>/dev/null
OMP_NUM_THREADS=1 fpm run --profile release --flag "$ANM_FFLAGS" bench-contact 2>/dev/null
OMP_NUM_THREADS=2 python3 bench/bench_slicing.py "${ANM_SLICE_MODEL:-out/msand/model.h5}"

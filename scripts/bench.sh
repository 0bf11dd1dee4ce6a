#!/usr/bin/env bash
# Benchmarks (they print figures; they are not timed tests). Figures go to docs/performance.md
# by hand, with this command and the machine's core count.
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

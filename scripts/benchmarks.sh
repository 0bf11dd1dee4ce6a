#!/usr/bin/env bash
# The benchmark suite behind one command: installs what is missing, builds, runs every benchmark
# (SH synthesis, shells, contact, the parking jobs with 1 and 2 threads, the RSA reference side by
# side, 10^6 particles, slicing) and rewrites docs/performance.md with the figures, the commands and
# the machine's core count. About 15-25 minutes on 2 cores. Arguments go to bench/run_all.py
# (e.g. --only contact shells, --skip million).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
bash scripts/setup.sh >&2
anm="$(bash scripts/build.sh)"
source scripts/flags.sh
fpm build --profile release --flag "$ANM_FFLAGS" >/dev/null 2>&1
exec python3 bench/run_all.py --anm "$anm" "$@"

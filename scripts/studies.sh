#!/usr/bin/env bash
# The thesis' tables over ten seeds (Tables 2.1, 2.2, 2.3, 3.1, 3.2; issue 18) and the single-run
# studies (Figs 2.14, 2.15, 3.8-3.13): runs every job of studies/jobs.py in out/studies/ensemble/
# (resuming: a job whose result is there for the same namelist and engine commit is not run again),
# gathers the results into docs/studies/data.json and writes docs/studies.md and its figures.
# Needs ../shared/shapes. About 40 min of CPU (one OpenMP thread per run).
# Usage: bash scripts/studies.sh [--workers N] [--force]   (or: bash scripts/studies.sh page)
set -euo pipefail
cd "$(dirname "$0")/.."
anm=$(bash scripts/build.sh | tail -n 1)
bash scripts/setup.sh > /dev/null
if [[ "${1:-}" != "page" ]]; then
   python3 -m studies --anm "$anm" run "$@"
   python3 -m studies --anm "$anm" extras
   python3 -m studies collect
fi
python3 -m studies page
echo "studies: docs/studies.md, docs/studies/data.json, figures in docs/figures"

#!/usr/bin/env bash
# Thesis Figs 2.14 and 2.15: extent-box volume against N_ext and overlap distance against N_box
# for one real coarse shape (MA111-7-coarse-anm-00002, order 14). Results in out/studies/eob/,
# figures copied to docs/figures/. Needs ../shared/shapes. Usage: bash scripts/study_eob.sh [SHAPE_FILE]
set -euo pipefail
cd "$(dirname "$0")/.."
anm=$(bash scripts/build.sh | tail -n 1)
bash scripts/setup.sh > /dev/null
# this checkout's anm_post, whatever the editable install points at
anm_post() { PYTHONPATH="$PWD/post${PYTHONPATH:+:$PYTHONPATH}" python3 -m anm_post "$@"; }
shape=${1:-../shared/shapes/MA111-7-coarse/MA111-7-coarse-anm-00002.dat}
out=out/studies/eob
mkdir -p "$out" docs/figures
"$anm" study next "$shape" --csv "$out/next.csv"
"$anm" study nbox "$shape" --csv "$out/nbox.csv"
anm_post plot "$out/next.csv" -o "$out/fig2_14_next.png"
anm_post plot "$out/nbox.csv" -o "$out/fig2_15_nbox.png"
cp "$out/fig2_14_next.png" "$out/fig2_15_nbox.png" docs/figures/
echo "study_eob: CSV and plots in $out, figures in docs/figures"

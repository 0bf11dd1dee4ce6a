#!/usr/bin/env bash
# Thesis Tables 2.1/2.2 and Figs 2.16/2.17: inputs/table2_1.nml (66 mm box, four sieves 7-11 mm,
# non-overlapping shells) with the shell thickness swept from 0 to 2 % of the particle length.
# Runs in out/studies/shells/; table and figure to docs/figures/. Needs ../shared/shapes.
# Usage: bash scripts/study_shells.sh
set -euo pipefail
cd "$(dirname "$0")/.."
anm=$(bash scripts/build.sh | tail -n 1)
bash scripts/setup.sh > /dev/null
# this checkout's anm_post, whatever the editable install points at
anm_post() { PYTHONPATH="$PWD/post${PYTHONPATH:+:$PYTHONPATH}" python3 -m anm_post "$@"; }
out=out/studies/shells
mkdir -p "$out" docs/figures
runs=()
for t in 0 0.002 0.004 0.006 0.008 0.010 0.012 0.014 0.016 0.018 0.020; do
   dir="$out/t$t"
   mkdir -p "$dir"
   if [[ "$t" == 0 ]]; then
      shells="\&shells nlayer = 0 /"
   else
      shells="\&shells nlayer = 1, thickness = $t, thickness_unit = 'fraction', mode = 'exclude' /"
   fi
   sed -e "s|^&shells.*|$shells|" -e "s|directory = 'out/table2_1'|directory = '$dir'|" \
      -e "s|, name = 'model' /|, name = 'model', vrml = .false. /|" inputs/table2_1.nml > "$dir/run.nml"
   /usr/bin/time -f "shell $t: %e s" "$anm" run --force "$dir/run.nml" > "$dir/run.log" 2>&1
   runs+=("$t=$dir/model-summary.csv")
done
anm_post sweep "${runs[@]}" --label "shell thickness (% of L)" --scale 100 --shells \
   --markdown "$out/table2_1_2.md" --png "$out/fig2_16_17.png"
cp "$out/fig2_16_17.png" docs/figures/

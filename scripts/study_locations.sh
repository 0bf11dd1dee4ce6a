#!/usr/bin/env bash
# Thesis Table 2.3: inputs/table2_3.nml (66 mm periodic box, six sieves 4.75-11 mm, target PD
# 0.355) with the number of random locations swept as in the thesis (30 ... 1500).
# Runs in out/studies/locations/; table and figure to docs/figures/. Needs ../shared/shapes.
# Usage: bash scripts/study_locations.sh
set -euo pipefail
cd "$(dirname "$0")/.."
anm=$(bash scripts/build.sh | tail -n 1)
bash scripts/setup.sh > /dev/null
# this checkout's anm_post, whatever the editable install points at
anm_post() { PYTHONPATH="$PWD/post${PYTHONPATH:+:$PYTHONPATH}" python3 -m anm_post "$@"; }
out=out/studies/locations
mkdir -p "$out" docs/figures
runs=()
for n in 30 60 90 120 140 285 450 975 1500; do
   dir="$out/n$n"
   mkdir -p "$dir"
   sed -e "s|max_locations = [0-9]*|max_locations = $n|" -e "s|directory = '[^']*'|directory = '$dir'|" \
      inputs/table2_3.nml > "$dir/run.nml"
   /usr/bin/time -f "locations $n: %e s" "$anm" run --force "$dir/run.nml" > "$dir/run.log" 2>&1
   runs+=("$n=$dir/model-summary.csv")
done
anm_post sweep "${runs[@]}" --label "random locations" --markdown "$out/table2_3.md" --png "$out/table2_3.png"
cp "$out/table2_3.png" docs/figures/

#!/usr/bin/env bash
# The main job: make synthetic aggregate shapes (no CT data needed) and print their geometry
# table; output in out/ (override with ANM_OUT). Installs what is missing first.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$here/scripts/setup.sh"
anm="$(bash "$here/scripts/build.sh")"
out="${ANM_OUT:-$here/out}"
mkdir -p "$out"
"$anm" synth "$out/shapes" --count 24 --seed 1
"$anm" shape "$out/shapes" > "$out/geometry.txt"
python3 -m anm_post table "$out/geometry.txt" --csv "$out/geometry.csv"
echo "main job: geometry table in $out/geometry.txt and $out/geometry.csv"

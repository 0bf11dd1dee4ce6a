#!/usr/bin/env bash
# The main job: the default namelist (inputs/default.nml: a mortar-like model of synthetic
# aggregate shapes, no CT data needed), then an independent audit of the model file.
# then a slice picture of it made by the Python package (anm-post slice: z = 10 mm, 0.05 mm
# pixels, ITZ shells of 2 % of each particle's length grown for the slice, with a legend).
# Output in out/ (the namelist's &output directory). Installs what is missing first.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
bash "$here/scripts/setup.sh"
anm="$(bash "$here/scripts/build.sh")"
"$anm" run --force inputs/default.nml
"$anm" verify out/default.h5
python3 -m anm_post slice out/default.h5 --axis z --position 10 --pixel 0.05 --shells 0.02 \
    --png out/default-slice.png --labels out/default-slice.npz
echo "main job: model out/default.h5, summary out/default-summary.csv, VRML out/default.wrl, slice out/default-slice.png"

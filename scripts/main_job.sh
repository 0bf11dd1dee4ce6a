#!/usr/bin/env bash
# The main job: the default namelist (inputs/default.nml: a mortar-like model of synthetic
# aggregate shapes, no CT data needed), then an independent audit of the model file.
# Output in out/ (the namelist's &output directory). Installs what is missing first.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
bash "$here/scripts/setup.sh"
anm="$(bash "$here/scripts/build.sh")"
"$anm" run inputs/default.nml
"$anm" verify out/default.h5
echo "main job: model out/default.h5, summary out/default-summary.csv, VRML out/default.wrl"

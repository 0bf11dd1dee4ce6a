#!/usr/bin/env bash
# Packing fraction of random sequential addition of monodisperse spheres (order 0, radius 1 mm,
# periodic 12 mm box) against the attempt budget per particle: prints CSV
# max_locations,attempts,spheres,fraction. The saturation limit is 0.3841.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
anm="${ANM_BIN:-$(bash "$here/scripts/build.sh")}"
tmp="$(mktemp -d)"
echo "max_locations,attempts,spheres,fraction"
for n in 10 100 1000 10000 100000 1000000; do
    sed -e "s/max_locations = [0-9]*/max_locations = $n/" -e "s|directory = 'out/rsa'|directory = '$tmp'|" \
        inputs/rsa_spheres.nml > "$tmp/rsa.nml"
    "$anm" run --force "$tmp/rsa.nml" > /dev/null 2>&1
    python3 - "$tmp/model.h5" "$n" <<'PY'
import sys, h5py
f = h5py.File(sys.argv[1])
print(f"{sys.argv[2]},{int(f['run'].attrs['attempts'])},{int(f['sieves/count'][0])},{f['sieves/achieved_fraction'][0]:.4f}")
PY
done
rm -rf "$tmp"

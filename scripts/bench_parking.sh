#!/usr/bin/env bash
# Parking benchmarks (figures, not timed tests): the default job with 1 and 2 threads, M_sand
# (needs ../shared/shapes), the Table 2.3 setup at 1500 locations (uniform and void placement), and
# 200,000 spheres to a packing fraction of 0.30 beside ../shared/bench/rsa_spheres.c.
# Prints wall time and peak memory (GNU time); outputs go to a temporary folder.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
anm="${ANM_BIN:-$(bash "$here/scripts/build.sh")}"
tmp="$(mktemp -d)"
echo "# machine: $(nproc) cores; load average: $(cut -d' ' -f1-3 /proc/loadavg)"
run() {   # name threads namelist [sed expressions...]
    local name="$1" threads="$2" nml="$3"; shift 3
    sed -e "s|directory = '[^']*'|directory = '$tmp/$name'|" "$@" "$nml" > "$tmp/$name.nml"
    /usr/bin/time -f "$name threads=$threads: %e s wall, %M KB peak" env OMP_NUM_THREADS="$threads" \
        "$anm" run "$tmp/$name.nml" > "$tmp/$name.out" 2> "$tmp/$name.err" || { tail -3 "$tmp/$name.err"; return; }
    tail -1 "$tmp/$name.err"
    grep -E "^total" "$tmp/$name.out"
}
run default1 1 inputs/default.nml
run default2 2 inputs/default.nml
if [ -d ../shared/shapes ]; then
    run msand1 1 inputs/msand.nml
    run msand2 2 inputs/msand.nml
    run table23 2 inputs/table2_3.nml
    run table23void 2 inputs/table2_3.nml -e "s|&parking max_locations = 1500 /|\&parking max_locations = 1500, placement = 'void' /|"
fi
L=140.82046803408818
cat > "$tmp/rsa.nml" <<NML
&box length = $L, $L, $L, periodic = .true. /
&sieves nsieve = 1, min_width = 2, max_width = 2, fraction = 0.30, source = 'sphere', order = 0 /
&parking max_locations = 1000000 /
&output directory = '$tmp/rsa', name = 'model', vrml = .false. /
NML
for t in 1 2; do
    /usr/bin/time -f "rsa200k threads=$t: %e s wall, %M KB peak" env OMP_NUM_THREADS=$t "$anm" run "$tmp/rsa.nml" \
        > /dev/null 2> "$tmp/rsa.err"; tail -1 "$tmp/rsa.err"
done
if [ -f ../shared/bench/rsa_spheres.c ]; then
    gcc -O2 -march=native -o "$tmp/rsa_spheres" ../shared/bench/rsa_spheres.c -lm
    echo "reference: $("$tmp/rsa_spheres" 200000 0.30 1000000 1)"
fi
rm -rf "$tmp"

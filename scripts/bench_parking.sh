#!/usr/bin/env bash
# Parking benchmarks (figures, not timed tests):
#   - the default job with 1 and 2 threads;
#   - M_sand with 1 and 2 threads and the Table 2.3 setup at 1500 locations, uniform and void
#     placement (these need ../shared/shapes);
#   - 200,000 spheres to a packing fraction of 0.30 with 1 and 2 threads, alternated with
#     ../shared/bench/rsa_spheres.c (gcc -O2 -march=native) run side by side (RSA_ROUNDS rounds,
#     default 3: the machine is shared, so single runs are noisy);
#   - with --million: inputs/million.nml (about 10^6 sand grains, 2 threads) and `anm verify` on its
#     model (synthetic shapes instead of ../shared/shapes/MA107-6-fine when that is absent).
# Prints wall time, user CPU time and peak memory (GNU time); models go to a temporary folder.
# Usage: bash scripts/bench_parking.sh [--million] [--only rsa|msand|default|table23|million]
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
million=0
only=""
while [ $# -gt 0 ]; do
    case "$1" in
    --million) million=1 ;;
    --only) only="$2"; shift ;;
    *) echo "usage: $0 [--million] [--only rsa|msand|default|table23|million]" >&2; exit 2 ;;
    esac
    shift
done
want() { [ -z "$only" ] || [ "$only" = "$1" ]; }
anm="${ANM_BIN:-$(bash "$here/scripts/build.sh")}"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
echo "# machine: $(nproc) cores; load average at start: $(cut -d' ' -f1-3 /proc/loadavg)"
timed() {   # label command... : one line "label: wall, user, peak" (GNU time)
    local label="$1"; shift
    /usr/bin/time -f "$label: %e s wall, %U s user, %M KB peak (load $(cut -d' ' -f1 /proc/loadavg))" "$@"
}
run() {   # name threads namelist [sed expressions...]
    local name="$1" threads="$2" nml="$3"; shift 3
    sed -e "s|directory = '[^']*'|directory = '$tmp/$name'|" "$@" "$nml" > "$tmp/$name.nml"
    timed "$name threads=$threads" env OMP_NUM_THREADS="$threads" "$anm" run --force "$tmp/$name.nml" \
        > "$tmp/$name.out" 2> "$tmp/$name.err" || { tail -3 "$tmp/$name.err"; return; }
    grep -E "done:" "$tmp/$name.err" | tail -1
    tail -1 "$tmp/$name.err"
    grep -E "^total" "$tmp/$name.out" || true
}
if want default; then
    run default1 1 inputs/default.nml
    run default2 2 inputs/default.nml
fi
if [ -d ../shared/shapes ]; then
    if want msand; then
        run msand1 1 inputs/msand.nml
        run msand2 2 inputs/msand.nml
    fi
    if want table23; then
        run table23 2 inputs/table2_3.nml
        run table23void 2 inputs/table2_3.nml \
            -e "s|&parking max_locations = 1500 /|\&parking max_locations = 1500, placement = 'void' /|"
    fi
fi
if want rsa; then
    L=140.82046803408818
    cat > "$tmp/rsa.nml" <<NML
&box length = $L, $L, $L, periodic = .true. /
&sieves nsieve = 1, min_width = 2, max_width = 2, fraction = 0.30, source = 'sphere', order = 0 /
&parking max_locations = 1000000 /
&output directory = '$tmp/rsa', name = 'model', vrml = .false. /
NML
    ref=""
    if [ -f ../shared/bench/rsa_spheres.c ]; then
        gcc -O2 -march=native -o "$tmp/rsa_spheres" ../shared/bench/rsa_spheres.c -lm
        ref="$tmp/rsa_spheres"
    fi
    for round in $(seq "${RSA_ROUNDS:-3}"); do
        for t in 1 2; do
            timed "rsa200k round $round threads=$t" env OMP_NUM_THREADS=$t "$anm" run --force "$tmp/rsa.nml" \
                > /dev/null 2> "$tmp/rsa.err"
            tail -1 "$tmp/rsa.err"
            if [ -n "$ref" ]; then
                echo "reference round $round: $("$ref" 200000 0.30 1000000 1) (load $(cut -d' ' -f1 /proc/loadavg))"
            fi
        done
    done
fi
if [ "$million" = 1 ] && want million; then
    src=()
    if [ ! -d ../shared/shapes/MA107-6-fine ]; then
        src=(-e "s|source = '../shared/shapes/MA107-6-fine'|source = 'synthetic'|")
    fi
    run million 2 inputs/million.nml "${src[@]}"
    timed "verify million threads=2" env OMP_NUM_THREADS=2 "$anm" verify "$tmp/million/model.h5" \
        > "$tmp/verify.out" 2> "$tmp/verify.err" || true
    tail -1 "$tmp/verify.err"
    grep -E "particles|pairs|result" "$tmp/verify.out"
fi

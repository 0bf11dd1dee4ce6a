#!/usr/bin/env bash
# Thesis section 3.4 study: M_sand with shaped sand (Table 3.1, Figs 3.8-3.10) and with spherical
# sand (Table 3.2, Figs 3.11-3.13). Runs inputs/msand.nml and inputs/msand_spheres.nml (unless
# their model files exist; --rerun forces), then the PSD tables, g(t) at rho_s = 1 and the
# convergence in rho_s, and (shaped sand, default shells) the slices at rho_s = 1 against the 3D
# value (Eq 3.11, docs/walleffect.md). Results in out/studies/msand/, figures copied to docs/figures/.
# Needs ../shared/shapes. Usage: bash scripts/study_msand.sh [--rerun]
set -euo pipefail
cd "$(dirname "$0")/.."
anm=$(bash scripts/build.sh | tail -n 1)
bash scripts/setup.sh > /dev/null
# this checkout's anm_post, whatever the editable install points at (an array, not a function, so
# that /usr/bin/time can run it)
anm_post=(env "PYTHONPATH=$PWD/post${PYTHONPATH:+:$PYTHONPATH}" python3 -m anm_post)
out=out/studies/msand
mkdir -p "$out" docs/figures
# thesis: ten shells 0.025-0.474 mm (0.5-5 % of its 9.997 mm particle), R_s = 0.05 mm, slices normal to x
dens=0.005,0.01,0.05,0.1,0.25,0.5,1
for case in model:msand model-spheres:msand_spheres; do
   name=${case%%:*}
   nml=${case##*:}
   if [[ "${1:-}" == "--rerun" || ! -f out/msand/$name.h5 ]]; then
      /usr/bin/time -f "$nml: %e s" "$anm" run --force "inputs/$nml.nml"
   fi
   "${anm_post[@]}" table "out/msand/$name.h5" --format markdown > "$out/$nml-psd.md"
   /usr/bin/time -f "$nml convergence: %e s" "${anm_post[@]}" convergence "out/msand/$name.h5" --densities "$dens" \
      --unit mm --t-min 0.025 --t-max 0.474 \
      --csv "$out/$nml-conv.csv" --png "$out/$nml-conv.png" --rdf-png "$out/$nml-rdf.png" > "$out/$nml-conv.txt"
   cp "$out/$nml-conv.png" "$out/$nml-rdf.png" docs/figures/
done
# Eq 3.11 on M_sand (docs/walleffect.md): slices at rho_s = 1 against the 3D value, default shells
/usr/bin/time -f "msand rdf --volume: %e s" "${anm_post[@]}" rdf out/msand/model.h5 --density 1 --volume \
   --csv "$out/msand-rdf-3d.csv" --png "$out/msand-rdf-3d.png" > "$out/msand-rdf-3d.txt"
cp "$out/msand-rdf-3d.png" docs/figures/
echo "study_msand: tables and plots in $out, figures in docs/figures"

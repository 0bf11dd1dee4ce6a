# Compiler flags added to fpm's release profile (sourced by the other scripts).
# -ffpe-summary=none: no floating-point exception summary at exit (underflow in tiny Legendre
# values is expected and harmless).
export ANM_FFLAGS="${ANM_FFLAGS:--march=native -ffpe-summary=none}"

# The serial build links the serial HDF5 whatever the system default: Debian's `hdf5.pc` is an
# alternative (update-alternatives) that installing libhdf5-openmpi-dev switches to the MPI
# flavour. fpm's hdf5 metapackage asks pkg-config for `hdf5`, so a folder whose hdf5.pc links to
# Debian's hdf5-serial.pc goes first on PKG_CONFIG_PATH (scripts/build_mpi.sh does the same with
# hdf5-openmpi.pc in its own folder). Elsewhere (no hdf5-serial.pc) nothing changes.
anm_pin_hdf5() {
    # $1: flavour (serial, openmpi); prints the folder to put first on PKG_CONFIG_PATH, or nothing
    local root pc dir
    root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
    for pc in /usr/lib/*/pkgconfig/hdf5-"$1".pc /usr/lib/pkgconfig/hdf5-"$1".pc; do
        [ -f "$pc" ] || continue
        dir="$root/build/pkgconfig-hdf5-$1"
        mkdir -p "$dir"
        [ "$(readlink "$dir/hdf5.pc" 2>/dev/null)" = "$pc" ] || ln -sfn "$pc" "$dir/hdf5.pc"
        echo "$dir"
        return 0
    done
}
anm_hdf5_pc_dir="$(anm_pin_hdf5 serial)"
if [ -n "$anm_hdf5_pc_dir" ]; then
    export PKG_CONFIG_PATH="$anm_hdf5_pc_dir${PKG_CONFIG_PATH:+:$PKG_CONFIG_PATH}"
fi
unset anm_hdf5_pc_dir

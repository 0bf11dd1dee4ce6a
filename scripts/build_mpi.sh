#!/usr/bin/env bash
# Build the MPI variant of the anm program (mpi/: the library plus the MPI phase-1 distributor;
# Open MPI and parallel HDF5 from Debian's packages) and print the path of its executable:
#     mpirun -np N "$(bash scripts/build_mpi.sh)" run FILE.nml
# Installs what is missing: libopenmpi-dev openmpi-bin libhdf5-openmpi-dev. Installing
# libhdf5-openmpi-dev switches Debian's default hdf5.pc (update-alternatives) to the MPI flavour;
# the default is restored at once, in the same command, so that other builds on the machine keep
# what they linked (the serial build is pinned to hdf5-serial anyway, scripts/flags.sh).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"

apt_packages=(libopenmpi-dev openmpi-bin libhdf5-openmpi-dev)
missing=()
for p in "${apt_packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    echo "build_mpi: installing Debian packages: ${missing[*]}" >&2
    sudo_cmd=""
    [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
    before="$(update-alternatives --query hdf5.pc 2>/dev/null | sed -n 's/^Value: //p')"
    $sudo_cmd apt-get update -qq
    rc=0
    DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq "${missing[@]}" >/dev/null || rc=$?
    # restore the system default hdf5.pc whatever the install did
    [ -z "$before" ] || $sudo_cmd update-alternatives --set hdf5.pc "$before" >/dev/null
    [ $rc -eq 0 ] || { echo "build_mpi: apt-get install failed" >&2; exit 1; }
    echo "build_mpi: system hdf5.pc: $(pkg-config --variable=pcfiledir hdf5 2>/dev/null)/hdf5.pc -> $(readlink -f "$(pkg-config --variable=pcfiledir hdf5)/hdf5.pc")" >&2
fi

source "$here/scripts/flags.sh"
pc_dir="$(anm_pin_hdf5 openmpi)"
[ -n "$pc_dir" ] || { echo "build_mpi: no hdf5-openmpi.pc found" >&2; exit 1; }
# the serial folder flags.sh put first is replaced by the Open MPI one
export PKG_CONFIG_PATH="$pc_dir"
export FPM_FC=mpifort
cd "$here/mpi"
fpm build --profile release --flag "$ANM_FFLAGS" >&2
fpm install --profile release --flag "$ANM_FFLAGS" --prefix "$here/build/install-mpi" >/dev/null
echo "$here/build/install-mpi/bin/anm"

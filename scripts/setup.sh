#!/usr/bin/env bash
# Install what Anm needs, only what is missing; quick (about a second) when nothing is.
#   Debian packages: gfortran libhdf5-dev liblapack-dev pkg-config
#   PyPI (pinned):   setuptools fpm numpy h5py matplotlib meson ninja pytest meshio vtk, and the post/ package itself
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"

apt_packages=(gfortran libhdf5-dev liblapack-dev pkg-config)
pip_pins=(setuptools==84.2.1 fpm==0.12.0 numpy==2.4.6 h5py==3.16.0 matplotlib==3.11.2 meson==1.12.1 ninja==1.13.2 pytest==9.2.0 meshio==5.3.5 vtk==9.7.1)

missing=()
for p in "${apt_packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    echo "setup: installing Debian packages: ${missing[*]}" >&2
    sudo_cmd=""
    [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
    $sudo_cmd apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq "${missing[@]}" >/dev/null
fi

python="${PYTHON:-python3}"
need_pip=$("$python" - "${pip_pins[@]}" <<'PY'
import sys
from importlib import metadata
out = []
for pin in sys.argv[1:]:
    name, version = pin.split("==")
    try:
        if metadata.version(name) != version:
            out.append(pin)
    except metadata.PackageNotFoundError:
        out.append(pin)
print(" ".join(out))
PY
)
if [ -n "$need_pip" ]; then
    echo "setup: installing from PyPI: $need_pip" >&2
    "$python" -m pip install -q --disable-pip-version-check --root-user-action=ignore $need_pip
fi

# the post-processing package, editable (post/ changes need no reinstall); reinstalled when the
# installed copy belongs to another checkout
installed=$("$python" -c "import anm_post, os; print(os.path.dirname(os.path.dirname(os.path.realpath(anm_post.__file__))))" 2>/dev/null || true)
if [ "$installed" != "$(realpath "$here/post")" ]; then
    echo "setup: installing the anm_post package (post/)" >&2
    "$python" -m pip install -q --disable-pip-version-check --root-user-action=ignore --no-build-isolation --no-deps -e "$here/post"
fi

# the compiled kernels of anm_post (numpy.f2py + meson from src/api/slice.f90 and the program's
# sources, post/meson.build): configured once in build/post-ext, rebuilt by ninja when a source
# changed (a no-op otherwise), then copied into post/anm_post/ when it differs
ext_build="$here/build/post-ext"
if [ ! -f "$ext_build/build.ninja" ]; then
    echo "setup: configuring the anm_post kernels (meson, build/post-ext)" >&2
    rm -rf "$ext_build"
    (cd "$here/post" && "$python" -m mesonbuild.mesonmain setup "$ext_build" . >/dev/null) || {
        echo "setup: meson setup of the anm_post kernels failed (see $ext_build/meson-logs)" >&2; exit 1; }
fi
"$python" -m ninja -C "$ext_build" >"$ext_build/last-build.log" 2>&1 || {
    cat "$ext_build/last-build.log" >&2; echo "setup: building the anm_post kernels failed" >&2; exit 1; }
for so in "$ext_build"/_kernels*.so; do
    cmp -s "$so" "$here/post/anm_post/$(basename "$so")" || cp "$so" "$here/post/anm_post/"
done

#!/usr/bin/env bash
# Build the anm program (release profile, OpenMP) and print the path of the executable.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
source "$here/scripts/flags.sh"
fpm build --profile release --flag "$ANM_FFLAGS" >&2
fpm install --profile release --flag "$ANM_FFLAGS" --prefix "$here/build/install" >/dev/null
echo "$here/build/install/bin/anm"

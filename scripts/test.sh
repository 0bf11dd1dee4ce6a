#!/usr/bin/env bash
# Every test: the Fortran suites (fpm test) and the Python package (pytest), with the MPI build
# (scripts/build_mpi.sh; its models checked by post/tests/test_mpi_models.py under mpirun).
# Installs what is missing first. Exit code non-zero when any test fails.
set -uo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
bash "$here/scripts/setup.sh" || exit 1
anm="$(bash "$here/scripts/build.sh")" || exit 1
source "$here/scripts/flags.sh"

status=0
echo "== Fortran tests (fpm test)"
fpm test --profile release --flag "$ANM_FFLAGS" 2>&1 | grep -vE '^\[ *[0-9]+%\]|^Project is up to date|^Project compiled'
[ "${PIPESTATUS[0]}" -eq 0 ] || status=1

echo "== MPI build (scripts/build_mpi.sh)"
anm_mpi="$(bash "$here/scripts/build_mpi.sh" 2>"$here/build/build_mpi.log")" || {
    cat "$here/build/build_mpi.log"; echo "MPI build failed"; status=1; anm_mpi=""; }

echo "== Python tests (pytest post/tests, the MPI models included)"
ANM_BIN="$anm" ANM_MPI_BIN="$anm_mpi" python3 -m pytest -q "$here/post/tests"
rc=$?
# pytest exit code 5 means no tests were collected: that is a failure here
[ $rc -eq 0 ] || status=1

if [ $status -ne 0 ]; then
    echo "TESTS FAILED"
fi
exit $status

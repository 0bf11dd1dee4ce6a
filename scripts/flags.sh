# Compiler flags added to fpm's release profile (sourced by the other scripts).
# -ffpe-summary=none: no floating-point exception summary at exit (underflow in tiny Legendre
# values is expected and harmless).
export ANM_FFLAGS="${ANM_FFLAGS:--march=native -ffpe-summary=none}"

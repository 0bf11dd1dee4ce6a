"""NIST spherical-harmonic coefficient files (`n m Re(a_nm) Im(a_nm)` per line)."""
from __future__ import annotations

import numpy as np

from .errors import AnmPostError


def read_shape_coefficients(path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (n, m, a) arrays of a coefficient file, a complex.

    Raises AnmPostError naming the file and line for a missing file, a wrong field count, a
    non-numeric field, or coefficients out of the NIST order (n = 0.., m = n..-n).
    """
    from .textio import read_text
    lines = read_text(path, "a shape coefficient file").splitlines()
    n_list, m_list, a_list = [], [], []
    n_exp, m_exp = 0, 0
    for lineno, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        fields = line.split()
        if len(fields) != 4:
            raise AnmPostError(f"{path}:{lineno}: expected 4 fields 'n m Re Im', found {len(fields)}")
        try:
            n, m = int(fields[0]), int(fields[1])
            re, im = float(fields[2]), float(fields[3])
        except ValueError:
            raise AnmPostError(f"{path}:{lineno}: non-numeric field in '{line.strip()}'") from None
        if (n, m) != (n_exp, m_exp):
            raise AnmPostError(f"{path}:{lineno}: expected n={n_exp} m={m_exp}, found n={n} m={m}")
        n_list.append(n)
        m_list.append(m)
        a_list.append(complex(re, im))
        if m == -n:
            n_exp, m_exp = n + 1, n + 1
        else:
            m_exp = m - 1
    if not a_list:
        raise AnmPostError(f"{path}: empty shape file")
    if m_exp != n_exp:
        raise AnmPostError(f"{path}: file ends inside degree {n_exp} (truncated)")
    return np.array(n_list), np.array(m_list), np.array(a_list)

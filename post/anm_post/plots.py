"""Plots of the contact studies' CSV files (`anm study next|nbox SHAPE --csv OUT`; thesis Figs
2.14 and 2.15): columns next,v_box,v_box_certified (extent-box volume against N_ext) or
nbox,d_overlap (overlap distance against the number of boxes)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import AnmPostError

#: Known study layouts: first column -> (y columns, x label, y label, title).
STUDIES = {
    "next": (("v_box", "v_box_certified"), "N_ext", "extent-box volume (shape units^3)",
             "Extent box volume against N_ext (thesis Fig 2.14)"),
    "nbox": (("d_overlap",), "number of boxes N_box", "overlap distance d (shape units)",
             "Overlap distance against N_box (thesis Fig 2.15)"),
}


def read_study_csv(path: str | Path) -> tuple[str, dict[str, np.ndarray]]:
    """Read a study CSV; returns (kind, columns). Errors name the file and line."""
    from .textio import read_csv_rows
    path = Path(path)
    rows = read_csv_rows(path, "a study CSV of `anm study next|nbox`")
    if not rows:
        raise AnmPostError(f"{path}: empty file")
    header = [h.strip() for h in rows[0]]
    kind = header[0]
    if kind not in STUDIES or any(c not in header for c in STUDIES[kind][0]):
        raise AnmPostError(f"{path}:1: header must be 'next,v_box,v_box_certified' or 'nbox,d_overlap', "
                           f"got {','.join(header)!r}")
    data = []
    for i, row in enumerate(rows[1:], start=2):
        if not row:
            continue
        try:
            data.append([float(x) for x in row])
        except ValueError:
            raise AnmPostError(f"{path}:{i}: not a number in {','.join(row)!r}") from None
        if len(row) != len(header):
            raise AnmPostError(f"{path}:{i}: {len(row)} fields, header has {len(header)}")
    if not data:
        raise AnmPostError(f"{path}: no data rows")
    arr = np.array(data)
    return kind, {h: arr[:, j] for j, h in enumerate(header)}


def plot_study(csv_path: str | Path, png_path: str | Path) -> Path:
    """Plot a study CSV to PNG; returns the PNG path."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kind, cols = read_study_csv(csv_path)
    ycols, xlabel, ylabel, title = STUDIES[kind]
    fig, ax = plt.subplots(figsize=(6, 4))
    for c, marker in zip(ycols, "os"):
        ax.plot(cols[kind], cols[c], marker=marker, ms=4, label=c)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(f"{title}\n{Path(csv_path).name}", fontsize=9)
    if kind == "nbox":
        ax.set_xscale("log")
    ax.legend()
    fig.tight_layout()
    png_path = Path(png_path)
    from .output import save_figure
    try:
        save_figure(fig, png_path, "-o", dpi=150)
    finally:
        plt.close(fig)
    return png_path

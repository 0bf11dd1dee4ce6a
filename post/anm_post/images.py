"""PNG pictures of slices: particles coloured by sieve, shells by layer colour, matrix white,
with a legend naming the sieves (width ranges) and layers."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .model import Model
from .slicing import SliceResult

#: Particle colours per sieve (dark, distinguishable), cycled for many sieves.
SIEVE_COLOURS = ("#3b3b3b", "#7a4f2a", "#1f4e79", "#6b2e6b", "#2e6b3a", "#8c1c13")
#: Shell colours per layer (thesis Fig 3.3: green inner, blue outer), cycled.
LAYER_COLOURS = ("#4caf50", "#42a5f5", "#ffb300", "#ef5350", "#ab47bc", "#26c6da")
#: Matrix colour.
MATRIX_COLOUR = "#ffffff"


def label_rgb(result: SliceResult, n_sieves: int) -> np.ndarray:
    """RGB image (rows, cols, 3) in [0, 1] of a slice; row 0 is at the slice origin (v = 0)."""
    from matplotlib.colors import to_rgb

    img = np.empty(result.particle.shape + (3,))
    img[:] = to_rgb(MATRIX_COLOUR)
    for k in range(1, int(result.layer.max(initial=0)) + 1):
        img[result.layer == k] = to_rgb(LAYER_COLOURS[(k - 1) % len(LAYER_COLOURS)])
    for s in range(n_sieves):
        img[result.sieve == s] = to_rgb(SIEVE_COLOURS[s % len(SIEVE_COLOURS)])
    return img


def save_slice_png(result: SliceResult, model: Model, path: str | Path, nlayer: int = 0, title: str | None = None,
                   dpi: int = 150) -> Path:
    """Write the slice picture with axes in mm and a legend; returns the path."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    path = Path(path)
    p = result.plane
    nv, nu = result.particle.shape
    fig, ax = plt.subplots(figsize=(7.5, 6.0 * nv / max(nu, nv) + 0.8))
    ax.imshow(label_rgb(result, model.n_sieves), origin="lower", interpolation="nearest",
              extent=(0, nu * p.pixel, 0, nv * p.pixel))
    ax.set_xlabel("u (mm)")
    ax.set_ylabel("v (mm)")
    ax.set_title(title or f"{model.path.name}: slice, R_s = {p.pixel:g} mm/pixel")
    handles = []
    for s in range(model.n_sieves):
        lo, hi = model.sieves["min_width"][s], model.sieves["max_width"][s]
        handles.append(Patch(color=SIEVE_COLOURS[s % len(SIEVE_COLOURS)], label=f"sieve {s + 1}: {lo:g}-{hi:g} mm"))
    for k in range(1, nlayer + 1):
        handles.append(Patch(color=LAYER_COLOURS[(k - 1) % len(LAYER_COLOURS)], label=f"shell layer {k}"))
    handles.append(Patch(facecolor=MATRIX_COLOUR, edgecolor="0.6", label="matrix"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    fig.tight_layout()
    from .output import save_figure
    try:
        save_figure(fig, path, "--png", dpi=dpi, bbox_inches="tight")
    finally:
        plt.close(fig)
    return path

"""PNG pictures of slices: particles coloured by sieve, shells by layer colour, matrix white,
with a legend naming the sieves (width ranges) and layers."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .model import Model
from .slicing import SliceResult

#: Particle colours per sieve, RGB in [0, 1]: the VRML palette of `anm run` (src/cli/run.f90,
#: `palette`), so that a slice and the 3D view of one model agree; cycled for many sieves.
SIEVE_COLOURS = ((0.55, 0.45, 0.35), (0.75, 0.65, 0.45), (0.85, 0.80, 0.60),
                 (0.60, 0.60, 0.65), (0.45, 0.55, 0.45), (0.70, 0.50, 0.50))
#: Shell colours per layer when the model stores none (files without /shells/colour); otherwise
#: each layer takes its colour from the model, as the VRML shells do (&shells colour).
LAYER_COLOURS = ("#4caf50", "#42a5f5", "#ffb300", "#ef5350", "#ab47bc", "#26c6da")
#: Matrix colour.
MATRIX_COLOUR = "#ffffff"


def layer_colours(model: Model | None, nlayer: int) -> list:
    """Colour of each shell layer 1..nlayer: the model's /shells/colour where it has the layer (the
    VRML colours), else LAYER_COLOURS."""
    stored = None
    if model is not None and getattr(model, "shells", None):
        stored = np.asarray(model.shells.get("colour", np.zeros((0, 3))), float).reshape(-1, 3)
    out = []
    for k in range(nlayer):
        if stored is not None and k < len(stored):
            out.append(tuple(float(c) for c in stored[k]))
        else:
            out.append(LAYER_COLOURS[k % len(LAYER_COLOURS)])
    return out


def plane_name(plane) -> tuple[str, str, str]:
    """(title part, u label, v label) of a slice plane: `z = 10 mm` with axes `x (mm)`, `y (mm)` for
    a plane normal to an axis; otherwise the centre and unit normal of the plane, axes u, v."""
    u, v = np.asarray(plane.u, float), np.asarray(plane.v, float)
    n = np.cross(u, v)
    origin = np.asarray(plane.origin, float)
    for k, name in enumerate("xyz"):
        if abs(abs(n[k]) - 1.0) < 1e-9:
            iu, iv = int(np.argmax(np.abs(u))), int(np.argmax(np.abs(v)))
            if abs(abs(u[iu]) - 1) < 1e-9 and abs(abs(v[iv]) - 1) < 1e-9:
                return f"{name} = {origin[k]:g} mm", f"{'xyz'[iu]} (mm)", f"{'xyz'[iv]} (mm)"
            return f"{name} = {origin[k]:g} mm", "u (mm)", "v (mm)"
    c = origin + 0.5 * plane.size[0] * u + 0.5 * plane.size[1] * v
    n = n / np.linalg.norm(n)
    fmt = lambda x: ", ".join(f"{a:.3g}" for a in x)  # noqa: E731
    return f"through ({fmt(c)}) mm, normal ({fmt(n)})", "u (mm)", "v (mm)"


def label_rgb(result: SliceResult, n_sieves: int, model: Model | None = None) -> np.ndarray:
    """RGB image (rows, cols, 3) in [0, 1] of a slice; row 0 is at the slice origin (v = 0)."""
    from matplotlib.colors import to_rgb

    img = np.empty(result.particle.shape + (3,))
    img[:] = to_rgb(MATRIX_COLOUR)
    nlayer = int(result.layer.max(initial=0))
    for k, colour in enumerate(layer_colours(model, nlayer), start=1):
        img[result.layer == k] = to_rgb(colour)
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
    ax.imshow(label_rgb(result, model.n_sieves, model), origin="lower", interpolation="nearest",
              extent=(0, nu * p.pixel, 0, nv * p.pixel))
    where, ulabel, vlabel = plane_name(p)
    ax.set_xlabel(ulabel)
    ax.set_ylabel(vlabel)
    ax.set_title(title or f"{model.path.name}: slice {where}, R_s = {p.pixel:g} mm/pixel")
    handles = []
    for s in range(model.n_sieves):
        lo, hi = model.sieves["min_width"][s], model.sieves["max_width"][s]
        handles.append(Patch(color=SIEVE_COLOURS[s % len(SIEVE_COLOURS)], label=f"sieve {s + 1}: {lo:g}-{hi:g} mm"))
    for k, colour in enumerate(layer_colours(model, nlayer), start=1):
        handles.append(Patch(color=colour, label=f"shell layer {k}"))
    handles.append(Patch(facecolor=MATRIX_COLOUR, edgecolor="0.6", label="matrix"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    fig.tight_layout()
    from .output import save_figure
    try:
        save_figure(fig, path, "--png", dpi=dpi, bbox_inches="tight")
    finally:
        plt.close(fig)
    return path

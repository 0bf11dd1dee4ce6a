"""Read Anm model files (HDF5, contract version 1; docs/model-file.md) into numpy arrays."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import AnmPostError

#: Datasets every model file must hold.
REQUIRED = (
    "box/length", "shapes/coeffs", "shapes/nmax", "shapes/name", "particles/shape", "particles/center",
    "particles/rotation", "particles/scale", "particles/nmax", "particles/sieve",
    "sieves/min_width", "sieves/max_width", "sieves/target_fraction", "sieves/achieved_fraction", "sieves/count",
)


@dataclass
class Model:
    """A packed model. Lengths in mm; indices 0-based (as in the file).

    Attributes:
        path: the file read.
        box: box edges (3,).
        periodic: periodic boundaries.
        shape_coeffs: (nshape, ncoef, 2) Re, Im of a_nm in the NIST line order (n = 0.., m = n..-n).
        shape_nmax: (nshape,) highest degree stored per shape.
        shape_names: shape names.
        shape: (np,) shape index per particle.
        center: (np, 3) centres.
        rotation: (np, 3, 3) body->world rotations, world = R @ body.
        scale: (np,) mm per shape unit.
        nmax: (np,) expansion order used per particle.
        sieve: (np,) sieve index per particle.
        shell_thickness: (np, nshell) cumulative outer distance of each layer (mm), nshell may be 0.
        sieves: per-sieve arrays min_width, max_width, target_fraction, achieved_fraction, count.
        attrs: run attributes (seed, threads, ...).
        shells: the shell specification of the run (group /shells): dict with thickness (nlayer,)
            cumulative, in unit; unit "mm" or "fraction"; mode "exclude", "shell_overlap" or
            "overlap"; colour (nlayer, 3). None for files written before /shells existed.
    """

    path: Path
    box: np.ndarray
    periodic: bool
    shape_coeffs: np.ndarray
    shape_nmax: np.ndarray
    shape_names: list[str]
    shape: np.ndarray
    center: np.ndarray
    rotation: np.ndarray
    scale: np.ndarray
    nmax: np.ndarray
    sieve: np.ndarray
    shell_thickness: np.ndarray
    sieves: dict[str, np.ndarray]
    attrs: dict[str, object] = field(default_factory=dict)
    shells: dict | None = None

    @property
    def n_particles(self) -> int:
        """Number of particles."""
        return int(self.shape.size)

    @property
    def n_sieves(self) -> int:
        """Number of sieves."""
        return int(self.sieves["count"].size)

    @property
    def volume(self) -> float:
        """Box volume (mm^3)."""
        return float(np.prod(self.box))


def read_model(path: str | Path) -> Model:
    """Read a model file; raises AnmPostError naming the file and dataset on any problem."""
    import h5py

    path = Path(path)
    if not path.is_file():
        raise AnmPostError(f"{path}: model file not found")
    try:
        fh = h5py.File(path, "r")
    except OSError as exc:
        raise AnmPostError(f"{path}: cannot read as HDF5 ({exc})") from None
    with fh:
        if fh.attrs.get("format") not in ("anm-model", b"anm-model"):
            raise AnmPostError(f"{path}: not an Anm model file (root attribute 'format' is not 'anm-model')")
        for name in REQUIRED:
            if name not in fh:
                raise AnmPostError(f"{path}::/{name}: dataset missing")
        try:
            box = np.asarray(fh["box/length"][()], dtype=np.float64)
            periodic = bool(int(fh["box"].attrs.get("periodic", 1)))
            coeffs = np.asarray(fh["shapes/coeffs"][()], dtype=np.float64)
            snmax = np.asarray(fh["shapes/nmax"][()], dtype=np.int32)
            names = [n.decode() if isinstance(n, bytes) else str(n) for n in fh["shapes/name"][()]]
            p = fh["particles"]
            shape = np.asarray(p["shape"][()], dtype=np.int32)
            center = np.asarray(p["center"][()], dtype=np.float64).reshape(-1, 3)
            rotation = np.asarray(p["rotation"][()], dtype=np.float64).reshape(-1, 3, 3)
            scale = np.asarray(p["scale"][()], dtype=np.float64)
            nmax = np.asarray(p["nmax"][()], dtype=np.int32)
            sieve = np.asarray(p["sieve"][()], dtype=np.int32)
            if "shell_thickness" in p:
                shells = np.asarray(p["shell_thickness"][()], dtype=np.float64).reshape(shape.size, -1)
            else:
                shells = np.zeros((shape.size, 0))
            sieves = {k: np.asarray(fh[f"sieves/{k}"][()]) for k in
                      ("min_width", "max_width", "target_fraction", "achieved_fraction", "count")}
            attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in fh["run"].attrs.items()} \
                if "run" in fh else {}
            spec = _read_shells(fh) if "shells" in fh else None
        except (KeyError, ValueError, TypeError) as exc:
            raise AnmPostError(f"{path}: malformed model file ({exc})") from None
    npart = shape.size
    checks = {
        "box/length": box.shape == (3,) and bool(np.all(box > 0)),
        "shapes/coeffs": coeffs.ndim == 3 and coeffs.shape[2] == 2 and coeffs.shape[0] == snmax.size,
        "shapes/nmax": bool(np.all((snmax + 1) ** 2 <= coeffs.shape[1])) if coeffs.ndim == 3 else False,
        "particles/shape": bool(np.all((shape >= 0) & (shape < snmax.size))),
        "particles/center": center.shape == (npart, 3),
        "particles/rotation": rotation.shape == (npart, 3, 3),
        "particles/scale": scale.shape == (npart,) and bool(np.all(scale > 0)),
        "particles/nmax": nmax.shape == (npart,) and bool(np.all(nmax >= 0)),
        "particles/sieve": sieve.shape == (npart,),
    }
    if spec is not None and spec["nlayer"] > 0:
        checks["particles/shell_thickness"] = shells.shape == (npart, spec["nlayer"])
    for name, ok in checks.items():
        if not ok:
            raise AnmPostError(f"{path}::/{name}: wrong shape or values")
    return Model(path=path, box=box, periodic=periodic, shape_coeffs=coeffs, shape_nmax=snmax, shape_names=names,
                 shape=shape, center=center, rotation=rotation, scale=scale, nmax=nmax, sieve=sieve,
                 shell_thickness=shells, sieves=sieves, attrs=attrs, shells=spec)


def _text(value) -> str:
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray):
        return _text(value.reshape(-1)[0])
    return str(value)


def _read_shells(fh) -> dict:
    """The group /shells: attributes nlayer, unit, mode; datasets thickness, colour."""
    g = fh["shells"]
    nlayer = int(np.asarray(g.attrs["nlayer"]).reshape(-1)[0])
    unit = _text(g.attrs["unit"]).strip()
    mode = _text(g.attrs["mode"]).strip()
    if nlayer > 0:
        thickness = np.asarray(g["thickness"][()], dtype=np.float64).reshape(-1)
        colour = np.asarray(g["colour"][()], dtype=np.float64).reshape(-1, 3)
    else:
        thickness, colour = np.zeros(0), np.zeros((0, 3))
    if thickness.size != nlayer or colour.shape[0] != nlayer or unit not in ("mm", "fraction"):
        raise ValueError(f"/shells: nlayer {nlayer}, unit {unit!r}, {thickness.size} thicknesses, "
                         f"{colour.shape[0]} colours do not agree")
    return {"nlayer": nlayer, "thickness": thickness, "unit": unit, "mode": mode, "colour": colour}

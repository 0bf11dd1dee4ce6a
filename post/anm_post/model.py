"""Read Anm model files (HDF5, contract version 1; docs/model-file.md) into numpy arrays."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import AnmPostError
from .validate import FORMAT_VERSIONS, text, validate_model

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
    """Read a model file and validate it (anm_post.validate.validate_model); raises AnmPostError
    naming the file, the dataset and the first bad particle on any problem. Strings may be fixed-
    or variable-length (any HDF5 writer)."""
    import h5py

    path = Path(path)
    if not path.exists():
        raise AnmPostError(f"{path}: model file not found")
    if not path.is_file():
        raise AnmPostError(f"{path}: not a file (a model file written by `anm run` is expected)")
    try:
        fh = h5py.File(path, "r")
    except OSError as exc:
        reason = "not an HDF5 file" if "signature" in str(exc) else str(exc)
        raise AnmPostError(f"{path}: cannot read as HDF5 ({reason})") from None
    with fh:
        if "format" not in fh.attrs:
            raise AnmPostError(f"{path}: not an Anm model file (no root attribute 'format')")
        try:
            fmt = text(fh.attrs["format"], f"{path}: root attribute 'format'")
        except AnmPostError:
            raise AnmPostError(f"{path}: not an Anm model file (root attribute 'format' is not text)") from None
        if fmt != "anm-model":
            shown = fmt if len(fmt) <= 40 and fmt.isprintable() else "other text"
            raise AnmPostError(f"{path}: not an Anm model file (format = {shown!r}, expected 'anm-model')")
        version = fh.attrs.get("format_version")
        try:
            version = int(np.asarray(version).reshape(-1)[0]) if version is not None else None
        except (TypeError, ValueError, IndexError):
            version = -1
        if version is None:
            raise AnmPostError(f"{path}: root attribute 'format_version' missing")
        if version not in FORMAT_VERSIONS:
            raise AnmPostError(f"{path}: unknown format_version {version} (this anm-post reads "
                               f"{', '.join(map(str, FORMAT_VERSIONS))})")
        for name in REQUIRED:
            if name not in fh:
                raise AnmPostError(f"{path}::/{name}: dataset missing")
        name = "box/length"
        try:
            box = np.asarray(fh[name][()], dtype=np.float64)
            periodic = bool(int(np.asarray(fh["box"].attrs.get("periodic", 1)).reshape(-1)[0]))
            name = "shapes/coeffs"
            coeffs = np.asarray(fh[name][()], dtype=np.float64)
            name = "shapes/nmax"
            snmax = np.asarray(fh[name][()], dtype=np.int32)
            name = "shapes/name"
            names = [text(n, f"{path}::/shapes/name[{k}]") for k, n in enumerate(np.asarray(fh[name][()]).reshape(-1))]
            p = fh["particles"]
            name = "particles/shape"
            shape = np.asarray(p["shape"][()], dtype=np.int32)
            name = "particles/center"
            center = np.asarray(p["center"][()], dtype=np.float64).reshape(-1, 3)
            name = "particles/rotation"
            rotation = np.asarray(p["rotation"][()], dtype=np.float64).reshape(-1, 3, 3)
            name = "particles/scale"
            scale = np.asarray(p["scale"][()], dtype=np.float64)
            name = "particles/nmax"
            nmax = np.asarray(p["nmax"][()], dtype=np.int32)
            name = "particles/sieve"
            sieve = np.asarray(p["sieve"][()], dtype=np.int32)
            name = "particles/shell_thickness"
            if "shell_thickness" in p:
                shells = np.asarray(p["shell_thickness"][()], dtype=np.float64).reshape(shape.size, -1)
            else:
                shells = np.zeros((shape.size, 0))
            sieves = {}
            for k in ("min_width", "max_width", "target_fraction", "achieved_fraction", "count"):
                name = f"sieves/{k}"
                sieves[k] = np.asarray(fh[name][()])
            name = "run"
            attrs = {}
            if "run" in fh:
                for k, v in fh["run"].attrs.items():
                    attrs[k] = text(v, f"{path}::/run attribute {k!r}") \
                        if isinstance(v, (str, bytes, np.bytes_)) else v
                for k in ("namelist", "resolved_namelist"):
                    if k in fh["run"] and isinstance(fh["run"][k], h5py.Dataset):
                        attrs[k] = text(fh["run"][k][()], f"{path}::/run/{k}")
            name = "shells"
            spec = _read_shells(fh, path) if "shells" in fh else None
        except AnmPostError:
            raise
        except (KeyError, ValueError, TypeError, OSError) as exc:
            raise AnmPostError(f"{path}::/{name}: malformed ({exc})") from None
    attrs["format_version"] = version
    if "attempts" in attrs:   # int64 since the self-describing attributes; float64 before
        attrs["attempts"] = int(np.asarray(attrs["attempts"]).reshape(-1)[0])
    model = Model(path=path, box=box, periodic=periodic, shape_coeffs=coeffs, shape_nmax=snmax, shape_names=names,
                  shape=shape, center=center, rotation=rotation, scale=scale, nmax=nmax, sieve=sieve,
                  shell_thickness=shells, sieves=sieves, attrs=attrs, shells=spec)
    validate_model(model)
    if spec is not None and spec["nlayer"] > 0 and shells.shape != (shape.size, spec["nlayer"]):
        raise AnmPostError(f"{path}::/particles/shell_thickness: shape {shells.shape} does not match "
                           f"/shells nlayer = {spec['nlayer']}")
    return model


def _read_shells(fh, path) -> dict:
    """The group /shells: attributes nlayer, unit, mode; datasets thickness, colour."""
    g = fh["shells"]
    nlayer = int(np.asarray(g.attrs["nlayer"]).reshape(-1)[0])
    unit = text(g.attrs["unit"], f"{path}::/shells attribute 'unit'").strip()
    mode = text(g.attrs["mode"], f"{path}::/shells attribute 'mode'").strip()
    if nlayer > 0:
        thickness = np.asarray(g["thickness"][()], dtype=np.float64).reshape(-1)
        colour = np.asarray(g["colour"][()], dtype=np.float64).reshape(-1, 3)
    else:
        thickness, colour = np.zeros(0), np.zeros((0, 3))
    if thickness.size != nlayer or colour.shape[0] != nlayer or unit not in ("mm", "fraction"):
        raise ValueError(f"/shells: nlayer {nlayer}, unit {unit!r}, {thickness.size} thicknesses, "
                         f"{colour.shape[0]} colours do not agree")
    return {"nlayer": nlayer, "thickness": thickness, "unit": unit, "mode": mode, "colour": colour}

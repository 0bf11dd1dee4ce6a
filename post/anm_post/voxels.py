"""Labelled 3D voxel images of a model (issue 17, item 3), for FFT homogenisation, finite-element
and hydration codes (NIST VCCTL among them).

The image is a stack of z-normal slices from the Fortran slicing kernel (anm_slicing_kernel via
anm_post.kernels.slice_labels; OpenMP inside the kernel), `chunk` slices per call: voxel (i, j, k)
has its centre at ((i + 1/2) h, (j + 1/2) h, (k + 1/2) h), h the voxel size, and takes the label of
that point (periodic images included). nx = round(Lx / h) etc.; with a box edge that is not a
multiple of h the image covers n h instead of L along that axis.

Phase codes: 0 matrix, 1..S the particles of sieve 0..S-1, S + k shell layer k (1-based; shells
grown as for slices, --shells). particle_id: 0-based particle id, -1 for matrix and shells.

    img = voxelize(model, 0.05)                      # VoxelImage: labels (nx, ny, nz), particle_id
    save_h5(img, "m.h5"); save_raw(img, "m.raw", "m.raw.txt"); save_vcctl(img, "m.img")
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from .progress import stderr_progress  # noqa: F401  (re-exported: voxels.stderr_progress)

from .errors import AnmPostError
from .model import Model

#: Bytes per voxel kept (labels uint8 + particle_id int32) and per voxel of a chunk slice in flight.
BYTES_PER_VOXEL = 5
BYTES_PER_CHUNK_PIXEL = 60


@dataclass
class VoxelImage:
    """labels (nx, ny, nz) uint8/uint16 phase codes; particle_id (nx, ny, nz) int32; voxel size
    (mm); code names (index = code)."""

    labels: np.ndarray
    particle_id: np.ndarray
    voxel: float
    codes: list[str]
    box: np.ndarray
    seconds: float = 0.0

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.labels.shape)

    def fractions(self) -> np.ndarray:
        """Volume fraction of every code."""
        return np.bincount(self.labels.reshape(-1), minlength=len(self.codes)) / self.labels.size


def code_names(model: Model, nlayer: int) -> list[str]:
    """Names of the phase codes: matrix, sieve s (min-max width), shell layer k."""
    lo, hi = model.sieves["min_width"], model.sieves["max_width"]
    return (["matrix"] + [f"sieve {s} ({lo[s]:g}-{hi[s]:g} mm)" for s in range(model.n_sieves)]
            + [f"shell layer {k}" for k in range(1, nlayer + 1)])


def grid_shape(model: Model, voxel: float) -> tuple[int, int, int]:
    """Voxels along x, y, z: round(L / h), at least 1."""
    if not (np.isfinite(voxel) and voxel > 0):
        raise AnmPostError(f"--voxel: must be a positive size in mm, got {voxel}")
    return tuple(max(1, int(round(float(L) / voxel))) for L in model.box)


def memory_bytes(shape: tuple[int, int, int], chunk: int) -> int:
    """Estimated peak memory of voxelize (bytes)."""
    nx, ny, nz = shape
    return int(nx * ny * nz * BYTES_PER_VOXEL + nx * ny * min(chunk, nz) * BYTES_PER_CHUNK_PIXEL)




def default_chunk(shape: tuple[int, int, int]) -> int:
    """Slices per kernel call: about 5 million pixels (each call has a fixed cost, about 0.5 s for
    M_sand's 171,081 particles, so few large calls), 4..64 slices."""
    return int(max(4, min(64, 5_000_000 // max(1, shape[0] * shape[1]))))


def voxelize(model: Model, voxel: float, shells=None, chunk: int | None = None,
             progress: Callable[[int, int], None] | None = None) -> VoxelImage:
    """Label every voxel of the box (see the module doc); shells: a slicing.ShellSpec or None."""
    from .slicing import Plane, Slicer

    nx, ny, nz = grid_shape(model, voxel)
    chunk = default_chunk((nx, ny, nz)) if chunk is None else int(chunk)
    nlayer = 0 if shells is None else len(shells.thickness)
    codes = code_names(model, nlayer)
    dtype = np.uint8 if len(codes) <= 256 else np.uint16
    slicer = Slicer(model, shells)
    labels = np.zeros((nx, ny, nz), dtype)
    pid = np.full((nx, ny, nz), -1, np.int32)
    size = (nx * voxel, ny * voxel)
    planes = [Plane((0.0, 0.0, (k + 0.5) * voxel), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), size, float(voxel))
              for k in range(nz)]
    sieve_code = (model.sieve + 1).astype(dtype)
    start = time.perf_counter()
    for k0 in range(0, nz, chunk):
        for dk, res in enumerate(slicer.slice_many(planes[k0:k0 + chunk])):
            p = res.particle.T  # (nu, nv) = (nx, ny)
            inside = p >= 0
            lab = np.zeros((nx, ny), dtype)
            lab[inside] = sieve_code[p[inside]]
            if nlayer:
                layer = res.layer.T
                lab[(~inside) & (layer > 0)] = (model.n_sieves + layer[(~inside) & (layer > 0)]).astype(dtype)
            labels[:, :, k0 + dk] = lab
            pid[:, :, k0 + dk] = p
        if progress:
            progress(min(nz, k0 + chunk), nz)
    return VoxelImage(labels, pid, float(voxel), codes, np.asarray(model.box, float),
                      time.perf_counter() - start)


# -- writers (each writes to the path it is given: the caller's temporary name) ------------------

def save_h5(img: VoxelImage, path: str | Path, model_path: str = "") -> None:
    """HDF5: /labels and /particle_id (nx, ny, nz), attributes voxel_size (mm), codes (names, index =
    code), code_values, box (mm), origin (mm), format = anm-voxels."""
    import h5py

    try:
        with h5py.File(path, "w") as fh:
            fh.attrs["format"] = "anm-voxels"
            fh.attrs["voxel_size"] = img.voxel
            fh.attrs["voxel_size_unit"] = "mm"
            fh.attrs["codes"] = np.array(img.codes, dtype=h5py.string_dtype())
            fh.attrs["code_values"] = np.arange(len(img.codes), dtype=np.int32)
            fh.attrs["box"] = img.box
            fh.attrs["origin"] = np.zeros(3)
            fh.attrs["model"] = str(model_path)
            chunks = (img.shape[0], img.shape[1], 1)
            d = fh.create_dataset("labels", data=img.labels, compression="gzip", compression_opts=1, chunks=chunks)
            d.attrs["description"] = "phase code of each voxel (x, y, z index order); see the root attribute codes"
            d = fh.create_dataset("particle_id", data=img.particle_id, compression="gzip", compression_opts=1,
                                  chunks=chunks)
            d.attrs["description"] = "0-based particle id of each voxel, -1 for matrix and shells"
    except (RuntimeError, ValueError) as exc:
        raise OSError(str(exc)) from None


def raw_header(img: VoxelImage, raw_name: str) -> str:
    """The text header of a .raw stack."""
    nx, ny, nz = img.shape
    lines = ["# Anm voxel image (anm-post voxels): raw bytes, no header in the data file",
             f"file: {raw_name}",
             f"dims: {nx} {ny} {nz}",
             "order: x fastest, then y, then z (Fortran order of labels(nx, ny, nz))",
             f"dtype: {np.dtype(img.labels.dtype).name}",
             "byte_order: little",
             f"voxel_size_mm: {img.voxel:.9g}",
             "origin_mm: 0 0 0",
             "codes:"]
    lines += [f"  {c}: {name}" for c, name in enumerate(img.codes)]
    return "\n".join(lines) + "\n"


def save_raw(img: VoxelImage, path: str | Path) -> None:
    """The labels as raw bytes, x fastest (little-endian for uint16)."""
    with open(path, "wb") as fh:
        for k in range(img.shape[2]):
            fh.write(np.ascontiguousarray(img.labels[:, :, k].T).astype(img.labels.dtype.newbyteorder("<")).tobytes())
        fh.flush()


def vcctl_header(img: VoxelImage) -> str:
    """VCCTL's image header (Version 7.0, sizes, resolution in micrometres per voxel)."""
    nx, ny, nz = img.shape
    return (f"Version: 7.0\nX_Size: {nx}\nY_Size: {ny}\nZ_Size: {nz}\n"
            f"Image_Resolution: {img.voxel * 1000.0:4.2f}\n")


def save_vcctl(img: VoxelImage, path: str | Path) -> None:
    """VCCTL's ASCII image: the header, then one phase code per line, x fastest, then y, then z."""
    with open(path, "wb") as fh:
        fh.write(vcctl_header(img).encode("ascii"))
        small = int(img.labels.max(initial=0)) < 10
        for k in range(img.shape[2]):
            s = np.ascontiguousarray(img.labels[:, :, k].T).reshape(-1)
            if small:
                buf = np.empty(2 * s.size, np.uint8)
                buf[0::2] = s + ord("0")
                buf[1::2] = ord("\n")
                fh.write(buf.tobytes())
            else:
                fh.write(("\n".join(map(str, s.tolist())) + "\n").encode("ascii"))
        fh.flush()


def read_vcctl(path: str | Path) -> tuple[dict, np.ndarray]:
    """Read a VCCTL ASCII image back: (header fields, labels (nx, ny, nz))."""
    with open(path) as fh:
        head = {}
        for _ in range(5):
            key, _, value = fh.readline().partition(":")
            head[key.strip()] = value.strip()
        data = np.loadtxt(fh, dtype=np.int64)
    nx, ny, nz = int(head["X_Size"]), int(head["Y_Size"]), int(head["Z_Size"])
    return head, data.reshape(nz, ny, nx).transpose(2, 1, 0)

"""Memory checked up front (issue 12, item 5, the anm-post side): a request is estimated before
any array is allocated and refused, with the estimate and the option to change, when it exceeds
the memory this process can have (the least of MemAvailable, the cgroup's free memory and the
address-space limit)."""
from __future__ import annotations

import os
import resource
from pathlib import Path

from .errors import AnmPostError

#: Bytes per pixel while a chunk of slices is labelled: the kernel's three int32 label arrays and
#: their C-order copies (24), the int64 particle, owner and sieve ids and the int32 layer (28),
#: temporaries of the conversion (16).
BYTES_PER_PIXEL_WORK = 68
#: Bytes per pixel of a slice kept after labelling (particle, owner, sieve int64; layer int32).
BYTES_PER_PIXEL_KEPT = 28
#: Bytes per pixel of a PNG picture (float RGB image, masks, matplotlib's resampled copy).
BYTES_PER_PIXEL_PNG = 48


def _read_int(path: str) -> int | None:
    try:
        text = Path(path).read_text().strip()
    except OSError:
        return None
    return None if text in ("", "max") else int(text) if text.isdigit() else None


def available_memory() -> int | None:
    """Bytes this process can still allocate (None when nothing says)."""
    limits = []
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                limits.append(int(line.split()[1]) * 1024)
    except (OSError, ValueError, IndexError):
        pass
    high = _read_int("/sys/fs/cgroup/memory.max")
    if high is not None:
        used = _read_int("/sys/fs/cgroup/memory.current") or 0
        limits.append(max(0, high - used))
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY:
        limits.append(soft)
    override = os.environ.get("ANM_MEMORY_LIMIT")  # tests: pretend a smaller machine
    if override and override.isdigit():
        limits.append(int(override))
    return min(limits) if limits else None


def human_bytes(n: float) -> str:
    """1.2 GB style (decimal units)."""
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if n < 1000 or unit == "PB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n:.1f} PB"  # pragma: no cover


def check_memory(need: float, what: str, change: str) -> None:
    """Refuse a request of `need` bytes (described by `what`) above the memory available; the
    message says which option to change."""
    have = available_memory()
    if have is not None and need > have:
        raise AnmPostError(f"{change}: {what} needs about {human_bytes(need)} of memory, more than the "
                           f"{human_bytes(have)} available; {_advice(change)}")


def _advice(change: str) -> str:
    if "--pixel" in change:
        return "use a larger --pixel (fewer pixels per slice)"
    if "--density" in change:
        return "use a smaller --density or a larger --pixel"
    return f"change {change}"


def slice_memory(pixels: int, kept_slices: int, chunk: int, png: bool, labels: bool) -> int:
    """Estimated peak bytes of labelling slices of `pixels` pixels each: `chunk` slices labelled
    at once, `kept_slices` slices kept (a stack keeps all), doubled when they are stacked for a
    label file, plus one PNG picture."""
    kept = kept_slices * BYTES_PER_PIXEL_KEPT * (2 if labels else 1)
    return int(pixels * (chunk * BYTES_PER_PIXEL_WORK + kept + (BYTES_PER_PIXEL_PNG if png else 0)))

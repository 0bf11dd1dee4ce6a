"""Data safety for every file anm_post writes (issue 12, item 6): CSV, Markdown, PNG, NPZ, HDF5.

A file is written to a unique temporary name in its target folder (``.NAME.anm-tmp-XXXX.SUFFIX``),
flushed, fsync'ed and closed with every error checked, then renamed over the final name
(os.replace, atomic on POSIX). On any error the temporary file is removed, the earlier file under
the final name is left as it was, and an AnmPostError names the file and the option.

The command line also stages the outputs of one command (OutputSet): each is written to its own
temporary name, and only when all of them are complete are they renamed, so a failed command
leaves every earlier output as it was (no mix of old and new files from one command, except if a
rename itself fails, which the message then says).

    with atomic_open("g.csv", "--csv") as fh: fh.write(text)
    save_figure(fig, "g.png", "--png", dpi=150)
    with atomic_path("s.h5", "--labels") as tmp: h5py.File(tmp, "w") ...
"""
from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from .errors import AnmPostError

#: Marker in the names of temporary files (tests look for it).
TMP_MARK = ".anm-tmp-"


def _error(path: Path, option: str, exc: OSError) -> AnmPostError:
    what = f" ({option})" if option else ""
    # h5py's errors carry a long text (with the temporary name) besides errno: the errno says it
    reason = os.strerror(exc.errno) if exc.errno else (exc.strerror or str(exc))
    return AnmPostError(f"{path}: cannot write{what}: {reason}; the earlier file, if any, is unchanged")


def _temp_name(path: Path) -> Path:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}{TMP_MARK}", suffix=path.suffix or ".tmp",
                               dir=path.parent)
    os.close(fd)
    return Path(tmp)


def _remove(path: Path) -> None:
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass
    except OSError:  # pragma: no cover - nothing more can be done
        pass


def _file_mode() -> int:
    """Permissions of a new file under the current umask (mkstemp makes 0600)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # pragma: no cover - not every system opens folders
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)


def check_writable(path: str | Path, option: str = "") -> Path:
    """Refuse up front (before any work) an output that cannot be written: a folder that does not
    exist or cannot take a new file (tried by creating and removing a temporary file, so read-only
    mounts are seen even by root), or a final name that is a folder."""
    path = Path(path)
    what = f" ({option})" if option else ""
    if path.is_dir():
        raise AnmPostError(f"{path}: is a folder, not a file name{what}")
    folder = path.parent
    if not folder.is_dir():
        raise AnmPostError(f"{path}: folder {folder} does not exist{what}")
    try:
        _remove(_temp_name(path))
    except OSError as exc:
        raise AnmPostError(f"{path}: cannot write in folder {folder}{what}: {exc.strerror or exc}") from None
    return path


@contextmanager
def atomic_path(path: str | Path, option: str = "") -> Iterator[Path]:
    """Yield a temporary path beside `path` (same suffix) for a writer that takes a file name
    (h5py); when the block ends without error the file is fsync'ed and renamed to `path`. On
    error the temporary file is removed and the earlier `path` kept."""
    path = Path(path)
    try:
        tmp = _temp_name(path)
    except OSError as exc:
        raise _error(path, option, exc) from None
    try:
        yield tmp
        _fsync(tmp)
        os.chmod(tmp, _file_mode())
        os.replace(tmp, path)
    except OSError as exc:
        _remove(tmp)
        raise _error(path, option, exc) from None
    except BaseException:
        _remove(tmp)
        raise
    _fsync_dir(path.parent)


@contextmanager
def atomic_open(path: str | Path, option: str = "", mode: str = "w", **kwargs) -> Iterator:
    """Open a temporary file beside `path` (mode "w" text, UTF-8, or "wb"); on a clean exit it is
    flushed, fsync'ed, closed (each checked) and renamed to `path`."""
    if "b" not in mode:
        kwargs.setdefault("encoding", "utf-8")
    with atomic_path(path, option) as tmp:
        fh = open(tmp, mode, **kwargs)
        try:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        finally:
            fh.close()


def write_text(path: str | Path, text: str, option: str = "") -> Path:
    """Write `text` to `path` atomically."""
    with atomic_open(path, option, "w", newline="") as fh:
        fh.write(text)
    return Path(path)


def figure_format(path: str | Path, option: str = "") -> str:
    """The picture format of a file name (its suffix; png without one), refused up front when
    matplotlib cannot write it."""
    from matplotlib.backend_bases import FigureCanvasBase

    path = Path(path)
    fmt = path.suffix[1:].lower() or "png"
    supported = FigureCanvasBase.get_supported_filetypes()
    if fmt not in supported:
        what = f" ({option})" if option else ""
        raise AnmPostError(f"{path}: unknown picture format '.{fmt}'{what}; use one of "
                           f"{', '.join('.' + k for k in sorted(supported))}")
    return fmt


def save_figure(fig, path: str | Path, option: str = "", **kwargs) -> Path:
    """fig.savefig to `path` atomically, in the format of its suffix (png without one)."""
    path = Path(path)
    fmt = figure_format(path, option)
    with atomic_open(path, option, "wb") as fh:
        fig.savefig(fh, format=fmt, **kwargs)
    return path


class OutputSet:
    """The output files of one command, written as one set: `add` checks each final name up front,
    `stage` gives the temporary name a writer writes to, and leaving the `with` block without
    error renames them all; with an error all temporary files are removed and every earlier
    file kept."""

    def __init__(self) -> None:
        self._staged: list[tuple[Path, Path, str]] = []

    def __enter__(self) -> "OutputSet":
        return self

    def add(self, path: str | Path | None, option: str) -> Path | None:
        """Check an output up front (None: option not given)."""
        return None if path is None else check_writable(path, option)

    def stage(self, path: str | Path, option: str) -> Path:
        """A temporary name beside `path` (same suffix) to write instead of `path`."""
        path = Path(path)
        try:
            tmp = _temp_name(path)
        except OSError as exc:
            raise _error(path, option, exc) from None
        self._staged.append((tmp, path, option))
        return tmp

    def discard(self) -> None:
        """Remove every staged temporary file."""
        for tmp, _, _ in self._staged:
            _remove(tmp)
        self._staged.clear()

    def commit(self) -> None:
        """Rename every staged file to its final name."""
        done: list[Path] = []
        for tmp, path, option in self._staged:
            try:
                if tmp.stat().st_size == 0:
                    raise AnmPostError(f"{path}: nothing was written ({option}); the earlier file, if any, "
                                       "is unchanged")
                os.chmod(tmp, _file_mode())
                os.replace(tmp, path)
            except OSError as exc:
                self.discard()
                note = f" (already written: {', '.join(map(str, done))})" if done else ""
                raise AnmPostError(f"{_error(path, option, exc)}{note}") from None
            except AnmPostError:
                self.discard()
                raise
            done.append(path)
        for folder in {p.parent for p in done}:
            _fsync_dir(folder)
        self._staged.clear()

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.discard()


#: Suffixes of label files (save_arrays).
ARRAY_SUFFIXES = (".npz", ".h5", ".hdf5")


def check_array_suffix(path: str | Path, option: str = "") -> None:
    """Refuse up front a label file name save_arrays cannot write."""
    path = Path(path)
    if path.suffix not in ARRAY_SUFFIXES:
        what = f" ({option})" if option else ""
        raise AnmPostError(f"{path}: label file must end in .npz, .h5 or .hdf5{what}")


def save_arrays(path: str | Path, data: dict, meta: dict, kind: str, option: str = "") -> Path:
    """Write arrays `data` and small arrays or numbers `meta` atomically: .npz (all as arrays) or
    .h5/.hdf5 (data as gzip datasets, meta as root attributes, root attribute format = kind)."""
    import numpy as np

    path = Path(path)
    check_array_suffix(path, option)
    if path.suffix == ".npz":
        with atomic_open(path, option, "wb") as fh:
            np.savez_compressed(fh, **data, **meta)
        return path
    import h5py
    with atomic_path(path, option) as tmp:
        try:
            with h5py.File(tmp, "w") as fh:
                fh.attrs["format"] = kind
                for k, val in data.items():
                    fh.create_dataset(k, data=val, compression="gzip")
                for k, val in meta.items():
                    fh.attrs[k] = val
        except (RuntimeError, ValueError) as exc:  # h5py reports some write errors so
            raise OSError(str(exc)) from None
    return path

"""Reading text input files (study CSVs, run summaries, shape files) so that any bytes give a
message naming the file and line, never a UnicodeDecodeError or csv.Error traceback."""
from __future__ import annotations

import csv
import io
from pathlib import Path

from .errors import AnmPostError


def read_text(path: str | Path, what: str) -> str:
    """The whole file as text. UTF-8 (ASCII) is expected: other bytes, NUL bytes (a binary file)
    or a folder give an AnmPostError naming the file, the line and what was expected; the bad
    bytes themselves are not printed."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except IsADirectoryError:
        raise AnmPostError(f"{path}: is a folder, not {what}") from None
    except OSError as exc:
        raise AnmPostError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if b"\0" in raw:
        line = raw[:raw.index(b"\0")].count(b"\n") + 1
        raise AnmPostError(f"{path}:{line}: binary data (NUL byte), not {what}")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise AnmPostError(f"{path}:{line}: not UTF-8 text (byte {exc.start}), not {what}") from None


def read_csv_rows(path: str | Path, what: str) -> list[list[str]]:
    """Rows of a CSV file (read_text, then the csv module; its errors name the line)."""
    reader = csv.reader(io.StringIO(read_text(path, what), newline=""))
    try:
        return list(reader)
    except csv.Error as exc:
        raise AnmPostError(f"{path}:{reader.line_num}: not a valid CSV ({exc}), not {what}") from None

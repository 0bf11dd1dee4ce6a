"""Geometry tables: the output of `anm shape` and NIST's *-geom*.dat tables share column names."""
from __future__ import annotations

from dataclasses import dataclass
import io

import numpy as np

from .errors import AnmPostError


@dataclass
class GeometryTable:
    """A geometry table: particle names and one float array per numeric column."""

    path: str
    names: list[str]
    columns: dict[str, np.ndarray]

    def __len__(self) -> int:
        return len(self.names)

    def column(self, name: str) -> np.ndarray:
        """Values of column `name`; AnmPostError naming the table if it is absent."""
        try:
            return self.columns[name]
        except KeyError:
            raise AnmPostError(f"{self.path}: no column '{name}' (columns: {', '.join(self.columns)})") from None

    def row(self, name: str) -> dict[str, float]:
        """All numeric values of the particle `name`."""
        try:
            i = self.names.index(name)
        except ValueError:
            raise AnmPostError(f"{self.path}: no particle '{name}'") from None
        return {k: float(v[i]) for k, v in self.columns.items()}

    def summary(self) -> dict[str, tuple[float, float]]:
        """Mean and standard deviation of L/T and W/T, like NIST's .sst files."""
        out = {}
        for key in ("L/T", "W/T"):
            v = self.column(key)
            out[key] = (float(np.mean(v)), float(np.std(v, ddof=1)) if len(v) > 1 else 0.0)
        return out

    def to_csv(self) -> str:
        """The table as CSV text (header row, then one row per particle)."""
        buf = io.StringIO()
        buf.write(",".join(["Name", *self.columns]) + "\n")
        for i, name in enumerate(self.names):
            buf.write(",".join([name, *(f"{v[i]:.10g}" for v in self.columns.values())]) + "\n")
        return buf.getvalue()

    def to_markdown(self, columns: list[str] | None = None) -> str:
        """The table (or chosen columns) as a Markdown table."""
        cols = columns or list(self.columns)
        for c in cols:
            self.column(c)
        lines = ["| Name | " + " | ".join(cols) + " |", "|---|" + "---|" * len(cols)]
        for i, name in enumerate(self.names):
            lines.append(f"| {name} | " + " | ".join(f"{self.columns[c][i]:.5g}" for c in cols) + " |")
        return "\n".join(lines) + "\n"


def read_geometry_table(path: str) -> GeometryTable:
    """Read a whitespace-separated geometry table with a header line naming the columns.

    Accepts the output of `anm shape` and NIST's tables (the stray 0xFF bytes of
    MA107-6-fine-geom.dat are removed). Raises AnmPostError naming the file and line for a
    missing file, an empty table, a wrong field count or a non-numeric value.
    """
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except OSError as exc:
        raise AnmPostError(f"{path}: cannot read geometry table ({exc.strerror})") from None
    text = raw.replace(b"\xff", b"").decode("ascii", errors="replace")
    lines = [ln for ln in text.splitlines()]
    if not lines or not lines[0].strip():
        raise AnmPostError(f"{path}:1: empty geometry table (no header line)")
    header = lines[0].split()
    if header[0] != "Name":
        raise AnmPostError(f"{path}:1: header must start with 'Name', found '{header[0]}'")
    ncol = len(header)
    names: list[str] = []
    rows: list[list[float]] = []
    for lineno, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        fields = line.split()
        if len(fields) != ncol:
            raise AnmPostError(f"{path}:{lineno}: expected {ncol} fields, found {len(fields)}")
        try:
            rows.append([float(x) for x in fields[1:]])
        except ValueError:
            bad = next(x for x in fields[1:] if not _is_float(x))
            raise AnmPostError(f"{path}:{lineno}: non-numeric value '{bad}'") from None
        names.append(fields[0])
    if not rows:
        raise AnmPostError(f"{path}: geometry table has a header but no rows")
    data = np.array(rows, dtype=np.float64)
    return GeometryTable(path=path, names=names, columns={h: data[:, i] for i, h in enumerate(header[1:])})


def _is_float(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


#: Columns of the PSD table of a model.
PSD_COLUMNS = ("sieve", "min_width_mm", "max_width_mm", "target_fraction", "achieved_fraction", "count")


def psd_table(model) -> list[dict[str, float]]:
    """The PSD table of a model (one row per sieve, then a total row with sieve = 'total')."""
    s = model.sieves
    rows = []
    for k in range(model.n_sieves):
        rows.append(dict(sieve=k + 1, min_width_mm=float(s["min_width"][k]), max_width_mm=float(s["max_width"][k]),
                         target_fraction=float(s["target_fraction"][k]),
                         achieved_fraction=float(s["achieved_fraction"][k]), count=int(s["count"][k])))
    rows.append(dict(sieve="total", min_width_mm=float(np.min(s["min_width"])),
                     max_width_mm=float(np.max(s["max_width"])), target_fraction=float(np.sum(s["target_fraction"])),
                     achieved_fraction=float(np.sum(s["achieved_fraction"])), count=int(np.sum(s["count"]))))
    return rows


def format_psd(rows: list[dict[str, float]], fmt: str = "text") -> str:
    """Format PSD rows as 'text' (aligned columns), 'csv' or 'markdown'."""
    def cell(v) -> str:
        return f"{v:.4f}" if isinstance(v, float) else str(v)

    body = [[cell(r[c]) for c in PSD_COLUMNS] for r in rows]
    if fmt == "csv":
        return "\n".join([",".join(PSD_COLUMNS)] + [",".join(b) for b in body]) + "\n"
    if fmt == "markdown":
        lines = ["| " + " | ".join(PSD_COLUMNS) + " |", "|" + "---|" * len(PSD_COLUMNS)]
        return "\n".join(lines + ["| " + " | ".join(b) + " |" for b in body]) + "\n"
    if fmt != "text":
        raise AnmPostError(f"unknown table format {fmt!r} (text, csv, markdown)")
    widths = [max(len(c), *(len(b[j]) for b in body)) for j, c in enumerate(PSD_COLUMNS)]
    out = ["  ".join(c.rjust(w) for c, w in zip(PSD_COLUMNS, widths))]
    out += ["  ".join(x.rjust(w) for x, w in zip(b, widths)) for b in body]
    return "\n".join(out) + "\n"

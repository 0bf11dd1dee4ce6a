"""Parameter sweeps over `anm run` (thesis Tables 2.1-2.3, Figs 2.16, 2.17): collect the
model-summary.csv files of several runs into one table and plot packing density, particle counts
and shell volume fraction against the swept parameter.

Library API:
    runs = [(0.0, "out/studies/shells/t0/model-summary.csv"), (0.002, ...)]
    rows = collect(runs)                    # list of SweepRow
    text = sweep_markdown(rows, "shell thickness (% of L)", scale=100)
    plot_sweep(rows, "shell thickness (% of L)", "fig.png", scale=100)
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from .errors import AnmPostError


@dataclass
class SweepRow:
    """One run: the swept value, achieved fraction and count per sieve, totals, shell fraction."""

    value: float
    achieved: np.ndarray
    count: np.ndarray
    total: float
    total_count: int
    shell_fraction: float


def read_summary(path: str | Path) -> tuple[np.ndarray, np.ndarray, float, int, float]:
    """(achieved per sieve, count per sieve, total achieved, total count, total shell fraction) of
    a model-summary.csv written by `anm run`."""
    from .textio import read_csv_rows
    path = Path(path)
    table = read_csv_rows(path, "a model-summary.csv of `anm run`")
    if not table:
        raise AnmPostError(f"{path}: empty file, not a model summary of `anm run`")
    header = table[0]
    rows = [dict(zip(header, r)) for r in table[1:] if r]
    try:
        sieves = [r for r in rows if r["sieve"] != "total"]
        total = next(r for r in rows if r["sieve"] == "total")
        return (np.array([float(r["achieved_fraction"]) for r in sieves]),
                np.array([int(r["count"]) for r in sieves]), float(total["achieved_fraction"]), int(total["count"]),
                float(total["shell_fraction"] or 0.0))
    except (KeyError, ValueError, StopIteration) as exc:
        raise AnmPostError(f"{path}: not a model summary of `anm run` ({exc})") from None


def collect(runs: Sequence[tuple[float, str | Path]]) -> list[SweepRow]:
    """Rows of (value, summary path) pairs, sorted by value."""
    out = []
    for value, path in sorted(runs, key=lambda r: r[0]):
        a, c, t, n, s = read_summary(path)
        out.append(SweepRow(float(value), a, c, t, n, s))
    if not out:
        raise AnmPostError("no runs to collect")
    nsieve = {len(r.achieved) for r in out}
    if len(nsieve) > 1:
        raise AnmPostError(f"the runs have different numbers of sieves ({', '.join(map(str, sorted(nsieve)))}): "
                           "a sweep compares runs of one grading")
    bad = [r.value for r in out if not np.isfinite(r.value)]
    if bad:
        raise AnmPostError(f"swept value {bad[0]} is not a finite number")
    return out


def sweep_markdown(rows: Sequence[SweepRow], label: str, scale: float = 1.0) -> str:
    """Markdown table: value, achieved fraction per sieve, total, count per sieve, total count, shell fraction."""
    ns = len(rows[0].achieved)
    head = ([label] + [f"PD sieve {k + 1}" for k in range(ns)] + ["total PD"] + [f"n sieve {k + 1}" for k in range(ns)]
            + ["total n", "shell fraction"])
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = ([f"{r.value * scale:g}"] + [f"{a:.4f}" for a in r.achieved] + [f"{r.total:.4f}"]
                 + [str(c) for c in r.count] + [str(r.total_count), f"{r.shell_fraction:.4f}"])
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot_sweep(rows: Sequence[SweepRow], label: str, path: str | Path, scale: float = 1.0,
               shells: bool = False) -> Path:
    """Packing density and particle count against the value (thesis Fig 2.16); with shells=True a
    third panel, the total shell volume fraction (Fig 2.17)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = np.array([r.value for r in rows]) * scale
    n = 3 if shells else 2
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.6))
    axes[0].plot(x, [r.total for r in rows], "o-", label="total")
    for k in range(len(rows[0].achieved)):
        axes[0].plot(x, [r.achieved[k] for r in rows], ".--", lw=0.8, label=f"sieve {k + 1}")
    axes[0].set_ylabel("achieved packing density")
    axes[0].legend(fontsize=7)
    axes[1].plot(x, [r.total_count for r in rows], "o-")
    axes[1].set_ylabel("particles packed")
    if shells:
        axes[2].plot(x, [r.shell_fraction for r in rows], "o-")
        axes[2].set_ylabel("total shell volume fraction")
    for ax in axes:
        ax.set_xlabel(label)
    fig.tight_layout()
    path = Path(path)
    from .output import save_figure
    try:
        save_figure(fig, path, "--png", dpi=150)
    finally:
        plt.close(fig)
    return path

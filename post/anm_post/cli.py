"""The `anm-post` command line (also `python -m anm_post`)."""
from __future__ import annotations

import argparse
import sys

from .errors import AnmPostError
from .tables import read_geometry_table


def _cmd_table(args: argparse.Namespace) -> int:
    table = read_geometry_table(args.table)
    if args.csv:
        try:
            with open(args.csv, "w") as fh:
                fh.write(table.to_csv())
        except OSError as exc:
            raise AnmPostError(f"{args.csv}: cannot write CSV (--csv): {exc.strerror}") from None
    if args.format == "markdown":
        cols = ["volume", "surf._area", "length(mm)", "width(mm)", "thick(mm)", "L/T", "W/T"]
        sys.stdout.write(table.to_markdown([c for c in cols if c in table.columns]))
    summary = table.summary()
    print(f"{len(table)} particles; " + "; ".join(f"mean {k} = {m:.3f} +- {s:.3f}" for k, (m, s) in summary.items()))
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of anm-post."""
    parser = argparse.ArgumentParser(
        prog="anm-post",
        description="Post-processing of Anm output: tables (slices, g(t) and plots follow).",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("table", help="summarise a geometry table written by `anm shape` (or a NIST table)")
    p.add_argument("table", help="geometry table file")
    p.add_argument("--csv", metavar="FILE", help="also write the table as CSV to FILE")
    p.add_argument("--format", choices=["summary", "markdown"], default="summary",
                   help="summary line only (default) or a Markdown table and the summary")
    p.set_defaults(func=_cmd_table)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code (1 with a message on bad input)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except AnmPostError as exc:
        print(f"anm-post: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())

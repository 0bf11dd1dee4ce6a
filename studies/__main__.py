"""Command line: python3 -m studies run [--workers N] [--seeds N] [--force] | page."""
import argparse
import json
import pathlib

from . import jobs as J

DATA = J.ROOT / "docs" / "studies" / "data.json"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python3 -m studies", description=__doc__)
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run the ensembles and write docs/studies/data.json")
    r.add_argument("--anm", default=str(J.ROOT / "build" / "install" / "bin" / "anm"))
    r.add_argument("--workers", type=int, default=2)
    r.add_argument("--seeds", type=int, default=len(J.SEEDS))
    r.add_argument("--force", action="store_true", help="run again even when a result exists")
    sub.add_parser("page", help="write docs/studies.md from docs/studies/data.json")
    args = p.parse_args(argv)
    if args.cmd == "run":
        from . import run
        results = run.run_all(args.anm, args.workers, tuple(range(1, args.seeds + 1)), args.force)
        DATA.parent.mkdir(parents=True, exist_ok=True)
        DATA.write_text(json.dumps({"seeds": list(range(1, args.seeds + 1)), "runs": results}, indent=1) + "\n")
    else:
        from . import page
        page.write(DATA)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

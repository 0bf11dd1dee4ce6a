"""python3 -m studies run | extras | collect | page (scripts/studies.sh runs all four)."""
import argparse
import json

from . import jobs as J

DATA = J.ROOT / "docs" / "studies" / "data.json"


def main(argv=None) -> int:
    from . import run
    p = argparse.ArgumentParser(prog="python3 -m studies", description=__doc__)
    p.add_argument("--anm", default=str(J.ROOT / "build" / "install" / "bin" / "anm"))
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run the ensemble jobs in out/studies/ensemble/")
    r.add_argument("--workers", type=int, default=2, help="runs at a time (one OpenMP thread each)")
    r.add_argument("--seeds", type=int, default=len(J.SEEDS))
    r.add_argument("--force", action="store_true", help="run again even when a result exists")
    r.add_argument("--any-engine", action="store_true",
                   help="keep results made by another engine commit (the page lists every engine commit)")
    sub.add_parser("extras", help="EOB studies and g(t) of the seed-1 M_sand models")
    sub.add_parser("collect", help="gather the results into docs/studies/data.json")
    sub.add_parser("page", help="write docs/studies.md and its figures from docs/studies/data.json")
    args = p.parse_args(argv)
    extras_file = run.SCRATCH / "extras.json"
    if args.cmd == "run":
        run.run_all(args.anm, args.workers, tuple(range(1, args.seeds + 1)), args.force,
                    any_engine=args.any_engine)
    elif args.cmd == "extras":
        from . import extras, page
        page.FIGURES.mkdir(parents=True, exist_ok=True)
        result = {"eob": extras.eob(args.anm, run.SCRATCH, page.FIGURES),
                  "wall": extras.wall(run.SCRATCH, page.FIGURES)}
        extras_file.write_text(json.dumps(result))
    elif args.cmd == "collect":
        from . import collect
        more = json.loads(extras_file.read_text()) if extras_file.is_file() else {}
        collect.write(collect.collect(run.SCRATCH, more), DATA)
    else:
        from . import page
        page.write(DATA)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

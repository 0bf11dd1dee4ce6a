"""Gather the scratch folder's result.json files (and the wall-effect results) into data.json."""
from __future__ import annotations

import json
import pathlib

from . import jobs as J

#: run fields kept in data.json (the namelist is made again from studies/jobs.py)
FIELDS = ("study", "value", "seed", "commit", "engine", "cpu_s", "sieves", "total")


def _order(r: dict) -> tuple:
    study = J.STUDIES[r["study"]]
    return (list(J.STUDIES).index(r["study"]), study.values.index(r["value"]), r["seed"])


def collect(scratch: pathlib.Path, extras: dict | None = None) -> dict:
    """data.json's content: every finished run in a fixed order, and the single-run results
    (studies/extras.py: "eob", "wall")."""
    extras = extras or {}
    runs = []
    for path in sorted(scratch.glob("*/*/seed*/result.json")):
        r = json.loads(path.read_text())
        if r["study"] in J.STUDIES and r["value"] in J.STUDIES[r["study"]].values:
            runs.append({k: r[k] for k in FIELDS})
    runs.sort(key=_order)
    return {"about": "per-seed results of the thesis' tables (studies/, docs/studies.md); "
                     "fractions are of the box, as in the anm run summary CSV",
            "runs": runs, "eob": extras.get("eob", {}), "wall": extras.get("wall", {})}


def write(data: dict, path: pathlib.Path) -> None:
    """Write data.json (stable layout: one run per line)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = ",\n".join("  " + json.dumps(r, sort_keys=True) for r in data["runs"])
    text = ("{\n" + f' "about": {json.dumps(data["about"])},\n' + ' "runs": [\n' + lines + "\n ],\n"
            + f' "eob": {json.dumps(data["eob"], sort_keys=True)},\n'
            + f' "wall": {json.dumps(data["wall"], sort_keys=True)}\n' + "}\n")
    json.loads(text)
    path.write_text(text)

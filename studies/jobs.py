"""The ensemble jobs: one (study, setting, seed) per `anm run`, its namelist made from inputs/.

Each study keeps the namelist of its single-seed script (scripts/study_shells.sh,
scripts/study_locations.sh, scripts/study_msand.sh) and changes only the swept setting, the seed
and the output folder.
"""
from __future__ import annotations

import dataclasses
import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[1]

#: seeds of every ensemble (`&run seed`)
SEEDS = tuple(range(1, 11))


@dataclasses.dataclass(frozen=True)
class Study:
    """One thesis table: the namelist it starts from and the values of its swept setting."""
    key: str
    title: str
    values: tuple
    label: str


STUDIES = {
    "table2_1": Study("table2_1", "Tables 2.1, 2.2: shell thickness", (
        0.0, 0.002, 0.004, 0.006, 0.008, 0.010, 0.012, 0.014, 0.016, 0.018, 0.020),
        "shell thickness (% of L)"),
    "table2_3": Study("table2_3", "Table 2.3: random locations",
                      (30, 60, 90, 120, 140, 285, 450, 975, 1500), "random locations"),
    "msand": Study("msand", "Tables 3.1, 3.2: M_sand", ("shaped", "spheres"), "sand"),
}


@dataclasses.dataclass(frozen=True)
class Job:
    """One run of the ensemble."""
    study: str
    value: object
    seed: int

    @property
    def name(self) -> str:
        """Folder name of the job under the scratch folder."""
        return f"{self.study}/{self.value}/seed{self.seed}"


def all_jobs(seeds=SEEDS) -> list[Job]:
    """Every job, seed by seed (so that an interrupted ensemble holds whole seeds)."""
    return [Job(s.key, v, seed) for seed in seeds for s in STUDIES.values() for v in s.values]


def _sub(pattern: str, repl: str, text: str) -> str:
    """re.sub that insists on exactly one match (a changed input must not go unnoticed)."""
    new, n = re.subn(pattern, repl, text, flags=re.M)
    if n != 1:
        raise ValueError(f"pattern {pattern!r} matched {n} times")
    return new


def namelist(job: Job, directory: str, shapes: str | None = None) -> str:
    """The namelist of one job writing model.h5 and model-summary.csv to `directory`.

    `shapes` replaces the inputs' shape folder ../shared/shapes (relative to the repository root).
    """
    if job.study == "table2_1":
        text = (ROOT / "inputs" / "table2_1.nml").read_text()
        t = float(job.value)
        shells = ("&shells nlayer = 0 /" if t == 0 else
                  f"&shells nlayer = 1, thickness = {t}, thickness_unit = 'fraction', mode = 'exclude' /")
        text = _sub(r"^&shells.*$", shells, text)
    elif job.study == "table2_3":
        text = (ROOT / "inputs" / "table2_3.nml").read_text()
        text = _sub(r"max_locations = [0-9]+", f"max_locations = {int(job.value)}", text)
    elif job.study == "msand":
        nml = {"shaped": "msand.nml", "spheres": "msand_spheres.nml"}[job.value]
        text = (ROOT / "inputs" / nml).read_text()
    else:
        raise ValueError(f"unknown study {job.study}")
    text = _sub(r"^&output .*$", f"&output directory = '{directory}', name = 'model', vrml = .false. /", text)
    text = _sub(r"^&run seed = [0-9]+ /$", f"&run seed = {job.seed} /", text)
    if shapes is not None:
        text = text.replace("'../shared/shapes/", f"'{shapes}/")
    return text

"""docs/studies.md cannot go stale (issue 18): the page is exactly what studies/page.py writes from
docs/studies/data.json, that file holds every thesis table over ten seeds or more, and the
cheapest recorded job, run again with this checkout's anm, gives its recorded numbers exactly."""
import importlib
import importlib.util
import json
import pathlib
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]


def _repository_package(name: str):
    """The repository's own package ROOT/name (not installed: it is loaded from its folder)."""
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, ROOT / name / "__init__.py",
                                                      submodule_search_locations=[str(ROOT / name)])
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


_repository_package("studies")
J = importlib.import_module("studies.jobs")
P = importlib.import_module("studies.page")
R = importlib.import_module("studies.run")

DATA = ROOT / "docs" / "studies" / "data.json"


def _data() -> dict:
    return json.loads(DATA.read_text())


def test_page_is_what_the_generator_writes():
    assert P.PAGE.read_text() == P.render(_data()), (
        "docs/studies.md differs from what studies/page.py writes from docs/studies/data.json: "
        "do not edit it by hand; run `bash scripts/studies.sh page` (or the whole `bash scripts/studies.sh`)")


def test_page_shows_a_changed_result():
    """The comparison can fail: one seed's particle count changed changes the page."""
    data = _data()
    before = P.render(data)
    run = next(r for r in data["runs"] if r["study"] == "table2_3")
    run["total"]["count"] += 7
    assert P.render(data) != before


def test_every_thesis_table_has_ten_seeds():
    runs = _data()["runs"]
    for key, study in J.STUDIES.items():
        for value in study.values:
            seeds = {r["seed"] for r in runs if r["study"] == key and r["value"] == value}
            assert len(seeds) >= 10, f"{key} at {value}: {len(seeds)} seeds in docs/studies/data.json"


def test_differences_beyond_two_sd_are_marked():
    """A cell is bold exactly when the thesis' value is more than two standard deviations away."""
    assert P.pair(0.30, [0.20, 0.21, 0.19], 2) == "0.30 / **0.20 ± 0.01**"
    assert P.pair(0.21, [0.20, 0.21, 0.19], 2) == "0.21 / 0.20 ± 0.01"


def test_cheapest_job_gives_its_recorded_numbers(anm_bin, shapes_dir, tmp_path):
    runs = _data()["runs"]
    entry = min(runs, key=lambda r: (r["cpu_s"], r["study"], str(r["value"]), r["seed"]))
    job = J.Job(entry["study"], entry["value"], entry["seed"])
    nml = tmp_path / "run.nml"
    nml.write_text(J.namelist(job, str(tmp_path / "out"), shapes=str(shapes_dir)))
    proc = subprocess.run([anm_bin, "run", "--force", str(nml)], cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    got = R.read_summary(tmp_path / "out" / "model-summary.csv")
    assert got == {"sieves": entry["sieves"], "total": entry["total"]}, (
        f"{job.name} no longer gives the numbers docs/studies.md was written from "
        f"(engine {entry['engine'][:12]}): run `bash scripts/studies.sh` again")

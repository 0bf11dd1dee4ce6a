"""The single-run parts of the page: the EOB parameter studies (Figs 2.14, 2.15) and g(t) on the
seed-1 M_sand models (Figs 3.8-3.13), their figures copied to docs/figures/."""
from __future__ import annotations

import csv
import os
import pathlib
import subprocess
import sys

from . import jobs as J

SHAPE = "../shared/shapes/MA111-7-coarse/MA111-7-coarse-anm-00002.dat"
#: slice densities and shells of g(t): the thesis' settings (scripts/study_msand.sh)
DENSITIES = (0.005, 0.01, 0.05, 0.1, 0.25, 0.5, 1.0)
T_MIN, T_MAX = 0.025, 0.474


def _post_env() -> dict:
    post = str(J.ROOT / "post")
    old = os.environ.get("PYTHONPATH")
    return dict(os.environ, PYTHONPATH=post + (os.pathsep + old if old else ""))


def _rows(path: pathlib.Path) -> list[list[float]]:
    with open(path, newline="") as f:
        reader = csv.reader(f)
        next(reader)
        return [[float(x) for x in row] for row in reader if row]


def eob(anm: str, scratch: pathlib.Path, figures: pathlib.Path) -> dict:
    """`anm study next` and `anm study nbox` on one coarse shape; the CSV rows and the two plots."""
    out = scratch / "eob"
    out.mkdir(parents=True, exist_ok=True)
    result = {}
    for study, fig in (("next", "fig2_14_next.png"), ("nbox", "fig2_15_nbox.png")):
        csv_path = out / f"{study}.csv"
        subprocess.run([anm, "study", study, SHAPE, "--csv", str(csv_path)], cwd=J.ROOT, check=True,
                       stdout=subprocess.DEVNULL, env=dict(os.environ, OMP_NUM_THREADS="1"))
        subprocess.run([sys.executable, "-m", "anm_post", "plot", str(csv_path), "-o", str(figures / fig)],
                       cwd=J.ROOT, check=True, env=_post_env(), stdout=subprocess.DEVNULL)
        rows = _rows(csv_path)
        result[study] = [[int(r[0])] + r[1:] for r in rows]
    return result


def wall(scratch: pathlib.Path, figures: pathlib.Path) -> dict:
    """g(t) against rho_s on the seed-1 M_sand models (shaped, spherical sand); the two plots each."""
    sys.path.insert(0, str(J.ROOT / "post"))
    from anm_post.model import read_model
    from anm_post.walleffect import RdfSpec, convergence, plot_convergence, plot_rdf
    spec = RdfSpec(t_min=T_MIN, t_max=T_MAX, unit="mm")
    result = {}
    for case, stem in (("shaped", "msand"), ("spheres", "msand_spheres")):
        path = scratch / "msand" / case / f"seed{J.SEEDS[0]}" / "model.h5"
        if not path.is_file():
            continue
        conv = convergence(read_model(str(path)), spec, DENSITIES)
        conv.to_csv(scratch / f"{stem}-conv.csv")
        plot_convergence(conv, figures / f"{stem}-conv.png")
        plot_rdf(conv.results[-1], figures / f"{stem}-rdf.png")
        top = conv.results[-1]
        result[case] = {
            "particle": int(top.particle), "length": float(top.length), "phi_b": float(top.phi_b),
            "densities": [{"density": float(r.density), "n": len(r.positions),
                           "t_inner": [float(x) for x in r.t_inner], "t_outer": [float(x) for x in r.t_outer],
                           "g": [float(x) for x in r.g], "g_se": [float(x) for x in r.g_se],
                           "g_sd": [float(x) for x in r.g_sd]} for r in conv.results]}
        print(f"g(t) {case}: {sum(len(r.positions) for r in conv.results)} slices", file=sys.stderr)
    return result

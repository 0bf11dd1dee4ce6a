"""scripts/density_curve.py follows the model's packing fraction through the progress lines: RSA
lines of a sieve until its first `done`, then only its dense rounds (the RSA passes inside a round
print the round's own request, which must not count) and the lines closing a sieve's growth."""
import importlib.util
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("density_curve", ROOT / "scripts" / "density_curve.py")
dc = importlib.util.module_from_spec(spec)
spec.loader.exec_module(dc)

LOG = """\
[     2.06] sieve 1: placed 64, fraction  0.26808 of  0.35000; run  53.6 % of the target volume, about 2 s left
[     2.31] sieve 1 done: 75 particles, fraction  0.31416 (target  0.35000), 37108 attempts, 1 particles not parked,     0.8 s
[     2.31] warning: sieve 1 ended  0.03584 short of its target (attempts exhausted)
[     5.00] sieve 1: placed 9, fraction  0.01500 of  0.02000; run  60.0 % of the target volume
[     6.00] sieve 1 done: 12 particles, fraction  0.01800 (target  0.02000), 100 attempts, 0 particles not parked,     0.1 s
[    12.47] sieve 1: dense round 1, 84 particles, fraction  0.35186 ( 0.35186 when grown) of  0.35000, acceptance 0.6
[    12.55] sieve 2: placed 100, fraction  0.05000 of  0.15000; run  80 % of the target volume
[    12.75] sieve 2 done: 250 particles, fraction  0.10200 (target  0.15000), 999 attempts, 0 particles not parked, 1 s
[    21.87] sieve 2: dense round 1, 282 particles, fraction  0.14500 ( 0.14765 when grown) of  0.15000, acceptance 0.5
[    22.10] sieve 2 done: 30 particles, fraction  0.00100 (target  0.00100), 99 attempts, 0 particles not parked, 1 s
[    25.00] sieve 2: growth sweep 10, 9 particles short of their size, fraction  0.14800
[    30.00] sieve 2: growth ended after 12 sweeps, 3 particles short of their size, fraction  0.14900
"""


def test_curve_follows_sieves_and_ignores_round_requests(tmp_path):
    log = tmp_path / "run.log"
    log.write_text(LOG)
    out = tmp_path / "c.csv"
    assert dc.main(["--parse", str(log), "--csv", str(out)]) == 0
    rows = [r.split(",") for r in out.read_text().splitlines()[1:]]
    totals = [(float(t), round(float(f), 5), e) for t, f, _, e in rows]
    assert totals == [(2.06, 0.26808, "placed"), (2.31, 0.31416, "sieve done"), (12.47, 0.35186, "dense round"),
                      (12.55, 0.40186, "placed"), (12.75, 0.45386, "sieve done"), (21.87, 0.49686, "dense round"),
                      (25.0, 0.49986, "growth"), (30.0, 0.50086, "growth")]

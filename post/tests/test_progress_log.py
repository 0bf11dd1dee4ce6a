"""Progress lines of `anm run` reach a log file as they are printed (issue 12 item 8): with stderr
redirected to a file, the first sieve's closing line is in the file while the run still goes on.
Before the flush, gfortran block-buffered stderr into a file and the log stayed empty until exit."""
import pathlib
import subprocess
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_progress_reaches_log_while_running(anm_bin, tmp_path):
    text = (ROOT / "inputs" / "default.nml").read_text().replace("directory = 'out'", f"directory = '{tmp_path}'")
    nml = tmp_path / "default.nml"
    nml.write_text(text)
    log = tmp_path / "run.log"
    with open(log, "w") as err:
        proc = subprocess.Popen([anm_bin, "run", str(nml)], stdout=subprocess.DEVNULL, stderr=err, cwd=ROOT)
        seen_while_running = False
        deadline = time.time() + 300
        while time.time() < deadline and proc.poll() is None:
            if "sieve 1 done" in log.read_text():
                seen_while_running = proc.poll() is None
                break
            time.sleep(0.05)
        rc = proc.wait(timeout=600)
    assert rc == 0, log.read_text()
    assert seen_while_running, "the first sieve's line reached the log only at exit:\n" + log.read_text()

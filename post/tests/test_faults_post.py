"""Faults during anm-post's outputs (issue 12, item 6): a full disk (a small tmpfs mounted for the
test; CI runs as root, and under CI=true a failed mount is a failure, not a skip) during each kind
of output (CSV, Markdown, PNG, NPZ, HDF5 labels), a read-only folder, and two processes writing
one output at once. After each: exit code 1 with a message naming the file, every earlier output
byte-identical, no temporary file left, and never a final file mixed from two runs."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from anm_post.cli import main
from anm_post.output import TMP_MARK, OutputSet, write_text

from test_bad_inputs_post import good_model, summary_csv

IN_CI = os.environ.get("CI", "").lower() in ("true", "1")


def _mount(folder: Path, size: str, options: str = "") -> None:
    folder.mkdir(exist_ok=True)
    res = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}{options}", "tmpfs", str(folder)],
                         capture_output=True, text=True)
    if res.returncode != 0:
        message = f"cannot mount a tmpfs at {folder} ({res.stderr.strip() or 'not root?'})"
        if IN_CI:
            pytest.fail(message + " (required when CI=true)")
        pytest.skip(message)


@pytest.fixture
def small_fs(tmp_path):
    """A 4 MB tmpfs; unmounted afterwards."""
    folder = tmp_path / "fs"
    _mount(folder, "4m")
    yield folder
    subprocess.run(["umount", "-l", str(folder)], check=False)


def fill(folder: Path, leave: int = 0) -> Path:
    """Fill the file system of `folder` up to `leave` bytes (about: page granularity)."""
    filler = folder / "filler"
    with open(filler, "wb", buffering=0) as fh:
        for chunk in (1 << 16, 4096, 1):
            try:
                while True:
                    st = os.statvfs(folder)
                    if st.f_bavail * st.f_frsize <= leave + chunk:
                        break
                    fh.write(b"\0" * chunk)
            except OSError:
                pass
    return filler


def snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file() and p.name != "filler"}


def temporaries(folder: Path) -> list[str]:
    return [p.name for p in folder.iterdir() if TMP_MARK in p.name]


def run(capsys, *argv) -> tuple[int, str]:
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code
    _, err = capsys.readouterr()
    assert "Traceback" not in err, err
    return code, err


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("inputs")
    good_model(d / "m.h5")
    (d / "study.csv").write_text("next,v_box,v_box_certified\n10,1.0,1.2\n20,1.1,1.15\n40,1.12,1.13\n")
    summary_csv(d / "s.csv", 2)
    return d


#: Each kind of output: (name, command with {m} model, {i} input folder, {o} output folder,
#: {p} a parameter that changes the content between the two runs).
OUTPUTS = {
    "table_csv": ["table", "{m}", "--csv", "{o}/t.csv"],
    "slice_png_npz": ["slice", "{m}", "--pixel", "0.1", "--position", "{p}", "--png", "{o}/s.png",
                      "--labels", "{o}/s.npz"],
    "slice_h5": ["slice", "{m}", "--pixel", "0.1", "--position", "{p}", "--labels", "{o}/s.h5"],
    "stack_h5": ["slice", "{m}", "--pixel", "0.2", "--density", "0.{p}", "--axis", "x", "--labels", "{o}/st.h5"],
    "plot_png": ["plot", "{i}/study.csv", "-o", "{o}/p.png"],
    "rdf_csv_png": ["rdf", "{m}", "--pixel", "0.2", "--density", "0.{p}", "--csv", "{o}/g.csv", "--png", "{o}/g.png"],
    "convergence": ["convergence", "{m}", "--pixel", "0.2", "--densities", "0.2,0.{p}", "--csv", "{o}/c.csv",
                    "--png", "{o}/c.png", "--rdf-png", "{o}/r.png"],
    "sweep_md_png": ["sweep", "{p}={i}/s.csv", "--markdown", "{o}/w.md", "--png", "{o}/w.png"],
}


def argv(kind: str, inputs: Path, out: Path, p: int) -> list[str]:
    return [a.format(m=inputs / "m.h5", i=inputs, o=out, p=p) for a in OUTPUTS[kind]]


@pytest.mark.parametrize("kind", sorted(OUTPUTS))
def test_full_disk_keeps_earlier_outputs(capsys, small_fs, inputs, kind):
    code, err = run(capsys, *argv(kind, inputs, small_fs, 5))
    assert code == 0, err
    before = snapshot(small_fs)
    assert before and all(before.values()), before.keys()
    fill(small_fs)
    code, err = run(capsys, *argv(kind, inputs, small_fs, 4))
    assert code == 1, err
    assert err.splitlines()[-1].startswith("anm-post: error: ") and "No space left on device" in err, err
    assert "earlier file" in err and TMP_MARK not in err, err
    assert snapshot(small_fs) == before, "an earlier output changed"
    assert temporaries(small_fs) == []
    # with room again the same command succeeds and replaces the outputs
    (small_fs / "filler").unlink()
    code, err = run(capsys, *argv(kind, inputs, small_fs, 4))
    assert code == 0, err
    assert temporaries(small_fs) == [] and set(snapshot(small_fs)) == set(before)


def test_outputs_of_one_command_are_one_set(capsys, small_fs, inputs):
    """Room for the small CSV but not for the picture: the CSV is not replaced either."""
    code, err = run(capsys, *argv("rdf_csv_png", inputs, small_fs, 5))
    assert code == 0, err
    before = snapshot(small_fs)
    fill(small_fs, leave=12 * 1024)
    code, err = run(capsys, *argv("rdf_csv_png", inputs, small_fs, 4))
    assert code == 1 and "g.png" in err and "No space left" in err, err
    assert snapshot(small_fs) == before and temporaries(small_fs) == []


def test_read_only_folder_is_refused_up_front(capsys, tmp_path, inputs):
    """A read-only mount (root ignores permission bits, so a mount is used) is refused before
    any work, naming the folder and the option."""
    folder = tmp_path / "ro"
    _mount(folder, "1m", ",ro")
    try:
        code, err = run(capsys, *argv("slice_png_npz", inputs, folder, 5))
        assert code == 1 and "cannot write in folder" in err and "--png" in err, err
        assert "Read-only file system" in err
    finally:
        subprocess.run(["umount", "-l", str(folder)], check=False)


def test_library_writer_keeps_earlier_file(tmp_path):
    """The helper itself: an error inside the write keeps the earlier file and leaves no temporary."""
    target = tmp_path / "x.csv"
    write_text(target, "old\n")
    with pytest.raises(ZeroDivisionError):
        from anm_post.output import atomic_open
        with atomic_open(target, "--csv") as fh:
            fh.write("new, half written")
            1 / 0
    assert target.read_text() == "old\n" and temporaries(tmp_path) == []
    with pytest.raises(RuntimeError):
        with OutputSet() as outs:
            a = outs.stage(tmp_path / "a.csv", "--csv")
            a.write_text("new")
            raise RuntimeError("later output failed")
    assert not (tmp_path / "a.csv").exists() and temporaries(tmp_path) == []


def test_new_file_has_ordinary_permissions(tmp_path):
    old = os.umask(0o022)
    try:
        write_text(tmp_path / "p.csv", "x\n")
    finally:
        os.umask(old)
    assert (tmp_path / "p.csv").stat().st_mode & 0o777 == 0o644


def test_two_processes_writing_one_output(tmp_path, inputs):
    """Two slices at once to one label file: the final file is complete and is one run's."""
    out = tmp_path / "s.npz"
    cmds = [[sys.executable, "-m", "anm_post", *argv("slice_h5", inputs, tmp_path, p)[:-1], str(out)]
            for p in (3, 5)]
    procs = [subprocess.Popen(c, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for c in cmds]
    results = [p.communicate() for p in procs]
    assert all(p.returncode == 0 for p in procs), results
    with np.load(out) as data:
        origin_z = float(data["origin"][2])
        particle = data["particle"]
    assert origin_z in (3.0, 5.0)
    # the labels belong to the run whose origin the file holds
    expect = tmp_path / "expect.npz"
    res = subprocess.run([sys.executable, "-m", "anm_post", *argv("slice_h5", inputs, tmp_path, int(origin_z))[:-1],
                          str(expect)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    with np.load(expect) as data:
        assert np.array_equal(data["particle"], particle)
    assert temporaries(tmp_path) == []


def test_lines_reach_a_log_file_before_the_process_ends(tmp_path):
    """Item 8: stdout and stderr of anm-post are line-buffered even when they are files, so a log
    shows each line as it is printed and keeps it when the process is killed."""
    code = ("import sys, time\nfrom anm_post.cli import _line_buffered\n_line_buffered()\n"
            "print('result line')\nprint('progress line', file=sys.stderr)\ntime.sleep(60)\n")
    out, err = tmp_path / "out.log", tmp_path / "err.log"
    with open(out, "w") as fo, open(err, "w") as fe:
        proc = subprocess.Popen([sys.executable, "-c", code], stdout=fo, stderr=fe)
        try:
            import time
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline and not (out.read_text() and err.read_text()):
                time.sleep(0.1)
        finally:
            proc.kill()
            proc.wait()
    assert out.read_text() == "result line\n" and err.read_text() == "progress line\n"

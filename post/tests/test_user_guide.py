"""The user guide as a test (issue 17 item 6): every code block of docs/user-guide.md marked
```` ```sh test ```` is run literally, in the order of the guide, as one bash script per block
(`set -euo pipefail`), in a fresh folder holding a copy of the repository's inputs/, with this
build's `anm` and this package's `anm-post` first on the PATH. Blocks marked
```` ```sh not-tested ```` are synopses or long jobs (M_sand). Every fenced block must carry one of
the two marks and there are no indented code blocks, so what is run is unambiguous."""
import os
import pathlib
import re
import shutil
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
GUIDE = ROOT / "docs" / "user-guide.md"
MARKS = ("sh test", "sh not-tested")
# what a new user must be able to do from the guide: these commands must be among the tested ones
MUST_RUN = ["anm run inputs/default.nml", "anm verify out/default.h5", "anm-post slice out/default.h5",
            "anm-post table out/default.h5", "anm-post table geometry.txt", "anm-post rdf", "anm-post sweep",
            "anm-post plot", "anm rerun"]


def blocks(text):
    """[(mark, code)] of every fenced block, in order; refuses unmarked fences and indented code."""
    out = []
    lines = text.splitlines()
    i = 0
    previous_blank = True
    while i < len(lines):
        line = lines[i]
        m = re.match(r"^```(.*)$", line)
        if m:
            mark = m.group(1).strip()
            assert mark in MARKS, f"docs/user-guide.md:{i + 1}: code fence without a mark {MARKS}: {line!r}"
            j = i + 1
            while j < len(lines) and not lines[j].startswith("```"):
                j += 1
            assert j < len(lines), f"docs/user-guide.md:{i + 1}: code fence not closed"
            out.append((mark, "\n".join(lines[i + 1:j]) + "\n"))
            i = j + 1
            previous_blank = False
            continue
        assert not (previous_blank and line.startswith("    ") and line.strip()), \
            f"docs/user-guide.md:{i + 1}: indented code block (use a marked fence): {line!r}"
        previous_blank = not line.strip()
        i += 1
    return out


def test_every_block_is_marked_and_the_essentials_are_tested():
    found = blocks(GUIDE.read_text())
    tested = "".join(code for mark, code in found if mark == "sh test")
    for command in MUST_RUN:
        assert command in tested, f"the guide does not test {command!r}"


def test_user_guide_runs_literally(anm_bin, tmp_path):
    work = tmp_path / "guide"
    shutil.copytree(ROOT / "inputs", work / "inputs")
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "anm").symlink_to(os.path.abspath(anm_bin))
    post = bin_dir / "anm-post"
    post.write_text(f"#!/bin/sh\nexec {sys.executable} -m anm_post \"$@\"\n")
    post.chmod(0o755)
    env = dict(os.environ, PATH=f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}",
               OMP_NUM_THREADS=os.environ.get("OMP_NUM_THREADS", "2"), MPLBACKEND="Agg")
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "post")] + [p for p in [os.environ.get("PYTHONPATH")] if p])
    for k, (mark, code) in enumerate(blocks(GUIDE.read_text())):
        if mark != "sh test":
            continue
        res = subprocess.run(["bash", "-euo", "pipefail", "-c", code], cwd=work, env=env, capture_output=True,
                             text=True, timeout=600)
        assert res.returncode == 0, f"guide block {k} failed (exit {res.returncode}):\n{code}\n" \
                                    f"stdout:\n{res.stdout[-2000:]}\nstderr:\n{res.stderr[-3000:]}"
    for name in ("out/default.h5", "out/default-summary.csv", "out/default.wrl", "out/slice.png", "out/slice.npz",
                 "sweep/again/default.h5", "sweep/again/namelist.nml", "geometry.txt", "next.png",
                 "g.csv", "g.png", "sweep.md", "sweep.png"):
        assert (work / name).is_file(), name

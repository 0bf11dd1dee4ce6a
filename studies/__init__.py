"""The thesis' tables re-run over many seeds (issue 18): jobs, runner and the page generator.

`python3 -m studies run` runs every job of studies/jobs.py in a scratch folder and writes
docs/studies/data.json; `python3 -m studies page` writes docs/studies.md (and its figures) from
that file alone. `bash scripts/studies.sh` does both.
"""

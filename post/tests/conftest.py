"""Shared fixtures: the anm executable and the folder of real CT shapes."""
import os
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def anm_bin() -> str:
    """Path of the anm executable: $ANM_BIN, else build/install/bin/anm (scripts/build.sh)."""
    path = os.environ.get("ANM_BIN") or str(ROOT / "build" / "install" / "bin" / "anm")
    if not os.access(path, os.X_OK):
        pytest.fail(f"anm executable not found at {path}: run scripts/build.sh or set ANM_BIN")
    return path


@pytest.fixture(scope="session")
def shapes_dir() -> pathlib.Path:
    """../shared/shapes (or $ANM_SHAPES_DIR); skipped when missing, but a failure under CI=true."""
    path = pathlib.Path(os.environ.get("ANM_SHAPES_DIR", ROOT.parent / "shared" / "shapes"))
    if not (path / "MA111-7-coarse").is_dir():
        if os.environ.get("CI", "").lower() in ("true", "1"):
            pytest.fail(f"shape folder {path} is missing (required when CI=true)")
        pytest.skip(f"shape folder {path} is missing")
    return path

"""One version number: fpm.toml, post/pyproject.toml, anm_post.__version__, the Fortran constant
written into model files (src/cli/run.f90) and `anm --version` all agree."""
import pathlib
import re
import subprocess

ROOT = pathlib.Path(__file__).resolve().parents[2]


def _toml_version(path):
    return re.search(r'^version\s*=\s*"([^"]+)"', path.read_text(), re.M).group(1)


def test_versions_agree(anm_bin):
    fpm = _toml_version(ROOT / "fpm.toml")
    assert _toml_version(ROOT / "post" / "pyproject.toml") == fpm
    init = (ROOT / "post" / "anm_post" / "__init__.py").read_text()
    assert re.search(r'^__version__\s*=\s*"([^"]+)"', init, re.M).group(1) == fpm
    fortran = re.search(r'anm_version\s*=\s*"([^"]+)"', (ROOT / "src" / "cli" / "run.f90").read_text()).group(1)
    assert fortran == fpm
    out = subprocess.run([anm_bin, "--version"], capture_output=True, text=True, check=True).stdout
    assert out.strip() == f"anm {fpm}"

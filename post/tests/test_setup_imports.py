"""Every third-party import of the Python code (post/, bench/, scripts/, studies/) is installed, pinned, by
scripts/setup.sh: a fresh machine that ran the setup can import everything the tests import
(issue 12, item 1). Imports are found with ast (also those inside functions), so a module that is
imported only on one code path is covered too."""
from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FOLDERS = ("post", "bench", "scripts", "studies")

#: Import name -> PyPI package name, where they differ or where one package provides several names.
IMPORT_TO_PACKAGE = {
    "mpl_toolkits": "matplotlib",
    "matplotlib": "matplotlib",
    "pylab": "matplotlib",
    "numpy": "numpy",
    "h5py": "h5py",
    "pytest": "pytest",
    "_pytest": "pytest",
    "mesonbuild": "meson",
    "ninja": "ninja",
    "setuptools": "setuptools",
    "pkg_resources": "setuptools",
    "fpm": "fpm",
    "meshio": "meshio",
    "vtk": "vtk",
    "vtkmodules": "vtk",
}


def setup_pins() -> dict[str, str]:
    """Package -> pinned version of the pip_pins=( ... ) list of scripts/setup.sh."""
    text = (ROOT / "scripts" / "setup.sh").read_text()
    match = re.search(r"^pip_pins=\(([^)]*)\)", text, re.M)
    assert match, "scripts/setup.sh has no pip_pins=( ... ) list"
    pins = {}
    for item in match.group(1).split():
        name, sep, version = item.partition("==")
        assert sep and version, f"setup.sh: {item!r} is not pinned (NAME==VERSION)"
        pins[name.lower()] = version
    return pins


def python_files() -> list[Path]:
    out = []
    for folder in FOLDERS:
        base = ROOT / folder
        if base.is_dir():
            out += [p for p in sorted(base.rglob("*.py")) if "build" not in p.relative_to(ROOT).parts]
    return out


def local_names(files: list[Path]) -> set[str]:
    """Modules of the project itself: the package, test helpers, scripts next to each other."""
    names = {"anm_post"}
    for p in files:
        names.add(p.stem)
        if p.name == "__init__.py":
            names.add(p.parent.name)
    return names


def third_party_imports(files: list[Path], root: Path = ROOT) -> dict[str, list[str]]:
    """Top-level import name -> places (file:line) of absolute imports that are neither the
    standard library nor the project's own modules."""
    stdlib = set(sys.stdlib_module_names) | {"__future__"}
    local = local_names(files)
    found: dict[str, list[str]] = {}
    for path in files:
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split(".")[0]
                if top in stdlib or top in local:
                    continue
                found.setdefault(top, []).append(f"{path.relative_to(root)}:{node.lineno}")
    return found


def test_every_third_party_import_is_pinned_by_setup():
    files = python_files()
    assert len(files) > 10, files
    pins = setup_pins()
    missing = []
    for top, places in sorted(third_party_imports(files).items()):
        package = IMPORT_TO_PACKAGE.get(top)
        if package is None or package not in pins:
            missing.append(f"{top} ({package or 'unknown package'}): {', '.join(places[:3])}")
    assert not missing, ("imports not installed by scripts/setup.sh (add the package, pinned, to pip_pins, "
                         "and its import name to IMPORT_TO_PACKAGE; or do without it):\n  " + "\n  ".join(missing))


def test_the_check_sees_an_uncovered_import(tmp_path):
    """The scan itself: a file importing scipy (inside a function) is reported, numpy is not."""
    f = tmp_path / "probe.py"
    f.write_text("import numpy as np\n\ndef g():\n    from scipy.special import sph_harm_y\n    import os\n")
    found = third_party_imports([f], root=tmp_path)
    assert set(found) == {"numpy", "scipy"}
    assert "scipy" not in IMPORT_TO_PACKAGE

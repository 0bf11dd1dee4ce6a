"""Rules of the house that a reviewer would otherwise check by eye (docs/developer.md):

- no Fortran procedure longer than 150 lines, internal procedures counted inside their host,
  except a numeric kernel whose header comment explains its length (a `!> Length:` line);
- every OpenMP parallel region states `default(none)`;
- no `stop` in the library (src/): errors are returned to the caller;
- every module file is src/<area>/<part>.f90 holding module anm_<area>_<part>.
"""
import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[2]
SOURCES = sorted((ROOT / "src").rglob("*.f90")) + [ROOT / "app" / "main.f90"]
START = re.compile(r"^(?:(?:pure|elemental|recursive|impure|module|logical|integer(?:\([a-z0-9_]+\))?|"
                   r"real(?:\([a-z0-9_]+\))?|type\([a-z_]+\)|character\([^)]*\))\s+)*"
                   r"(subroutine|function|program)\s+([a-z_0-9]+)")
END = re.compile(r"^end\s*(subroutine|function|program)\b")


def procedures(path):
    """(name, first line, length, header comment) of every outermost procedure of a file."""
    lines = path.read_text().splitlines()
    stack, out = [], []
    for i, raw in enumerate(lines):
        s = raw.split("!")[0].strip().lower()
        if not s:
            continue
        if END.match(s):
            name, first = stack.pop()
            if not stack:
                j = first - 1
                while j >= 0 and lines[j].strip().startswith("!"):
                    j -= 1
                out.append((name, first + 1, i - first + 1, "\n".join(lines[j + 1:first])))
            continue
        m = START.match(s)
        if m:
            stack.append((m.group(2), i))
    assert not stack, f"{path}: unbalanced procedure structure"
    return out


def test_no_procedure_longer_than_150_lines():
    long = [f"{p.relative_to(ROOT)}:{line} {name} ({n} lines)"
            for p in SOURCES for name, line, n, header in procedures(p)
            if n > 150 and "!> Length:" not in header]
    assert not long, "procedures over 150 lines without a '!> Length:' explanation:\n" + "\n".join(long)


def test_rule_scanner_finds_long_procedures(tmp_path):
    """The scanner itself can fail: a 160-line subroutine is reported."""
    body = "\n".join(["   x = x + 1"] * 158)
    f = tmp_path / "long.f90"
    f.write_text(f"module m\ncontains\nsubroutine big(x)\n{body}\nend subroutine big\nend module m\n")
    (name, _, n, _), = procedures(f)
    assert name == "big" and n == 160


def test_openmp_regions_default_none():
    bad = []
    for p in SOURCES:
        text = p.read_text().lower()
        # a directive may continue over several lines ("!$omp ... &" / "!$omp& ...")
        for m in re.finditer(r"!\$omp\s+parallel\b((?:[^\n]*&\s*\n\s*!\$omp&?)*[^\n]*)", text):
            if "default(none)" not in m.group(0).replace(" ", ""):
                line = text[:m.start()].count("\n") + 1
                bad.append(f"{p.relative_to(ROOT)}:{line}")
    assert not bad, "OpenMP parallel regions without default(none): " + ", ".join(bad)


def test_no_stop_in_library():
    bad = []
    for p in sorted((ROOT / "src").rglob("*.f90")):
        for i, raw in enumerate(p.read_text().splitlines(), 1):
            s = raw.split("!")[0].strip().lower()
            if re.match(r"^(error\s+)?stop\b", s) or re.search(r"\bcall\s+exit\s*\(", s):
                bad.append(f"{p.relative_to(ROOT)}:{i}: {raw.strip()}")
    assert not bad, "stop/exit in src/ (return an error instead):\n" + "\n".join(bad)


def test_module_names_spell_their_path():
    bad = []
    for p in sorted((ROOT / "src").rglob("*.f90")):
        rel = p.relative_to(ROOT / "src")
        if len(rel.parts) != 2:
            bad.append(f"{rel}: not src/<area>/<part>.f90")
            continue
        expected = f"anm_{rel.parts[0]}_{p.stem}"
        mods = re.findall(r"^\s*module\s+(?!procedure\b)([a-z_0-9]+)", p.read_text().lower(), re.M)
        if mods != [expected]:
            bad.append(f"{rel}: modules {mods}, expected [{expected}]")
    assert not bad, "\n".join(bad)

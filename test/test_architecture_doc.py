"""docs/architecture.md matches the code (issue 28, item 5).

Two checks, each failing with the exact names to fix:

- every module the page names exists: a ``name.py`` in backticks (bare, under a heading that names
  its package in backticks, or ``package/name.py``), every dotted ``package.module[.attr]``, and
  every test or repository file it names (``test_x.py``, ``test/test_x.py``);
- every module of a package (``src/<pkg>/<pkg>/**/*.py`` but ``__init__.py``) has its row in the
  page's table of that package under "## Every module, package by package".

Modules are added, renamed and split all the time; the failure message lists, per package, the rows
to add and the names to remove, so that a merge only has to follow it.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / 'src'
DOC = ROOT / 'docs' / 'architecture.md'
INDEX_HEADING = '## Every module, package by package'

PACKAGES = sorted(p.name for p in SRC.iterdir() if (p / p.name / '__init__.py').is_file())
"""The Python packages of the suite (rfi_msgs has no Python source of its own)."""

_CODE = re.compile(r'`([^`\n]+)`')
_MODULE_FILE = re.compile(r'^(?:(?P<pkg>[a-z_]+)/)?(?P<rel>(?:[a-z_0-9]+/)*[a-z_0-9]+\.py)$')
_DOTTED = re.compile(r'^(?P<pkg>[a-z_]+)\.(?P<rest>[A-Za-z_][\w.]*)')
_ROW = re.compile(r'^\|\s*`([^`]+)`\s*\|')
TEST_FILES = {p.name for p in [*(ROOT / 'test').glob('test_*.py'), *SRC.glob('*/test/test_*.py')]}


def package_modules(pkg: str) -> set[str]:
    """The modules of one package, as paths relative to ``src/<pkg>/<pkg>/`` (``streams/x.py``)."""
    root = SRC / pkg / pkg
    return {p.relative_to(root).as_posix() for p in root.rglob('*.py') if p.name != '__init__.py'}


MODULES = {pkg: package_modules(pkg) for pkg in PACKAGES}


def _heading_package(heading: str) -> str | None:
    """The first suite package a heading names in backticks (the package of its bare module names)."""
    for name in _CODE.findall(heading):
        if name in MODULES:
            return name
    return None


def _exists(pkg: str | None, rel: str) -> bool:
    if pkg is not None:
        return rel in MODULES[pkg]
    return any(rel in mods for mods in MODULES.values())


def named_modules_missing(text: str) -> list[str]:
    """Module names in the page that do not exist, as ``line N: name (where it was looked for)``."""
    missing: list[str] = []
    heading_pkg: str | None = None
    for number, line in enumerate(text.splitlines(), start=1):
        if line.startswith('#'):
            heading_pkg = _heading_package(line)
            if line.startswith('### ') and line[4:].strip() in MODULES:
                heading_pkg = line[4:].strip()
        for code in _CODE.findall(line):
            for word in re.split(r'[\s,()]+', code):
                file_match = _MODULE_FILE.match(word)
                if file_match:
                    pkg, rel = file_match.group('pkg'), file_match.group('rel')
                    if pkg is not None and pkg not in MODULES:  # a sub-package (streams/) or test/, tools/
                        if not ((ROOT / word).is_file() or _exists(heading_pkg, word)):
                            missing.append(f'line {number}: {word} (no such file)')
                        continue
                    if pkg is None and rel.startswith('test_'):  # a test module, not a package module
                        if rel not in TEST_FILES:
                            missing.append(f'line {number}: {word} (no such test in test/ or src/*/test/)')
                        continue
                    where = pkg if pkg is not None else heading_pkg
                    if not _exists(where, rel):
                        place = f'src/{where}/{where}/' if where else 'every package'
                        missing.append(f'line {number}: {word} (looked for in {place})')
                    continue
                dotted = _DOTTED.match(word)
                if dotted and dotted.group('pkg') in MODULES:
                    pkg, parts = dotted.group('pkg'), dotted.group('rest').split('.')
                    module = parts[0] + '.py'
                    package_dir = SRC / pkg / pkg / parts[0]
                    if module not in MODULES[pkg] and not (package_dir / '__init__.py').is_file():
                        missing.append(f'line {number}: {word} (no src/{pkg}/{pkg}/{module})')
    return missing


def index_rows(text: str) -> dict[str, set[str]]:
    """Per package, the modules of its table under the index heading."""
    assert INDEX_HEADING in text, f'docs/architecture.md has no section "{INDEX_HEADING}"'
    rows: dict[str, set[str]] = {}
    pkg: str | None = None
    for line in text.split(INDEX_HEADING, 1)[1].splitlines():
        if line.startswith('## '):
            break
        if line.startswith('### '):
            pkg = line[4:].strip()
            rows.setdefault(pkg, set())
            continue
        row = _ROW.match(line)
        if row and pkg is not None:
            rows[pkg].add(row.group(1))
    return rows


def index_differences(rows: dict[str, set[str]]) -> list[str]:
    problems: list[str] = []
    for pkg in sorted(set(rows) - set(MODULES)):
        problems.append(f'"### {pkg}": not a package of src/ (packages: {", ".join(PACKAGES)})')
    for pkg in PACKAGES:
        if pkg not in rows:
            problems.append(f'no "### {pkg}" table: add one with a row for each of {sorted(MODULES[pkg])}')
            continue
        absent = sorted(MODULES[pkg] - rows[pkg])
        extra = sorted(rows[pkg] - MODULES[pkg])
        if absent:
            problems.append(f'### {pkg}: add a row for {", ".join(absent)}')
        if extra:
            problems.append(f'### {pkg}: remove the row of {", ".join(extra)} (no such module)')
    return problems


def test_every_module_the_architecture_page_names_exists():
    missing = named_modules_missing(DOC.read_text())
    assert not missing, ('docs/architecture.md names modules that do not exist (rename them to the '
                         'modules that now hold the code):\n  ' + '\n  '.join(missing))


def test_every_package_module_has_its_row_in_the_architecture_page():
    problems = index_differences(index_rows(DOC.read_text()))
    assert not problems, (f'docs/architecture.md, "{INDEX_HEADING}", does not match src/:\n  '
                          + '\n  '.join(problems))


def test_the_checks_see_a_wrong_page():
    """The checks report a renamed module, a missing row and a row too many by name."""
    assert PACKAGES and all(MODULES.values())
    pkg = 'gnss_common'
    first, *rest = sorted(MODULES[pkg])
    page = (f'### Something, `{pkg}`\n\n| `{first}` | x |\n| `no_such_module.py` | y |\n'
            f'`{pkg}.no_such_module.thing` and `{pkg}.{first[:-3]}.thing` and `test/test_x.py`\n'
            f'`test_architecture_doc.py` `test_no_such_test.py`\n')
    missing = named_modules_missing(page)
    assert missing == [f'line 4: no_such_module.py (looked for in src/{pkg}/{pkg}/)',
                       f'line 5: {pkg}.no_such_module.thing (no src/{pkg}/{pkg}/no_such_module.py)',
                       'line 5: test/test_x.py (no such file)',
                       'line 6: test_no_such_test.py (no such test in test/ or src/*/test/)']
    rows = index_rows(f'{INDEX_HEADING}\n\n### {pkg}\n\n| `{first}` | x |\n| `gone.py` | y |\n')
    rows.update({p: MODULES[p] for p in PACKAGES if p != pkg})
    problems = index_differences(rows)
    assert problems == [f'### {pkg}: add a row for {", ".join(rest)}',
                        f'### {pkg}: remove the row of gone.py (no such module)']

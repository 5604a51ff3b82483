"""Dependencies of the suite's packages point only downward, form no module cycle, and are declared.

Every module under ``src/<pkg>/<pkg>/`` and ``src/<pkg>/test/`` is parsed with ``ast`` (imports
inside functions included: a lazy import is still a dependency) and each import of a suite package
is checked against the layering (lowest first)::

    rfi_msgs < gnss_common < rfi_node_common < rfi_sim
             < {rfi_monitor, uwb_gnss_fusion, imm_carrier, gnss_integrity, gnss_correlator} < rfi_experiments

A package may import itself and the packages of lower layers only: the node packages do not
import each other, and no package (nor its tests) imports one above it. Every suite package a
package imports must be declared in its package.xml: ``depend``/``exec_depend`` for the package's
modules, any of ``depend``/``exec_depend``/``test_depend`` for its tests. Finally, the
module-level import graph of the suite has no cycle.
"""

from __future__ import annotations

import ast
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / 'src'

LAYERS: tuple[tuple[str, ...], ...] = (
    ('rfi_msgs',),
    ('gnss_common',),
    ('rfi_node_common',),
    ('rfi_sim',),
    ('rfi_monitor', 'uwb_gnss_fusion', 'imm_carrier', 'gnss_integrity', 'gnss_correlator'),
    ('rfi_experiments',),
)
"""The declared order, lowest first; packages of one layer do not import each other."""

LEVEL = {pkg: level for level, pkgs in enumerate(LAYERS) for pkg in pkgs}
RUN_TIME_TAGS = ('depend', 'exec_depend')
TEST_TAGS = ('depend', 'exec_depend', 'test_depend')


@dataclass(frozen=True)
class Import:
    owner: str       # package whose source holds the import
    is_test: bool    # the importing module is under src/<pkg>/test/
    path: Path       # importing file
    line: int
    module: str      # imported module, dotted (resolved for relative imports)
    names: tuple[str, ...]  # names of ``from module import names`` (empty for ``import module``)


def _modules(pkg: str) -> Iterator[tuple[Path, str | None, bool]]:
    """(file, dotted module name or None for test files, is_test) of one package."""
    root = SRC / pkg
    for path in sorted((root / pkg).rglob('*.py')):
        parts = path.relative_to(root).with_suffix('').parts
        if parts[-1] == '__init__':
            parts = parts[:-1]
        yield path, '.'.join(parts), False
    for path in sorted((root / 'test').rglob('*.py')) if (root / 'test').is_dir() else ():
        yield path, None, True


def _package_of(path: Path, module: str | None) -> str | None:
    """Dotted package of a module (itself for ``__init__``), for relative imports."""
    if module is None:
        return None
    return module if path.name == '__init__.py' else module.rpartition('.')[0]


def collect_imports() -> list[Import]:
    """Every import of a suite package in the suite's sources."""
    found: list[Import] = []
    for pkg in LEVEL:
        if not (SRC / pkg).is_dir():
            continue
        for path, module, is_test in _modules(pkg):
            tree = ast.parse(path.read_text(), filename=str(path))
            base = _package_of(path, module)
            for node in ast.walk(tree):
                if isinstance(node, ast.Import):
                    targets = [(alias.name, ()) for alias in node.names]
                elif isinstance(node, ast.ImportFrom):
                    if node.level:
                        assert base is not None, f'{path}:{node.lineno}: relative import in a test module'
                        anchor = base.split('.')
                        anchor = anchor[:len(anchor) - (node.level - 1)]
                        name = '.'.join(anchor + ([node.module] if node.module else []))
                    else:
                        name = node.module or ''
                    targets = [(name, tuple(a.name for a in node.names))]
                else:
                    continue
                for name, names in targets:
                    if name.split('.')[0] in LEVEL:
                        found.append(Import(pkg, is_test, path, node.lineno, name, names))
    return found


def declared(pkg: str, tags: tuple[str, ...]) -> set[str]:
    """Packages that ``src/<pkg>/package.xml`` declares under any of ``tags``."""
    root = ET.parse(SRC / pkg / 'package.xml').getroot()
    return {(e.text or '').strip() for tag in tags for e in root.findall(tag)}


def layering_violations(imports: list[Import]) -> list[str]:
    out = []
    for imp in imports:
        target = imp.module.split('.')[0]
        if target == imp.owner:
            continue
        if LEVEL[target] >= LEVEL[imp.owner]:
            how = 'a package of its own layer' if LEVEL[target] == LEVEL[imp.owner] else 'a package above it'
            out.append(f'{imp.path.relative_to(SRC)}:{imp.line}: {imp.owner} imports {imp.module} ({how})')
    return out


def undeclared(imports: list[Import]) -> list[str]:
    out = []
    for imp in imports:
        target = imp.module.split('.')[0]
        if target == imp.owner or target not in LEVEL:
            continue
        tags = TEST_TAGS if imp.is_test else RUN_TIME_TAGS
        if target not in declared(imp.owner, tags):
            out.append(f'{imp.path.relative_to(SRC)}:{imp.line}: imports {imp.module} but src/{imp.owner}/package.xml '
                       f'declares no {"/".join(tags)} on {target}')
    return sorted(set(out))


def module_graph(imports: list[Import]) -> dict[str, set[str]]:
    """Edges importer module -> imported module between the packages' own modules (not the tests)."""
    modules: dict[Path, str] = {}
    for pkg in LEVEL:
        if (SRC / pkg).is_dir():
            modules.update({path: mod for path, mod, is_test in _modules(pkg) if not is_test and mod})
    known = set(modules.values())
    graph: dict[str, set[str]] = {mod: set() for mod in known}
    for imp in imports:
        if imp.is_test:
            continue
        importer = modules[imp.path]
        # ``from pkg import module`` imports that module; ``from module import name`` the module itself
        targets = {f'{imp.module}.{n}' for n in imp.names if f'{imp.module}.{n}' in known}
        if imp.module in known and (not imp.names or len(targets) < len(imp.names)):
            targets.add(imp.module)
        graph[importer] |= targets - {importer}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            scc = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                scc.append(w)
                if w == v:
                    break
            if len(scc) > 1:
                out.append(sorted(scc))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


@pytest.fixture(scope='module')
def imports() -> list[Import]:
    return collect_imports()


def test_every_package_of_src_has_a_layer():
    packages = {p.parent.name for p in SRC.glob('*/package.xml')}
    assert packages == set(LEVEL), f'packages without a layer: {sorted(packages - set(LEVEL))}'


def test_imports_point_only_downward(imports):
    violations = layering_violations(imports)
    assert not violations, 'imports against the layering:\n' + '\n'.join(violations)


def test_imported_packages_are_declared(imports):
    missing = undeclared(imports)
    assert not missing, 'undeclared dependencies:\n' + '\n'.join(missing)


def test_no_import_cycle_between_modules(imports):
    found = cycles(module_graph(imports))
    assert not found, 'import cycles:\n' + '\n'.join(' <-> '.join(c) for c in found)


def test_the_checks_catch_what_they_are_for():
    """The checkers on made-up imports: an upward import, a same-layer import, an undeclared one, a cycle."""
    here = SRC / 'rfi_monitor' / 'rfi_monitor' / 'x.py'
    up = Import('rfi_monitor', True, here, 1, 'rfi_experiments.scenario', ('Scenario',))
    side = Import('rfi_monitor', False, here, 2, 'uwb_gnss_fusion.fusion_filter', ())
    down = Import('rfi_monitor', False, here, 3, 'gnss_common.constants', ())
    assert len(layering_violations([up, side, down])) == 2
    assert any('rfi_experiments' in m for m in undeclared([up]))
    assert not undeclared([down])
    assert cycles({'a': {'b'}, 'b': {'c'}, 'c': {'a'}, 'd': {'a'}}) == [['a', 'b', 'c']]
    assert cycles({'a': {'b'}, 'b': set()}) == []

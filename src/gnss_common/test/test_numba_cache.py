"""numba's on-disk cache goes stale across modules; the suite's stamp (gnss_common.numba_cache) does not.

The failure: kernel ``g`` (``cache=True``, module B) inlines kernel ``f`` of module A. After an edit of
``f`` only, plain numba loads ``g``'s old machine code from B's cache (B's file did not change) and
returns the old result. With the suite's stamp (the hash of all the packages' sources in each cache
index) the edit invalidates ``g``'s cache and the new result comes out. Each run is a fresh child
process, as a node start or a test session is.
"""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from gnss_common import numba_cache

SRC = Path(__file__).resolve().parents[2]

A_SOURCE = '''
from numba import njit

OFFSET = {offset}


@njit
def f(x):
    return x + OFFSET
'''

B_SOURCE = '''
from numba import njit

from nbdep_a.kern import f


@njit(cache=True)
def g(x):
    return 2.0 * f(x)
'''

CHILD = '''
import json, sys
if sys.argv[1] == 'stamped':
    from gnss_common import numba_cache
    numba_cache.install(('nbdep_a', 'nbdep_b'))
from nbdep_b.kern import g
value = g(1.0)
print(json.dumps({'value': value, 'hits': sum(g.stats.cache_hits.values()),
                  'locator': type(g._cache._impl.locator).__name__}))
'''


def _write_packages(root: Path, offset: str) -> None:
    for name, source in (('nbdep_a', A_SOURCE.format(offset=offset)), ('nbdep_b', B_SOURCE)):
        (root / name).mkdir(exist_ok=True)
        (root / name / '__init__.py').write_text('')
        (root / name / 'kern.py').write_text(source)


def _run(root: Path, mode: str) -> dict:
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join([str(root), env.get('PYTHONPATH', '')])
    env.pop('NUMBA_CACHE_DIR', None)
    env.pop('NUMBA_DISABLE_JIT', None)
    # -B: no .pyc, so the edited module is read anew whatever the file system's time resolution.
    # A fixed timeout, not rfi_node_common.testing's progress bound: gnss_common's tests may not import a package
    # above it (test_import_direction), nor rclpy. The child imports numba and compiles two one-line kernels: one
    # test's 3-4 children took 20-34 s in all at load 13 on 2 cores (5-10 s each), so 300 s is 30x one child.
    out = subprocess.run([sys.executable, '-B', '-c', CHILD, mode], env=env, cwd=root, check=True,
                         capture_output=True, text=True, timeout=300)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.slow
@pytest.mark.parametrize('mode', ['plain', 'stamped'])
def test_edit_of_an_inlined_kernel_in_another_module(tmp_path, mode):
    _write_packages(tmp_path, '1.0')
    first = _run(tmp_path, mode)
    again = _run(tmp_path, mode)
    assert (first['value'], first['hits']) == (4.0, 0)
    assert (again['value'], again['hits']) == (4.0, 1)  # unchanged sources: loaded from the cache
    assert first['locator'].lstrip('_') == ('SuiteStampLocator' if mode == 'stamped' else 'InTreeCacheLocator')

    _write_packages(tmp_path, '10.0')  # module A only: f(x) = x + 10
    edited = _run(tmp_path, mode)
    if mode == 'plain':
        # the failure mode of numba's own cache: g's machine code of before the edit
        assert (edited['value'], edited['hits']) == (4.0, 1)
    else:
        assert (edited['value'], edited['hits']) == (22.0, 0)
        assert _run(tmp_path, mode) == {'value': 22.0, 'hits': 1, 'locator': 'SuiteStampLocator'}


def _python_packages() -> list[str]:
    return sorted(p.name for p in SRC.iterdir() if (p / p.name / '__init__.py').is_file())


def test_suite_packages_are_the_python_packages_of_src():
    assert sorted(numba_cache.SUITE_PACKAGES) == _python_packages()


@pytest.mark.parametrize('pkg', _python_packages())
def test_each_package_installs_the_stamp_before_anything_else(pkg):
    body = ast.parse((SRC / pkg / pkg / '__init__.py').read_text()).body
    statements = body[1:] if body and isinstance(body[0], ast.Expr) else body  # after the docstring
    first = statements[0]
    assert isinstance(first, ast.ImportFrom)
    want = (None, 1) if pkg == 'gnss_common' else ('gnss_common', 0)  # `from . import` in gnss_common
    assert (first.module, first.level) == want
    assert [a.name for a in first.names] == ['numba_cache']


SUITE_CHILD = '''
import json, sys
if sys.argv[1] == 'numba-first':
    import numba  # noqa: F401
from numba.core.registry import CPUDispatcher
import gnss_common.coordinates, rfi_node_common.cdr
from gnss_common import numba_cache
kinds, stamps = set(), set()
for module in (gnss_common.coordinates, rfi_node_common.cdr):
    for obj in vars(module).values():
        if isinstance(obj, CPUDispatcher) and obj._cache.__class__.__name__ != 'NullCache':
            kinds.add(type(obj._cache._impl.locator).__name__)
            stamps.add(obj._cache._impl.locator.get_source_stamp()[1])
print(json.dumps({'kinds': sorted(kinds), 'stamps': sorted(stamps),
                  'suite': numba_cache.source_hash(numba_cache.SUITE_PACKAGES)}))
'''


@pytest.mark.parametrize('order', ['numba-first', 'suite-first'])
def test_the_suite_kernels_carry_the_stamp_whatever_is_imported_first(order):
    # a fixed timeout, as in _run (no progress bound here: the layering); 3-4 s at load 13
    out = subprocess.run([sys.executable, '-c', SUITE_CHILD, order], check=True, capture_output=True,
                         text=True, timeout=300)
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got['kinds'] == ['SuiteStampLocator']
    assert got['stamps'] == [got['suite']]

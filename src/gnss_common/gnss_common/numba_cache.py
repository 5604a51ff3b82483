"""numba's on-disk cache of the suite's kernels, keyed on the sources of the whole suite.

numba (0.68) keys the cache index of an ``@njit(cache=True)`` function on the content of the one
file that defines it. A kernel that calls a kernel of another module compiles that callee into its
own machine code, and reads the globals it uses (constants) at compile time; after an edit of the
other module, numba still loads the old machine code. This module adds a second part to the index
stamp of every cached function defined in a suite package: one SHA-256 of every ``.py`` file of the
suite's packages, as they are found on ``sys.path`` (the install tree, or ``src/`` for a symlink
install). Any edit of any package makes each kernel's stored index stale, so numba compiles it anew
and overwrites the old files in place (the data files are numbered per index; nothing accumulates).
The caches stay where numba puts them (``__pycache__`` beside the module, ``NUMBA_CACHE_DIR`` when
set, the user cache directory when the tree is read-only): only their freshness test changes, so it
holds however the code runs (``make``, a colcon build on a ROS install, installed executables).

Every package ``__init__`` of the suite imports this module first, so that the stamp is in place
before any of its kernels is decorated. Importing it does not import numba: numba's cache module is
patched when it is imported (or at once if it already was), and the suite's sources are hashed once
per process, when the first cached kernel is decorated (2.4 MB: `docs/numba_cache.md` gives the time).

The stamp is applied through numba's default list of cache locators
(``numba.core.caching.CacheImpl._locator_classes``); when the user replaces that list with
``NUMBA_CACHE_LOCATOR_CLASSES``, numba does not consult it and a warning says so.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import os
import sys
from types import ModuleType
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Iterable, Sequence

SUITE_PACKAGES: tuple[str, ...] = (
    'gnss_common', 'gnss_correlator', 'gnss_integrity', 'imm_carrier', 'rfi_experiments', 'rfi_monitor',
    'rfi_node_common', 'rfi_sim', 'uwb_gnss_fusion',
)
"""The suite's Python packages (``src/<pkg>/<pkg>/``); a test keeps this list equal to ``src/``."""

_NUMBA_CACHING = 'numba.core.caching'
_packages: set[str] = set()
_hashes: dict[frozenset[str], str] = {}
_dirs: dict[frozenset[str], tuple[str, ...]] = {}


def _package_dir(name: str) -> str | None:
    """Directory of top-level package *name* on ``sys.path`` (without importing it), or None."""
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    return os.path.realpath(list(spec.submodule_search_locations)[0])


def source_hash(packages: Iterable[str]) -> str:
    """SHA-256 (hex) of every ``.py`` file of *packages*, by relative path, in sorted order.

    A package that cannot be found contributes its name only. Computed once per process and set
    of packages: a running process keeps the stamp of the code it loaded.
    """
    key = frozenset(packages)
    if key not in _hashes:
        import hashlib  # here, not at import: a process with no cached kernel never pays for it

        digest = hashlib.sha256()
        dirs = []
        for name in sorted(key):
            root = _package_dir(name)
            digest.update(f'package {name}\0'.encode())
            if root is None:
                continue
            dirs.append(root)
            files = sorted(os.path.relpath(os.path.join(where, f), root)
                           for where, _, names in os.walk(root) for f in names if f.endswith('.py'))
            for rel in files:
                digest.update(rel.replace(os.sep, '/').encode() + b'\0')
                with open(os.path.join(root, rel), 'rb') as source:
                    digest.update(source.read())
                digest.update(b'\0')
        _hashes[key] = digest.hexdigest()
        _dirs[key] = tuple(dirs)
    return _hashes[key]


def _in_packages(py_file: str, packages: frozenset[str]) -> bool:
    source_hash(packages)
    path = os.path.realpath(py_file)
    return any(path.startswith(root + os.sep) for root in _dirs[packages])


def _make_locator_class(caching: ModuleType, defaults: Sequence[Any]) -> type:
    """A numba cache locator: numba's own choice of location, stamp extended by the suite hash."""

    class SuiteStampLocator(caching._CacheLocator):  # type: ignore[name-defined]
        """Wraps the locator numba would pick; the stamp is (numba's stamp, suite source hash)."""

        def __init__(self, inner: Any, packages: frozenset[str]) -> None:
            self._inner = inner
            self._packages = packages
            self._py_file = inner._py_file  # numba's warnings name the file

        def ensure_cache_path(self) -> None:
            self._inner.ensure_cache_path()

        def get_cache_path(self) -> str:
            return str(self._inner.get_cache_path())

        def get_source_stamp(self) -> tuple[Any, str]:
            return (self._inner.get_source_stamp(), source_hash(self._packages))

        def get_disambiguator(self) -> str:
            return str(self._inner.get_disambiguator())

        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> Any:
            packages = frozenset(_packages)
            if not _in_packages(py_file, packages):
                return None  # not ours: numba's own locators handle it
            for locator_class in defaults:
                inner = locator_class.from_function(py_func, py_file)
                if inner is not None:
                    return cls(inner, packages)
            return None

    return SuiteStampLocator


def _patch(caching: ModuleType) -> None:
    """Put the suite-stamp locator first in numba's default locator list (once)."""
    impl = getattr(caching, 'CacheImpl', None) or caching._CacheImpl  # numba >= 0.68 / older
    if any(c.__name__ == 'SuiteStampLocator' for c in impl._locator_classes):
        return
    defaults = list(impl._locator_classes)
    impl._locator_classes = [_make_locator_class(caching, defaults), *defaults]
    config = sys.modules.get('numba.core.config')
    if config is not None and str(getattr(config, 'CACHE_LOCATOR_CLASSES', None) or ''):
        import warnings

        warnings.warn('NUMBA_CACHE_LOCATOR_CLASSES is set: the caches of the suite\'s kernels are '
                      'keyed on their own file only and may keep stale code after an edit of '
                      'another module', RuntimeWarning, stacklevel=2)


class _PatchingLoader:
    """Runs numba's cache module, then patches it."""

    def __init__(self, inner: Any) -> None:
        self._inner = inner

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        return self._inner.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        self._inner.exec_module(module)
        _patch(module)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)


class _PatchOnImport:
    """Finds ``numba.core.caching`` with the other finders and wraps its loader (once)."""

    def find_spec(self, fullname: str, path: Any, target: Any = None) -> Any:
        if fullname != _NUMBA_CACHING:
            return None
        sys.meta_path[:] = [f for f in sys.meta_path if not isinstance(f, _PatchOnImport)]
        spec = importlib.machinery.PathFinder.find_spec(fullname, path, target)
        if spec is not None and spec.loader is not None:
            spec.loader = _PatchingLoader(spec.loader)  # type: ignore[assignment]  # a Loader by protocol
        return spec


def install(packages: Iterable[str] = SUITE_PACKAGES) -> None:
    """Key the numba caches of the functions defined in *packages* on the sources of them all.

    Idempotent; further calls add packages (tests use this for packages of their own).
    """
    _packages.update(packages)
    caching = sys.modules.get(_NUMBA_CACHING)
    if caching is not None and hasattr(caching, '_CacheLocator'):
        _patch(caching)
    elif not any(isinstance(f, _PatchOnImport) for f in sys.meta_path):
        sys.meta_path.insert(0, _PatchOnImport())


install()

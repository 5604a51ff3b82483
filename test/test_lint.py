"""Linters as tests: ruff on all Python code, mypy on the pure cores and the shared plumbing."""

from __future__ import annotations

import shutil
from pathlib import Path

from rfi_node_common import testing

ROOT = Path(__file__).resolve().parents[1]


def test_ruff():
    ruff = shutil.which('ruff')
    assert ruff, 'ruff is not installed in the venv'
    done = testing.run_process([ruff, 'check', '--no-cache', '.'], 'ruff did not end', cwd=ROOT, text=True)
    assert done.returncode == 0, done.stdout + done.stderr


def test_mypy():
    mypy = shutil.which('mypy')
    assert mypy, 'mypy is not installed in the venv'
    done = testing.run_process([mypy], 'mypy did not end', cwd=ROOT, text=True)  # a cold cache: minutes of CPU
    assert done.returncode == 0, done.stdout + done.stderr

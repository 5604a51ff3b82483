"""Linters as tests: ruff on all Python code, mypy on the pure cores and the shared plumbing."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_ruff():
    ruff = shutil.which('ruff')
    assert ruff, 'ruff is not installed in the venv'
    done = subprocess.run([ruff, 'check', '--no-cache', '.'], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr


def test_mypy():
    mypy = shutil.which('mypy')
    assert mypy, 'mypy is not installed in the venv'
    done = subprocess.run([mypy], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr

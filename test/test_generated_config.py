"""The generated config files and parameter tables equal what the parameter definitions give.

``tools/generate_config.py`` writes each registered node's ``config/<node>.yaml`` and its user-parameter
table in docs/reference/parameters.md from the node's parameter dataclass; a default or a description
changed in the code without running it fails here.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _tool():
    spec = importlib.util.spec_from_file_location('generate_config', ROOT / 'tools' / 'generate_config.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_shipped_config_files_and_tables_are_the_generated_ones(capsys):
    assert _tool().main(['--check']) == 0, capsys.readouterr().out


def test_the_table_markers_are_required_and_the_table_is_replaced():
    tool = _tool()
    begin, end = tool.markers('n')
    assert tool.with_table(f'a\n{begin}\nold\n{end}\nb\n', 'n', 'new\n') == f'a\n{begin}\nnew\n{end}\nb\n'
    with pytest.raises(ValueError, match='lacks the markers'):
        tool.with_table('no markers', 'n', 'new\n')

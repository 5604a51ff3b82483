"""The launch files (issue 30 item 1) against what is installed, without ``ros2 launch``.

Every ``share/<package>/launch/*.launch.xml`` of the suite's packages is read as launch_xml reads it: every
argument is documented; every ``<node>`` names an installed executable whose ``--help`` lists each topic the launch
file remaps and each parameter it sets, and whose parameters file (the default of ``params_file``) holds the node's
name as its top-level key; every ``<include>`` resolves to an installed launch file that declares each argument passed
to it, and every argument of an included file without a default is passed. test_launch_real.py runs them with the
official ``ros2 launch``.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from functools import cache
from pathlib import Path

import pytest
import yaml
from ament_index_python.packages import get_package_prefix, get_package_share_directory

from rfi_node_common import testing

PACKAGES = ('rfi_monitor', 'gnss_integrity', 'uwb_gnss_fusion', 'imm_carrier', 'gnss_correlator', 'rfi_experiments')
"""The packages that ship launch files (test_every_node_package_ships_one checks the node packages do)."""
SUITE = ('rfi_experiments', 'suite.launch.xml')


def _launch_files() -> list[Path]:
    out = []
    for pkg in PACKAGES:
        out += sorted((Path(get_package_share_directory(pkg)) / 'launch').glob('*.launch.xml'))
    return out


FILES = _launch_files()


def _resolve(text: str, args: dict[str, str]) -> str:
    """The substitutions these files use: $(var NAME) and $(find-pkg-share PKG)."""
    text = re.sub(r'\$\(find-pkg-share ([\w]+)\)', lambda m: get_package_share_directory(m.group(1)), text)
    return re.sub(r'\$\(var ([\w]+)\)', lambda m: args[m.group(1)], text)


def _args(root: ET.Element) -> dict[str, ET.Element]:
    return {a.get('name'): a for a in root.findall('arg')}


def _defaults(root: ET.Element) -> dict[str, str]:
    return {n: _resolve(a.get('default', ''), {}) for n, a in _args(root).items() if a.get('default') is not None}


@cache
def _help(pkg: str, exe: str) -> tuple[str, str]:
    """(topics section, parameters section) of an installed executable's --help."""
    path = Path(get_package_prefix(pkg)) / 'lib' / pkg / exe
    out = testing.run_process([str(path), '--help'], text=True)  # its speed is test_executables.py's to bound
    assert out.returncode == 0, out.stderr
    text = out.stdout
    topics = text.split('topics:', 1)[1].split('parameters:', 1)[0]
    params = text.split('parameters:', 1)[1] if 'parameters:' in text else ''
    return topics, params


def _topic_names(section: str) -> set[str]:
    return {t.lstrip('/') for t in re.findall(r'(/?[a-z_]+(?:/[a-z_]+)+|/diagnostics)', section)}


def _param_names(section: str) -> set[str]:
    return set(re.findall(r'^  ([a-z_][a-z0-9_.]*) \(default', section, flags=re.M))


def test_every_node_package_ships_one():
    names = {f.name for f in FILES}
    for expected in ('rfi_monitor.launch.xml', 'gnss_integrity.launch.xml', 'fusion.launch.xml',
                     'imm_carrier.launch.xml', 'gnss_correlator.launch.xml',
                     'if_source.launch.xml', 'ubx_source.launch.xml', 'suite.launch.xml'):
        assert expected in names, (expected, sorted(names))


@pytest.mark.parametrize('path', FILES, ids=[f.name for f in FILES])
def test_arguments_are_documented_and_nodes_match_their_executables(path: Path):
    root = ET.parse(path).getroot()
    assert root.tag == 'launch'
    for name, arg in _args(root).items():
        assert len(arg.get('description', '')) >= 10, f'{path.name}: argument {name} has no description'
    values = _defaults(root)
    for node in root.iter('node'):
        pkg, exe, name = node.get('pkg'), node.get('exec'), node.get('name')
        topics, params = _help(pkg, exe)
        known_topics, known_params = _topic_names(topics), _param_names(params)
        for remap in node.findall('remap'):
            topic = remap.get('from').lstrip('/')
            assert topic in known_topics, f'{path.name}: {exe} has no topic {topic} ({sorted(known_topics)})'
        for param in node.findall('param'):
            if param.get('from') is not None:
                file = Path(_resolve(param.get('from'), values))
                assert file.is_file(), f'{path.name}: parameters file {file} not installed'
                top = yaml.safe_load(file.read_text())
                assert list(top) == [name], f'{path.name}: {file.name} is keyed {list(top)}, the node is {name}'
                declared = set(top[name]['ros__parameters'])
                assert declared <= known_params, f'{file.name}: not parameters of {exe}: {declared - known_params}'
            else:
                assert param.get('name') in known_params | {'use_sim_time'}, (path.name, param.get('name'))


@pytest.mark.parametrize('path', FILES, ids=[f.name for f in FILES])
def test_includes_resolve_and_pass_declared_arguments(path: Path):
    root = ET.parse(path).getroot()
    values = _defaults(root)
    for inc in root.iter('include'):
        target = Path(_resolve(inc.get('file'), values))
        assert target.is_file(), f'{path.name}: includes {target}, not installed'
        declared = _args(ET.parse(target).getroot())
        passed = {a.get('name') for a in inc.findall('arg')}
        assert passed <= set(declared), f'{path.name}: {target.name} has no argument {passed - set(declared)}'
        missing = {n for n, a in declared.items() if a.get('default') is None} - passed
        assert not missing, f'{path.name}: {target.name} needs {missing}'
        cond = inc.get('if')
        if cond is not None:
            assert re.fullmatch(r'\$\(var \w+\)', cond) and values[cond[6:-1]] in ('true', 'false'), (path.name, cond)


def test_the_suite_starts_every_node_of_the_suite():
    """suite.launch.xml reaches every node launch file (the sources optionally)."""
    root = ET.parse(Path(get_package_share_directory(SUITE[0])) / 'launch' / SUITE[1]).getroot()
    values = _defaults(root)
    included = {Path(_resolve(i.get('file'), values)).name: i.get('if') for i in root.iter('include')}
    assert included == {'rfi_monitor.launch.xml': None, 'gnss_integrity.launch.xml': '$(var with_integrity)',
                        'fusion.launch.xml': None, 'imm_carrier.launch.xml': '$(var with_imm)',
                        'gnss_correlator.launch.xml': '$(var with_correlator)',
                        'if_source.launch.xml': '$(var with_if_source)',
                        'ubx_source.launch.xml': '$(var with_ubx_source)'}
    assert values['with_integrity'] == values['with_imm'] == 'true'
    assert values['with_if_source'] == values['with_ubx_source'] == values['with_correlator'] == 'false'

"""Every dependency in src/*/package.xml is a key that rosdep resolves on Ubuntu 24.04 / ROS 2 Jazzy
(issue 11, item 5), so `rosdep install --from-paths src --ignore-src -y` works as docs/guide/setup.md says.

rosdep cannot run here (no apt ROS), so the keys it resolves are written down below, each with
where it is defined: ros/rosdistro's rosdep/python.yaml (with the pull request that added or fixed
the rule where it is recent), the packages released in ros/rosdistro's jazzy/distribution.yaml
(ros-jazzy-<name> debs), or this project's rosdep/rfi.yaml for PyPI-only packages that rosdistro
has no key for (docs/guide/setup.md registers it as a rosdep source). A new dependency needs its key's
source added here: look the key up in rosdistro, never guess it (`rosbags`, the key we had, is
not one: rosdistro names it python3-rosbags-pip).
"""

from __future__ import annotations

import re
import shlex
import xml.etree.ElementTree as ET
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / 'src'
PROJECT_RULES = ROOT / 'rosdep' / 'rfi.yaml'
DEPENDENCY_TAGS = ('depend', 'build_depend', 'build_export_depend', 'buildtool_depend', 'buildtool_export_depend',
                   'exec_depend', 'test_depend', 'doc_depend')

PYTHON_YAML = 'ros/rosdistro rosdep/python.yaml'
ROSDISTRO_PYTHON_KEYS = {
    # key: (what rosdep installs on Ubuntu, source)
    'python3-numpy': ('apt python3-numpy', f'{PYTHON_YAML}: ubuntu: [python3-numpy]'),
    'python3-scipy': ('apt python3-scipy', f'{PYTHON_YAML}: ubuntu: [python3-scipy]'),
    'python3-matplotlib': ('apt python3-matplotlib', f'{PYTHON_YAML}: ubuntu: [python3-matplotlib]'),
    'python3-tqdm': ('apt python3-tqdm', f"{PYTHON_YAML}: ubuntu: '*': [python3-tqdm] (xenial: null)"),
    'python3-serial': ('apt python3-serial', f'{PYTHON_YAML}: ubuntu: [python3-serial]'),
    'python3-pytest': ('apt python3-pytest', f'{PYTHON_YAML}: ubuntu: [python3-pytest]'),
    'python3-numba': ('apt python3-numba', f'{PYTHON_YAML}: ubuntu: [python3-numba] for every release since '
                                           'ros/rosdistro#36477 (merged 2023-03-15; before, bionic and focal only)'),
    'python3-rosbags-pip': ('pip rosbags', f'{PYTHON_YAML}: pip [rosbags], ros/rosdistro#37795 (merged 2023-06-26)'),
    'python3-pyubx2-pip': ('pip pyubx2', f'{PYTHON_YAML}: pip [pyubx2], ros/rosdistro#44166 (merged 2025; its '
                                         'review renamed pyubx2-pip to python3-pyubx2-pip)'),
}
"""rosdistro's rules for the Python packages the suite uses."""

JAZZY = 'ros/rosdistro jazzy/distribution.yaml'
JAZZY_PACKAGES = {
    'rclpy': f'{JAZZY}: repository rclpy',
    'std_msgs': f'{JAZZY}: repository common_interfaces',
    'geometry_msgs': f'{JAZZY}: repository common_interfaces',
    'nav_msgs': f'{JAZZY}: repository common_interfaces',
    'sensor_msgs': f'{JAZZY}: repository common_interfaces',
    'diagnostic_msgs': f'{JAZZY}: repository common_interfaces',
    'visualization_msgs': f'{JAZZY}: repository common_interfaces',
    'builtin_interfaces': f'{JAZZY}: repository rcl_interfaces',
    'rosidl_default_generators': f'{JAZZY}: repository rosidl_defaults',
    'rosidl_default_runtime': f'{JAZZY}: repository rosidl_defaults',
    'ament_cmake': f'{JAZZY}: repository ament_cmake',
}
"""ROS packages released into Jazzy: rosdep resolves them to ros-jazzy-<name with dashes>."""


def workspace_packages() -> set[str]:
    return {ET.parse(p).getroot().findtext('name', '').strip() for p in SRC.glob('*/package.xml')}


def dependencies() -> dict[str, set[str]]:
    """Key -> the package.xml files (package names) that depend on it, every dependency tag."""
    out: dict[str, set[str]] = {}
    for path in sorted(SRC.glob('*/package.xml')):
        root = ET.parse(path).getroot()
        for tag in DEPENDENCY_TAGS:
            for element in root.findall(tag):
                out.setdefault((element.text or '').strip(), set()).add(path.parent.name)
    return out


def project_rules() -> dict[str, list[str]]:
    """Key -> PyPI packages, from rosdep/rfi.yaml (every rule must be pip on debian and ubuntu)."""
    rules = yaml.safe_load(PROJECT_RULES.read_text())
    out = {}
    for key, rule in rules.items():
        packages = {os_name: rule.get(os_name, {}).get('pip', {}).get('packages') for os_name in ('debian', 'ubuntu')}
        assert packages['debian'] == packages['ubuntu'] and packages['ubuntu'], (key, rule)
        assert key.startswith('python3-') and key.endswith('-pip'), key
        out[key] = packages['ubuntu']
    return out


def pip_packages(key: str, rules: dict[str, list[str]]) -> list[str]:
    """PyPI packages behind a pip key (empty for an apt or ROS key)."""
    if key in rules:
        return rules[key]
    how = ROSDISTRO_PYTHON_KEYS.get(key, ('',))[0]
    return [how.split()[1]] if how.startswith('pip ') else []


def test_every_dependency_is_a_key_rosdep_resolves():
    own = workspace_packages()
    rules = project_rules()
    unknown = {key: sorted(users) for key, users in dependencies().items()
               if key not in own and key not in ROSDISTRO_PYTHON_KEYS and key not in JAZZY_PACKAGES
               and key not in rules}
    assert not unknown, (f'keys rosdep cannot resolve (look each up in ros/rosdistro rosdep/*.yaml or '
                         f'jazzy/distribution.yaml and add it with its source to this test): {unknown}')


def test_the_project_rules_are_only_for_what_rosdistro_lacks():
    rules = project_rules()
    assert not set(rules) & (set(ROSDISTRO_PYTHON_KEYS) | set(JAZZY_PACKAGES))
    used = dependencies()
    assert set(rules) <= set(used), 'a rule in rosdep/rfi.yaml that no package.xml uses'


def test_every_pip_key_is_in_requirements_and_in_the_setup_guide_pip_line():
    """`make setup` (requirements.txt) and the setup guide's pip line for an existing ROS install install
    exactly the PyPI packages behind the pip keys, so rosdep finds them installed and never runs pip
    itself (system-wide, which PEP 668 refuses on Ubuntu 24.04)."""
    rules = project_rules()
    wanted = {p for key in dependencies() for p in pip_packages(key, rules)}
    requirements = {re.split(r'[\[<>=;\s]', line.strip())[0].lower()
                    for line in (ROOT / 'requirements.txt').read_text().splitlines()
                    if line.strip() and not line.startswith('#')}
    assert wanted <= requirements, wanted - requirements
    guide = (ROOT / 'docs' / 'guide' / 'setup.md').read_text()
    section = guide.split('## On an existing ROS 2 Jazzy install', 1)[1].split('\n## ', 1)[0]
    lines = [line for line in section.splitlines() if line.startswith('python -m pip install ')]
    assert len(lines) == 1, lines
    words = shlex.split(lines[0].split(' #', 1)[0])[4:]  # after `python -m pip install`
    # numpy pinned to the version already there: apt's, which ROS's message packages are built against
    pinned = ["numpy==$(python -c 'import numpy; print(numpy.__version__)')"]
    assert [w for w in words if w.startswith('numpy==')] == pinned
    assert {w for w in words if not w.startswith('numpy==')} == wanted

"""The Foxglove layout and the rviz2 config (issue 30 item 3) name only topics the nodes publish, with the type the
display expects, and message paths whose fields exist. What a node publishes is read from its code (the ``TOPICS``
text its ``--help`` prints); no ROS graph is needed."""

from __future__ import annotations

import importlib
import json
import re
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
VIZ = ROOT / 'src' / 'rfi_experiments' / 'viz'
LAYOUT = VIZ / 'rfi_suite.foxglove.json'
RVIZ = VIZ / 'rfi_suite.rviz'
NODES = ('rfi_monitor.rfi_monitor_node', 'uwb_gnss_fusion.fusion_node', 'imm_carrier.imm_carrier_node',
         'gnss_integrity.gnss_integrity_node')
RVIZ_TYPES = {'rviz_default_plugins/Image': 'sensor_msgs/Image', 'rviz_default_plugins/Path': 'nav_msgs/Path',
              'rviz_default_plugins/MarkerArray': 'visualization_msgs/MarkerArray',
              'rviz_default_plugins/Odometry': 'nav_msgs/Odometry'}
"""The message type each rviz2 display class subscribes to."""


def published() -> dict[str, str]:
    """Topic (absolute, without a namespace) -> message type, from the ``publishes`` part of each node's TOPICS."""
    out: dict[str, str] = {}
    for name in NODES:
        text = importlib.import_module(name).TOPICS
        part = text.split('publishes', 1)[1]
        for topic, msg_type in re.findall(r'(/?[a-z][\w/]*) \((\w+/\w+)', part):
            out['/' + topic.lstrip('/')] = msg_type
    return out


def message_class(type_name: str):
    pkg, msg = type_name.split('/')
    return getattr(importlib.import_module(f'{pkg}.msg'), msg)


def resolve(type_name: str, fields: list[str]) -> str:
    """The type at the end of a field path (``sequence<pkg/Type>`` and ``pkg/Type`` followed; a missing field
    raises KeyError)."""
    t = type_name
    for f in fields:
        t = message_class(t).get_fields_and_field_types()[f]
        m = re.fullmatch(r'sequence<(.+?)(?:, \d+)?>', t) or re.fullmatch(r'(.+?)\[\d*\]', t)
        if m:
            t = m.group(1)
    return t


def layout_paths() -> list[str]:
    """Every topic or message path the layout names."""
    config = json.loads(LAYOUT.read_text())['configById']
    paths: list[str] = []
    for panel in config.values():
        paths += [p['value'] for p in panel.get('paths', [])]
        image = panel.get('imageMode', {})
        if image:
            paths += [image['imageTopic'], *image.get('annotations', {})]
        paths += list(panel.get('topics', {}))
        if 'followTopic' in panel:
            paths.append(panel['followTopic'])
        paths += list(panel.get('topicColors', {}))
        if 'topicPath' in panel:
            paths.append(panel['topicPath'])
    return paths


def test_every_layout_path_is_a_published_topic_and_its_fields_exist():
    pub = published()
    paths = layout_paths()
    assert len(paths) >= 15
    for path in paths:
        topic, _, rest = path.partition('.')
        assert topic in pub, f'{path}: {topic} is published by no node'
        fields = [re.sub(r'\[.*?\]|\{.*?\}', '', f) for f in rest.split('.')] if rest else []
        leaf = resolve(pub[topic], fields)
        if fields:   # a plotted value: a number
            assert leaf in ('double', 'float', 'uint8', 'uint16', 'uint32', 'int8', 'int32', 'boolean'), (path, leaf)
        for flt in re.findall(r'\{(\w+)==', path):
            parent = resolve(pub[topic], fields[:-1])
            assert flt in message_class(parent).get_fields_and_field_types(), (path, flt)


def test_the_layout_draws_what_issue_30_asks_for():
    config = json.loads(LAYOUT.read_text())['configById']
    kinds = {key.split('!')[0] for key in config}
    assert {'Image', '3D', 'map', 'Plot', 'StateTransitions'} <= kinds
    image = next(p for k, p in config.items() if k.startswith('Image!'))['imageMode']
    assert image['imageTopic'] == '/rfi/spectrum/waterfall' and '/rfi/spectrum/swept_band' in image['annotations']
    values = [p['value'] for panel in config.values() for p in panel.get('paths', [])]
    assert any('{method==1}' in v for v in values) and any('{method==2}' in v for v in values)  # IMM against PLL
    assert any(v.startswith('/rfi/jammer_state.') for v in values)
    track = next(p for k, p in config.items() if k.startswith('3D!'))
    assert {'/fusion/path', '/fusion/markers', '/fusion/satellites'} <= set(track['topics'])
    assert track['followTf'] == 'map'

    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node['first']) + leaves(node['second'])
    assert sorted(leaves(json.loads(LAYOUT.read_text())['layout'])) == sorted(config)   # every panel placed


def test_every_rviz_display_subscribes_a_published_topic_of_its_type():
    pub = published()
    cfg = yaml.safe_load(RVIZ.read_text())
    displays = cfg['Visualization Manager']['Displays']
    seen = []
    for d in displays:
        if 'Topic' not in d:
            continue
        topic = d['Topic']['Value']
        assert topic in pub, f'{d["Name"]}: {topic} is published by no node'
        assert RVIZ_TYPES[d['Class']] == pub[topic], (d['Name'], pub[topic])
        seen.append(topic)
        assert d['Topic']['Reliability Policy'] in ('Reliable', 'Best Effort')
    assert {'/rfi/spectrum/waterfall', '/fusion/path', '/fusion/markers', '/fusion/satellites'} <= set(seen)
    assert cfg['Visualization Manager']['Global Options']['Fixed Frame'] == 'map'


def test_marker_namespaces_in_rviz_are_those_the_fusion_draws():
    src = (ROOT / 'src' / 'uwb_gnss_fusion' / 'uwb_gnss_fusion' / 'view_topics.py').read_text()
    cfg = yaml.safe_load(RVIZ.read_text())
    for d in cfg['Visualization Manager']['Displays']:
        for ns in d.get('Namespaces', {}):
            assert f"'{ns}'" in src, ns


@pytest.mark.parametrize('path', [LAYOUT, RVIZ])
def test_the_viewer_files_are_installed_with_rfi_experiments(path):
    setup = (ROOT / 'src' / 'rfi_experiments' / 'setup.py').read_text()
    assert "'/viz'" in setup and f"viz/*{path.suffix}" in setup

"""Diagnostics levels of the fusion node on the default experiment's timeline (issue 11 item 3).

The GNSS + UWB stream of scenarios/default.yaml's first 40 s (clean until 30 s, then a 22 dB CW), made
by the scenario code, replayed through FusionNode with the truth's jammer states (an ideal monitor).
Every report of the clean phase must be OK (before this issue one rejected range per second made the
node WARN), every report well inside the jammed phase WARN (the J/S costs 7.7 dB of C/N0 by eq. 4),
none ERROR; hardware_id is the parameter.
"""

from __future__ import annotations

from pathlib import Path

import rclpy
import yaml
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.parameter import Parameter
from ros_fixtures import make_context

from rfi_experiments.replay import ReplayHarness
from rfi_experiments.scenario import load_scenario, write_scenario_bag
from uwb_gnss_fusion.fusion_node import FusionNode

DEFAULT_SCENARIO = Path(__file__).resolve().parents[1] / 'src' / 'rfi_experiments' / 'scenarios' / 'default.yaml'
DURATION_S = 40.0
CLEAN_END_S = 30.0
INPUTS = ('/gnss/measurements', '/uwb/ranges', '/truth/jammer_state')


def test_levels_are_ok_on_clean_input_and_warn_under_the_jammer(tmp_path):
    scenario = yaml.safe_load(DEFAULT_SCENARIO.read_text())
    scenario['duration_s'] = DURATION_S
    scenario['jamming'] = [{**j, 'end_s': min(j['end_s'], DURATION_S)} for j in scenario['jamming']
                           if j['start_s'] < DURATION_S]
    # the GNSS + UWB stream alone, with its truth jammer states (the IF stream writes them in the demo)
    scenario['streams'] = {'gnss_uwb': {**scenario['streams']['gnss_uwb'], 'truth_jammer_state': True}}
    (tmp_path / 'scenario.yaml').write_text(yaml.safe_dump(scenario))
    write_scenario_bag(load_scenario(tmp_path / 'scenario.yaml'), tmp_path / 'bag')
    context = make_context()
    try:
        node = FusionNode(context=context, parameter_overrides=[Parameter('hardware_id', value='sim-receiver+tag')],
                          cli_args=['--ros-args', '-r', '/rfi/jammer_state:=/truth/jammer_state'])
        harness = ReplayHarness([node], context=context)
        result = harness.run(tmp_path / 'bag', topics=INPUTS, rate=None)
        harness.destroy()
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    reports = result.messages('/diagnostics')
    t0 = reports[0].header.stamp.sec + reports[0].header.stamp.nanosec * 1e-9
    levels = {}
    for report in reports:
        status = report.status[0]
        assert status.hardware_id == 'sim-receiver+tag' and status.name == 'uwb_gnss_fusion'
        t = report.header.stamp.sec + report.header.stamp.nanosec * 1e-9 - t0
        levels[round(t, 3)] = (status.level, status.message)
    clean = {t: v for t, v in levels.items() if t < CLEAN_END_S}
    jammed = {t: v for t, v in levels.items() if t >= CLEAN_END_S + 1.0}
    assert len(clean) >= 29 and len(jammed) >= 8
    assert all(level == DiagnosticStatus.OK for level, _ in clean.values()), clean
    assert all(level == DiagnosticStatus.WARN and 'costs 7.7 dB of C/N0' in text for level, text in jammed.values())
    assert not any(level == DiagnosticStatus.ERROR for level, _ in levels.values())
    # three anchors and no side given (the scenario's): the mirror across their plane is said, never a fault
    values = [{kv.key: kv.value for kv in r.status[0].values} for r in reports]
    fusing = [(v, text) for v, (_, text) in zip(values, levels.values(), strict=True) if text.startswith('fusing')]
    assert fusing and all(v['uwb_anchors_heard'] == '3' and v['uwb_mirror_ambiguous'] == 'True'
                          and 'mirror' in text for v, text in fusing), fusing[:2]

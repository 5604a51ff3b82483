"""Spoofing attacks and a moving receiver in the gnss_uwb scenario stream: the shipped spoofed.yaml,
its truth topics, the drag a snapshot solver sees, clear errors for bad attack lists, and the
simulate command writing the bag. Pure apart from rclpy's message classes: no ROS graph."""

from __future__ import annotations

import copy
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
import pytest
import yaml

from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic
from gnss_common.spp import SinglePointPositioner
from rfi_experiments.scenario import ScenarioError, load_scenario, scenario_messages
from rfi_experiments.streams import gnss_uwb

PKG = Path(__file__).resolve().parents[1]
SPOOFED = PKG / 'scenarios' / 'spoofed.yaml'
S = 1_000_000_000


def _load(tmp_path, data):
    path = tmp_path / 'scenario.yaml'
    path.write_text(yaml.safe_dump(data))
    return load_scenario(path)


def _spoofed_data():
    return yaml.safe_load(SPOOFED.read_text())


def _collect(scenario):
    by_topic = defaultdict(list)
    for stamp_ns, topic, msg in scenario_messages(scenario):
        by_topic[topic].append((stamp_ns, msg))
    return by_topic


@pytest.fixture(scope='module')
def spoofed_run():
    return _collect(load_scenario(SPOOFED))


def test_the_shipped_scenario_is_the_attack_of_the_issue():
    sc = load_scenario(SPOOFED)
    assert set(sc.streams) == {'gnss_uwb'} and sc.duration_s == 180.0 and sc.jamming is None
    s, phases, _ = gnss_uwb.parse_section(sc, sc.streams['gnss_uwb'])
    assert phases == ((None, 180.0),) and len(s.anchors[0]) == 3
    (attack,) = s.spoofing
    assert attack.kind == 'position_push' and attack.start_s == 60.0 and attack.end_s is None
    assert attack.push_velocity_enu_mps == (1.0, 0.0, 0.0) and attack.doppler_consistent
    assert attack.power_advantage_db == 3.0 and attack.constellations is None


def test_spoofed_stream_topics_and_truth(spoofed_run):
    counts = {t: len(v) for t, v in spoofed_run.items()}
    assert counts == {'/gnss/measurements': 900, '/truth/position': 900, '/truth/integrity': 900,
                      '/truth/spoofed_position': 600, '/truth/spoofed_time': 600, '/uwb/ranges': 10800}
    from rfi_msgs.msg import GnssIntegrity
    t0 = spoofed_run['/gnss/measurements'][0][0]
    attack_ns = t0 + 60 * S
    for stamp, msg in spoofed_run['/truth/integrity']:
        assert msg.jamming_state == GnssIntegrity.STATE_NONE
        if stamp < attack_ns:
            assert msg.spoofing_state == GnssIntegrity.STATE_NONE and len(msg.affected_svids) == 0
        else:
            assert msg.spoofing_state == GnssIntegrity.STATE_DETECTED
            assert msg.spoofing_scope == GnssIntegrity.SCOPE_ALL and list(msg.affected_constellations) == [1]
            assert msg.first_alarm_stamp.sec * S + msg.first_alarm_stamp.nanosec == attack_ns
    truth = {stamp: np.array([m.point.x, m.point.y, m.point.z]) for stamp, m in spoofed_run['/truth/position']}
    rx = next(iter(truth.values()))
    lat, lon, _ = ecef_to_geodetic(rx)
    rot = ecef_to_enu_rotation(lat, lon)
    for stamp, m in spoofed_run['/truth/spoofed_position']:
        offset = rot @ (np.array([m.point.x, m.point.y, m.point.z]) - truth[stamp])
        np.testing.assert_allclose(offset, [(stamp - attack_ns) / S, 0.0, 0.0], atol=1e-6)
    for stamp, m in spoofed_run['/truth/spoofed_time']:
        assert (m.time_ref.sec * S + m.time_ref.nanosec) == stamp and m.source == 'position_push'


def test_the_snapshot_solution_is_dragged_east(spoofed_run):
    from rfi_node_common.conversions import msg_to_epoch

    truth = {stamp: np.array([m.point.x, m.point.y, m.point.z]) for stamp, m in spoofed_run['/truth/position']}
    rx = next(iter(truth.values()))
    lat, lon, _ = ecef_to_geodetic(rx)
    rot = ecef_to_enu_rotation(lat, lon)
    spp = SinglePointPositioner()
    east = {stamp: float(rot[0] @ (spp.process(msg_to_epoch(m)).position_ecef_m - truth[stamp]))
            for stamp, m in spoofed_run['/gnss/measurements']}
    stamps = sorted(east)
    before = np.array([east[s] for s in stamps[:300]])
    last = np.array([east[s] for s in stamps[-25:]])
    assert np.abs(before).max() < 5.0
    assert np.mean(last) == pytest.approx(119.6, abs=3.0)  # 1 m/s east from 60 s, last 5 s


def test_without_the_attack_the_same_run_before_it(tmp_path, spoofed_run):
    data = _spoofed_data()
    del data['streams']['gnss_uwb']['spoofing']
    clean = _collect(_load(tmp_path, data))
    assert set(clean) == {'/gnss/measurements', '/truth/position', '/uwb/ranges'}
    t0 = clean['/gnss/measurements'][0][0]
    for (sa, a), (sb, b) in zip(clean['/gnss/measurements'], spoofed_run['/gnss/measurements'], strict=True):
        pa = [m.pseudorange_m for m in a.measurements]
        pb = [m.pseudorange_m for m in b.measurements]
        ca = [m.cn0_dbhz for m in a.measurements]
        cb = [m.cn0_dbhz for m in b.measurements]
        # the takeover at 60 s starts on the authentic code (zero push) with the spoofer's power
        assert sa == sb and (pa == pb) == (sa <= t0 + 60 * S) and (ca == cb) == (sa < t0 + 60 * S)
    assert [m.range_m for _, m in clean['/uwb/ranges']] == [m.range_m for _, m in spoofed_run['/uwb/ranges']]


@pytest.mark.parametrize('spoofing,match', [
    ([{'kind': 'position_push', 'start_s': 10.0}], r'spoofing\[0\].*push_velocity_enu_mps'),
    ([{'kind': 'takeover', 'start_s': 10.0, 'power': 3.0}], r'spoofing\[0\].*unknown key.*power'),
    ('takeover', r'gnss_uwb\.spoofing must be a list'),
    ([{'kind': 'takeover', 'start_s': 200.0}], r'spoofing\[0\]\.start_s 200.0 is not before'),
    ([{'kind': 'takeover', 'start_s': 10.0}, {'kind': 'time_push', 'start_s': 20.0, 'time_push_ns_per_s': 100.0}],
     r'spoofing\[1\].*not overlap'),
    ([{'kind': 'takeover', 'start_s': 10.0, 'end_s': 30.0},
      {'kind': 'time_push', 'start_s': 20.0, 'time_push_ns_per_s': 100.0}], r'spoofing\[1\].*not overlap'),
])
def test_bad_attack_lists_are_named(tmp_path, spoofing, match):
    data = _spoofed_data()
    data['streams']['gnss_uwb']['spoofing'] = spoofing
    with pytest.raises(ScenarioError, match=match):
        list(scenario_messages(_load(tmp_path, data)))


def test_two_attacks_in_turn_and_a_moving_receiver_across_phases(tmp_path):
    data = _spoofed_data()
    data['duration_s'] = 20.0
    g = data['streams']['gnss_uwb']
    g['receiver_velocity_enu_mps'] = [2.0, 1.0, 0.0]
    g['jamming'] = [{'jsr_db': None, 'duration_s': 10.0}, {'jsr_db': 6.0}]
    g['spoofing'] = [
        {'kind': 'time_push', 'start_s': 2.0, 'end_s': 8.0, 'time_push_ns_per_s': 100.0, 'doppler_consistent': False},
        {'kind': 'position_push', 'start_s': 12.0, 'push_velocity_enu_mps': [0.0, 0.0, 1.0],
         'constellations': ['gps'], 'cn0_mode': 'matched'},
    ]
    run = _collect(_load(tmp_path, copy.deepcopy(data)))
    pos = np.array([[m.point.x, m.point.y, m.point.z] for _, m in run['/truth/position']])
    lat, lon, _ = ecef_to_geodetic(pos[0])
    rot = ecef_to_enu_rotation(lat, lon)
    steps = (pos[1:] - pos[:-1]) @ rot.T  # 0.2 s apart, straight on through the phase boundary at 10 s
    np.testing.assert_allclose(steps, np.tile([0.4, 0.2, 0.0], (len(steps), 1)), atol=1e-6)
    anchors = {m.anchor_id: (m.anchor_position.x, m.anchor_position.y, m.anchor_position.z)
               for _, m in run['/uwb/ranges'][:3]}
    assert all(anchors[m.anchor_id] == (m.anchor_position.x, m.anchor_position.y, m.anchor_position.z)
               for _, m in run['/uwb/ranges'])  # the anchors stay where they were placed
    sources = Counter(m.source for _, m in run['/truth/spoofed_time'])
    assert sources == {'time_push': 30, 'position_push': 40}
    from rfi_msgs.msg import GnssIntegrity
    states = [(stamp, m.spoofing_state, m.jamming_state) for stamp, m in run['/truth/integrity']]
    t0 = states[0][0]
    for stamp, spoof, jam in states:
        t = (stamp - t0) / S
        on = 2.0 <= t < 8.0 or t >= 12.0
        assert spoof == (GnssIntegrity.STATE_DETECTED if on else GnssIntegrity.STATE_NONE)
        assert jam == (GnssIntegrity.STATE_DETECTED if t >= 10.0 else GnssIntegrity.STATE_NONE)
    bad = copy.deepcopy(data)
    bad['streams']['gnss_uwb']['receiver_velocity_enu_mps'] = [1.0, 'fast', 0.0]
    with pytest.raises(ScenarioError, match='receiver_velocity_enu_mps'):
        list(scenario_messages(_load(tmp_path, bad)))


def test_simulate_writes_a_small_bag(tmp_path, capsys):
    from rfi_experiments.simulate import main

    out = tmp_path / 'spoofed_bag'
    assert main(['simulate', str(SPOOFED), str(out), '--no-progress']) == 0
    assert 'wrote 14700 messages' in capsys.readouterr().out
    size = sum(f.stat().st_size for f in out.rglob('*') if f.is_file())
    assert size < 5e6

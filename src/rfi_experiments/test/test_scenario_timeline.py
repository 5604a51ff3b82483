"""The shared scenario timeline (top-level ``start`` and ``jamming``): what each stream derives from
it, per-stream overrides, and clear errors for a bad schedule. Pure: no ROS graph."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from rfi_experiments.scenario import ScenarioError, load_scenario

PKG = Path(__file__).resolve().parents[1]

BASE = {
    'name': 't', 'seed': 1, 'duration_s': 60.0,
    'start': {'gps_week': 1854, 'tow_s': 3600.0},
    'jamming': [
        {'start_s': 0.0, 'end_s': 10.0, 'type': 'none'},
        {'start_s': 10.0, 'end_s': 20.0, 'type': 'cw', 'jsr_db': 22.0, 'frequency_hz': 1.2e6},
        {'start_s': 30.0, 'end_s': 50.0, 'type': 'chirp', 'jsr_db': 22.0, 'sweep_rate_hz_per_s': 1.0e12},
    ],
    'streams': {'if_snapshots': {}, 'gnss_uwb': {}, 'correlators': {'onset_phase': {'type': 'chirp', 'jsr_db': 22.0}}},
}


def load(tmp_path, data):
    path = tmp_path / 'scenario.yaml'
    path.write_text(yaml.safe_dump(data))
    return load_scenario(path)


def with_(**changes):
    data = {**BASE, **changes}
    return {k: (dict(v) if isinstance(v, dict) else v) for k, v in data.items()}


def test_every_stream_derives_start_and_schedule(tmp_path):
    sc = load(tmp_path, BASE)
    ifs, gnss, corr = sc.streams['if_snapshots'], sc.streams['gnss_uwb'], sc.streams['correlators']
    # ROS (UTC) stamp of GPS week 1854, TOW 3600 s (2015-07-19 01:00:00 GPST; GPS - UTC = 17 s)
    assert ifs['start_stamp_ns'] == 1437267583_000_000_000
    assert ifs['phases'] == BASE['jamming']
    assert (gnss['start_gps_week'], gnss['start_gps_tow_s']) == (1854, 3600.0)
    assert (corr['start_gps_week'], corr['start_gps_tow_s']) == (1854, 3600.0)
    # one J/S phase per phase; gaps (20-30 s, 50-60 s) are jammer-free phases of their own
    assert gnss['jamming'] == [{'jsr_db': None, 'duration_s': 10.0}, {'jsr_db': 22.0, 'duration_s': 10.0},
                               {'jsr_db': None, 'duration_s': 10.0}, {'jsr_db': 22.0, 'duration_s': 20.0},
                               {'jsr_db': None, 'duration_s': 10.0}]
    # the first chirp phase at 22 dB, not the CW phase at the same J/S
    assert corr['onset_s'] == 30.0 and 'onset_phase' not in corr


def test_a_stream_key_overrides_the_shared_one(tmp_path):
    data = with_(streams={'if_snapshots': {'start_stamp_ns': 5, 'phases': []},
                          'gnss_uwb': {'jamming': [{'jsr_db': 6.0}]}, 'correlators': {'onset_s': 12.0}})
    sc = load(tmp_path, data)
    assert sc.streams['if_snapshots']['start_stamp_ns'] == 5 and sc.streams['if_snapshots']['phases'] == []
    assert sc.streams['gnss_uwb']['jamming'] == [{'jsr_db': 6.0}]
    assert sc.streams['gnss_uwb']['start_gps_week'] == 1854
    assert sc.streams['correlators']['onset_s'] == 12.0


def test_without_a_timeline_the_sections_are_unchanged(tmp_path):
    data = {k: v for k, v in BASE.items() if k not in ('start', 'jamming')}
    data['streams'] = {'gnss_uwb': {'start_gps_week': 1854}}
    assert load(tmp_path, data).streams == {'gnss_uwb': {'start_gps_week': 1854}}


@pytest.mark.parametrize('changes, words', [
    ({'start': {'gps_week': 1854}}, ['start', 'gps_week and tow_s']),
    ({'start': {'gps_week': -1, 'tow_s': 0.0}}, ['start.gps_week']),
    ({'start': {'gps_week': 1854, 'tow_s': 604800.0}}, ['start.tow_s']),
    ({'jamming': []}, ['jamming', 'non-empty']),
    ({'jamming': [{'start_s': 0.0, 'end_s': 10.0, 'type': 'pulsed'}]}, ['jamming[0].type']),
    ({'jamming': [{'start_s': 0.0, 'end_s': 10.0, 'type': 'cw'}]}, ['jamming[0].jsr_db', 'required']),
    ({'jamming': [{'start_s': 0.0, 'end_s': 10.0, 'type': 'none', 'jsr_db': 3.0}]}, ['jamming[0]', 'jsr_db']),
    ({'jamming': [{'start_s': 0.0, 'end_s': 10.0, 'type': 'cw', 'jsr_db': 3.0, 'sweep_rate_hz_per_s': 1.0}]},
     ['jamming[0]', 'unknown key', 'sweep_rate_hz_per_s']),
    ({'jamming': [{'start_s': 0.0, 'end_s': 90.0, 'type': 'none'}]}, ['jamming[0]', 'duration_s']),
    ({'jamming': [{'start_s': 0.0, 'end_s': 20.0, 'type': 'none'}, {'start_s': 10.0, 'end_s': 30.0, 'type': 'none'}]},
     ['jamming[1]', 'overlap']),
    ({'jamming': [{'start_s': 0.0, 'end_s': 10.0, 'type': 'chirp', 'jsr_db': '1e12'}]},
     ['jamming[0].jsr_db', 'exponent']),
    ({'streams': {'correlators': {'onset_phase': {'type': 'chirp', 'jsr_db': 30.0}}}}, ['onset_phase', 'no chirp']),
    ({'streams': {'correlators': {'onset_s': 1.0, 'onset_phase': {'type': 'cw', 'jsr_db': 22.0}}}}, ['not both']),
    ({'streams': {'rinex_jammed': {}}}, ['rinex_jammed', 'remove the top-level start']),
])
def test_bad_timeline_is_a_clear_error(tmp_path, changes, words):
    with pytest.raises(ScenarioError) as err:
        load(tmp_path, with_(**changes))
    for word in words:
        assert word in str(err.value)


def test_onset_phase_needs_the_schedule(tmp_path):
    data = {k: v for k, v in BASE.items() if k != 'jamming'}
    with pytest.raises(ScenarioError, match='needs the top-level jamming'):
        load(tmp_path, data)


def test_shipped_default_scenario_resolves_to_its_former_explicit_sections():
    """bags/default was made when every stream spelled out the timeline; the shared timeline must
    resolve to exactly those sections (test/test_default_bag_regeneration.py compares the messages)."""
    sc = load_scenario(PKG / 'scenarios' / 'default.yaml')
    ifs, gnss, corr = sc.streams['if_snapshots'], sc.streams['gnss_uwb'], sc.streams['correlators']
    assert ifs['start_stamp_ns'] == 1437267583000000000  # ROS (UTC) stamp of week 1854, TOW 3600 s
    assert [(p['start_s'], p['end_s'], p['type'], p.get('jsr_db')) for p in ifs['phases']] == [
        (0.0, 30.0, 'none', None), (30.0, 50.0, 'cw', 22.0), (50.0, 60.0, 'none', None),
        (60.0, 80.0, 'chirp', -10.0), (80.0, 100.0, 'chirp', -2.0), (100.0, 120.0, 'chirp', 6.0),
        (120.0, 140.0, 'chirp', 14.0), (140.0, 160.0, 'chirp', 22.0), (160.0, 180.0, 'chirp', 30.0)]
    assert ifs['phases'][1]['frequency_hz'] == 1.2e6
    assert all(p['sweep_rate_hz_per_s'] == 1.0e12 for p in ifs['phases'] if p['type'] == 'chirp')
    assert gnss['jamming'] == [{'jsr_db': j, 'duration_s': d} for j, d in (
        (None, 30.0), (22.0, 20.0), (None, 10.0), (-10.0, 20.0), (-2.0, 20.0), (6.0, 20.0), (14.0, 20.0),
        (22.0, 20.0), (30.0, 20.0))]
    assert (gnss['start_gps_week'], gnss['start_gps_tow_s']) == (corr['start_gps_week'], corr['start_gps_tow_s']) \
        == (1854, 3600.0)
    assert corr['onset_s'] == 140.0


@pytest.mark.parametrize('name', ['arl1_jammed', 'fusion_paper', 'imm_paper', 'rfi_paper'])
def test_other_shipped_scenarios_load(name):
    sc = load_scenario(PKG / 'scenarios' / f'{name}.yaml')
    assert sc.streams

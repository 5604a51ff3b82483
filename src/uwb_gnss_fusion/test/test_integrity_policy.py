"""Tests for uwb_gnss_fusion.integrity_policy: exclusion of spoofed GNSS, hysteresis, J/S, bad verdicts."""

import math
from types import SimpleNamespace

import pytest

from gnss_common.integrity_codes import (
    SCOPE_ALL,
    SCOPE_CONSTELLATIONS,
    SCOPE_NONE,
    SCOPE_SATELLITES,
    STATE_DETECTED,
    STATE_NONE,
    STATE_SUSPECTED,
    STATE_UNKNOWN,
)
from gnss_common.observations import GALILEO, GPS
from gnss_common.synthetic_sky import synthetic_epoch
from uwb_gnss_fusion.integrity_policy import (
    GnssExclusion,
    IntegrityVerdict,
    integrity_jammer_to_signal,
    verdict_of,
)

S = 1_000_000_000
EPOCH = synthetic_epoch(constellations=[GPS] * 5 + [GALILEO] * 4)


def v(t_s, state, scope=SCOPE_NONE, constellations=(), satellites=(), jam=STATE_UNKNOWN, js=math.nan):
    return IntegrityVerdict(int(t_s * S), state, scope, constellations, satellites, jam, js)


def test_detected_all_excludes_every_epoch_until_a_clean_period_without_break():
    ex = GnssExclusion(readmit_clean_s=30.0)
    assert ex.filter_epoch(EPOCH) == (EPOCH, 0)
    assert ex.update(v(10, STATE_DETECTED, SCOPE_ALL)) == "excluded"
    assert ex.filter_epoch(EPOCH) == (None, 9)
    assert ex.update(v(11, STATE_NONE)) is None
    assert ex.update(v(30, STATE_SUSPECTED)) is None  # a suspect restarts the wait
    assert ex.update(v(31, STATE_NONE)) is None
    assert ex.update(v(50, STATE_UNKNOWN)) is None  # unknown holds it, never readmits
    assert ex.update(v(60, STATE_NONE)) is None and ex.active
    assert ex.update(v(61, STATE_NONE)) == "readmitted"
    assert not ex.active and ex.filter_epoch(EPOCH) == (EPOCH, 0)
    assert ex.counts == {"exclusions": 1, "readmissions": 1, "epochs_excluded": 1, "satellites_excluded": 9}


def test_constellation_and_satellite_scopes_remove_only_what_they_name():
    ex = GnssExclusion()
    ex.update(v(1, STATE_DETECTED, SCOPE_CONSTELLATIONS, (GALILEO,)))
    epoch, removed = ex.filter_epoch(EPOCH)
    assert removed == 4 and {o.constellation for o in epoch.observations} == {GPS}
    ex.update(v(2, STATE_DETECTED, SCOPE_SATELLITES, (), ((GPS, 1), (GPS, 2))))
    assert ex.scope == SCOPE_CONSTELLATIONS
    epoch, removed = ex.filter_epoch(EPOCH)
    assert removed == 6 and sorted(o.svid for o in epoch.observations) == [3, 4, 5]
    ex.update(v(3, STATE_DETECTED, SCOPE_ALL))
    assert ex.scope == SCOPE_ALL and ex.filter_epoch(EPOCH)[0] is None


def test_suspected_never_excludes_and_detected_without_scope_excludes_all():
    ex = GnssExclusion()
    assert ex.update(v(1, STATE_SUSPECTED, SCOPE_ALL)) is None and not ex.active
    assert ex.update(v(2, STATE_DETECTED, SCOPE_NONE)) == "excluded" and ex.scope == SCOPE_ALL


def test_not_acting_counts_nothing_and_excludes_nothing():
    ex = GnssExclusion(act_on_spoofing=False)
    assert ex.update(v(1, STATE_DETECTED, SCOPE_ALL)) is None and not ex.active


def test_jamming_js_from_a_verdict():
    assert integrity_jammer_to_signal(v(1, STATE_NONE, jam=STATE_DETECTED, js=21.5)) == 21.5
    assert math.isnan(integrity_jammer_to_signal(v(1, STATE_NONE, jam=STATE_NONE)))
    assert integrity_jammer_to_signal(v(1, STATE_NONE, jam=STATE_SUSPECTED, js=10.0)) is None
    assert integrity_jammer_to_signal(v(1, STATE_NONE, jam=STATE_DETECTED)) is None  # no J/S estimate


def _msg(**kw):
    base = dict(spoofing_state=STATE_DETECTED, spoofing_scope=SCOPE_SATELLITES, jamming_state=STATE_NONE,
                affected_constellations=[], affected_satellite_constellations=[GPS, GPS], affected_svids=[3, 7],
                jammer_to_signal_db=math.nan, header=SimpleNamespace(stamp=SimpleNamespace(sec=5, nanosec=7)))
    base.update(kw)
    return SimpleNamespace(**base)


def test_verdict_of_a_message_and_its_rejections():
    verdict, reason = verdict_of(_msg())
    assert reason is None and verdict.stamp_ns == 5 * S + 7 and verdict.satellites == ((GPS, 3), (GPS, 7))
    assert verdict_of(_msg(spoofing_state=9)) == (None, "integrity_unknown_state")
    assert verdict_of(_msg(spoofing_scope=4)) == (None, "integrity_unknown_state")
    assert verdict_of(_msg(affected_svids=[3])) == (None, "integrity_malformed_satellites")
    assert verdict_of(_msg(jammer_to_signal_db=math.inf)) == (None, "integrity_js_nonphysical")
    assert verdict_of(_msg(jammer_to_signal_db=500.0)) == (None, "integrity_js_nonphysical")


def test_bad_readmit_period():
    with pytest.raises(ValueError, match="readmit_clean_s"):
        GnssExclusion(readmit_clean_s=-1.0)

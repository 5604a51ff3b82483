"""Tests for uwb_gnss_fusion.spp_reference: the SPP reference the fusion asks for on divergence."""

import math
from dataclasses import replace

import numpy as np

from gnss_common.spp import SinglePointPositioner
from gnss_common.synthetic_sky import RECEIVER_ECEF_M as RX
from gnss_common.synthetic_sky import synthetic_epoch as _synthetic_epoch
from uwb_gnss_fusion.spp_reference import SppReferenceCache

# ----------------------------------------------------------------------------- SPP reference cache
_T0 = 1_437_263_983_000_000_000  # ROS (UTC) stamp of GPS week 1854, TOW 0
_NS = 1_000_000_000


def _at(stamp_ns: int, valid: bool = True):
    epoch = _synthetic_epoch()
    if not valid:  # three satellites: no fix
        epoch = replace(epoch, observations=epoch.observations[:3])
    return replace(epoch, stamp_ns=stamp_ns)


def test_reference_is_the_newest_valid_fix_within_the_age_and_each_epoch_is_solved_once():
    solved = []
    cache = SppReferenceCache(SinglePointPositioner(), 5.0, solved.append)
    for k in range(8):
        cache.add(_at(_T0 + k * _NS, valid=k != 6))
    assert len(cache) == 6  # the last 5 s: stamps _T0 + 2 s .. _T0 + 7 s
    assert cache.reference(_T0 + 7 * _NS - 1) is not None and solved == [False, True]  # 6 s invalid, then 5 s
    stamp, pos, std, clock = cache.reference(_T0 + 7 * _NS - 1)
    assert stamp == _T0 + 5 * _NS and solved == [False, True]  # nothing solved twice
    assert np.linalg.norm(pos - RX) < 1e-3 and 0.0 < std < 10.0 and math.isfinite(clock)
    assert cache.reference(_T0 + 7 * _NS)[0] == _T0 + 7 * _NS
    assert cache.reference(_T0 + 20 * _NS) is None  # every kept epoch is older than 5 s before that
    assert cache.reference(_T0) is None  # dropped already
    cache.clear()
    assert len(cache) == 0 and cache.reference(_T0 + 7 * _NS) is None

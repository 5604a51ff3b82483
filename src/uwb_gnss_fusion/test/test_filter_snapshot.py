"""FusionFilter.snapshot / restore copy an explicit state object: nothing the filter carries from message to
message can be left out of a snapshot without a test failing.

The filter's attributes are ``__slots__``: one not declared there cannot be set at all. The slots are
``state`` (a :class:`FilterState`, deep-copied whole by a snapshot) and the attributes listed in
``FusionFilter.NOT_IN_SNAPSHOT`` with the reason they stay out; these tests hold that classification
complete and check that a restored filter continues exactly as the original did from the snapshot on.
"""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest

from gnss_common.observations import UwbRangeMeasurement
from uwb_gnss_fusion.filter_state import FilterState
from uwb_gnss_fusion.fusion_filter import FusionFilter
from uwb_gnss_fusion.fusion_params import FusionParams

ANCHORS_M = np.array([[12.0, 1.0, 2.0], [-6.0, 8.0, 1.5], [-4.0, -10.0, 3.0], [1.0, 0.0, 9.0]])


def ranges(t0_s: float, t1_s: float, tag=(1.0, 2.0, 0.5)) -> list[UwbRangeMeasurement]:
    """Ranges (map frame, 0.05 m) from the four anchors in turn to a static tag, 40 a second."""
    stamps_ns = np.arange(round(t0_s * 40), round(t1_s * 40)) * 25_000_000
    return [UwbRangeMeasurement(int(t), f'A{k % 4}', ANCHORS_M[k % 4], 'map',
                                float(np.linalg.norm(np.asarray(tag) - ANCHORS_M[k % 4])), 0.05)
            for k, t in zip(range(round(t0_s * 40), round(t1_s * 40)), stamps_ns, strict=True)]


def uwb_filter() -> FusionFilter:
    return FusionFilter(FusionParams(use_gnss=False))


def test_every_attribute_of_the_filter_is_state_or_listed_with_a_reason():
    assert set(FusionFilter.__slots__) == {'state'} | set(FusionFilter.NOT_IN_SNAPSHOT)
    assert all(reason for reason in FusionFilter.NOT_IN_SNAPSHOT.values())
    f = uwb_filter()
    assert not hasattr(f, '__dict__')  # no attribute can be added outside the slots
    with pytest.raises(AttributeError):
        f.new_history = []  # type: ignore[attr-defined]
    for name in FusionFilter.__slots__:
        getattr(f, name)  # every slot is set by the constructor


def test_the_attributes_left_out_never_change_while_the_filter_runs():
    """What a snapshot leaves out is either cumulative (counts) or fixed at construction; the second kind
    must not change while messages are processed (else a restore would have to bring it back)."""
    f = uwb_filter()
    cumulative = {'reinits', '_counts', '_counts_tuple', 'uwb_noise', 'params', 'reference_provider'}
    fixed = {name: copy.deepcopy(getattr(f, name)) for name in FusionFilter.NOT_IN_SNAPSHOT if name not in cumulative}
    assert set(fixed) == {'gate', 'gate_3d', 'lever', 'lever_floats', 'anchor_registry', 'clock_q'}
    for m in ranges(0.0, 4.0):
        f.process_uwb(m)
    for name, before in fixed.items():
        now = getattr(f, name)
        if name == 'clock_q':
            np.testing.assert_array_equal(now(0.2), before(0.2))
        elif isinstance(before, dict):
            assert before.keys() == now.keys()
        else:
            np.testing.assert_array_equal(np.asarray(now, dtype=float), np.asarray(before, dtype=float))


def test_a_snapshot_is_a_deep_copy_of_every_state_field():
    f = uwb_filter()
    for m in ranges(0.0, 3.0):
        f.process_uwb(m)
    snap = f.snapshot()
    assert isinstance(snap, FilterState) and snap is not f.state
    for field in dataclasses.fields(FilterState):
        mine, copied = getattr(f.state, field.name), getattr(snap, field.name)
        if isinstance(mine, (list, dict, set, np.ndarray)) or hasattr(mine, '__dict__'):
            assert mine is not copied, field.name


def test_a_restored_filter_continues_exactly_as_the_original_did():
    first, rest = ranges(0.0, 3.0), ranges(3.0, 6.0, tag=(3.0, 1.0, 0.5))
    original = uwb_filter()
    for m in first:
        original.process_uwb(m)
    snap = original.snapshot()
    expected = [original.process_uwb(m) for m in rest]
    other = uwb_filter()  # a different filter restored to the snapshot: everything it needs is in the snapshot
    for m in ranges(0.0, 1.0, tag=(-2.0, 0.0, 1.0)):
        other.process_uwb(m)
    other.restore(snap)
    for m, want in zip(rest, expected, strict=True):
        got = other.process_uwb(m)
        np.testing.assert_array_equal(got.position_m, want.position_m)
        np.testing.assert_array_equal(got.covariance_pv, want.covariance_pv)
        assert got.stamp_ns == want.stamp_ns and got.mode == want.mode

"""The fusion node's diagnostics computed without ROS (fusion_diagnostics): the accounting, the levels and
eq. 4's C/N0 loss, on a real FusionCore fed through the admission."""

from __future__ import annotations

import numpy as np
import pytest

from gnss_common.jamming_weights import effective_cn0_dbhz
from gnss_common.observations import UwbRangeMeasurement
from rfi_node_common.diagnostics import ERROR, OK, WARN
from uwb_gnss_fusion.fusion_core import FusionCore
from uwb_gnss_fusion.fusion_diagnostics import FusionDiagnostics, accounting, jammer_cn0_loss_db
from uwb_gnss_fusion.fusion_node_params import FusionNodeParams
from uwb_gnss_fusion.input_admission import InputAdmission, Item

S = 1_000_000_000
T0 = 100 * S
TAG = np.array([1.0, 2.0, 0.5])
ANCHORS = {'n': np.array([0.0, 15.0, 2.0]), 'e': np.array([14.0, -3.0, 2.5]), 'w': np.array([-13.0, -4.0, 3.0])}


class Rig:
    """Admission -> core, as the node wires them, and the diagnostics of both."""

    def __init__(self, **params) -> None:
        self.params = FusionNodeParams(**{'use_gnss': False, **params})
        self.diag = FusionDiagnostics(self.params.diagnostics_window_s)
        self.admission = InputAdmission(0.0, 0.0, 120.0, 3, self._process, lambda: None, lambda *_: None,
                                        lambda: None)
        self.counts = self.admission.counts
        self.core = FusionCore(self.params, self.counts, self.admission.reasons, lambda *_: None)

    def _process(self, item: Item) -> None:
        out = self.core.process(item)
        if out is not None:
            self.diag.count_outcome(out, self.counts)
            self.diag.note_output(item.stamp_ns)

    def ranges(self, t0_s: float, t1_s: float) -> None:
        for k in range(round(t0_s * 30), round(t1_s * 30)):
            aid = 'new'[k % 3]
            a = ANCHORS[aid]
            self.counts['uwb_received'] += 1
            meas = UwbRangeMeasurement(T0 + round(k * S / 30), aid, a, 'map', float(np.linalg.norm(TAG - a)), 0.05)
            self.admission.offer(Item(meas.stamp_ns, 'uwb', meas))

    def report(self, stamp_s: float) -> tuple[bytes, str, bool, dict]:
        values = accounting(self.admission, self.core, {})
        level, text, warn = self.diag.report(T0 + round(stamp_s * S), self.params, values, self.counts, self.core,
                                             (0, 0, 0), 0)
        return level, text, warn, values


def test_starting_then_fusing_with_three_anchors_the_mirror_warned_once():
    rig = Rig()
    level, text, _, values = rig.report(0.0)
    assert (level, text) == (OK, 'starting: nothing processed yet') and values['accounting_ok']
    rig.ranges(0.0, 5.0)
    level, text, warn, values = rig.report(5.0)
    assert level == OK and text.startswith('fusing; three UWB anchors: mirror') and warn
    assert values['uwb_anchors_heard'] == 3 and values['uwb_mirror_ambiguous'] and values['accounting_ok']
    assert values['uwb_processed'] == values['uwb_received'] == 150 and values['initialized']
    assert not rig.report(6.0)[2]  # logged once


def test_no_solution_after_input_and_a_broken_accounting_are_errors():
    rig = Rig()
    rig.ranges(0.0, 0.05)  # two ranges: not enough to start
    level, text, _, _ = rig.report(0.1)
    assert (level, text) == (ERROR, 'no valid solution: filter not initialised')
    rig.counts['gnss_received'] += 1  # received, never rejected, processed or buffered
    assert rig.report(0.2)[:2] == (ERROR, 'input accounting does not add up')


def test_a_core_exception_is_an_error_until_the_next_report():
    rig = Rig()
    rig.ranges(0.0, 3.0)
    rig.counts['uwb_received'] += 1
    rig.admission.offer(Item(T0 + 4 * S, 'uwb', 'not a range'))  # the filter raises: counted
    assert rig.counts['core_exceptions'] == 1 and rig.admission.reasons['core_exception'] == 1
    assert rig.report(4.0)[:2] == (ERROR, '1 core or publishing exceptions since the last report')
    assert rig.report(5.0)[0] == OK


def test_a_reported_jammer_warns_by_its_c_n0_loss_of_eq_4():
    p = FusionNodeParams()
    expected = p.nominal_cn0_dbhz - float(effective_cn0_dbhz(p.nominal_cn0_dbhz, 15.0, p.jammer_quality_factor))
    assert jammer_cn0_loss_db(p, 15.0) == pytest.approx(expected) and 2.0 < expected < 4.0
    assert jammer_cn0_loss_db(p, float('nan')) == 0.0
    rig = Rig(warn_cn0_loss_db=1.0)
    rig.ranges(0.0, 3.0)
    rig.counts['jammer_received'] += 1
    rig.admission.offer(Item(T0 + round(3.01 * S), 'jammer', 15.0))
    rig.ranges(3.02, 4.0)
    level, text, _, values = rig.report(4.0)
    assert level == WARN and 'jammer reported: J/S 15.0 dB' in text
    assert values['jammer_cn0_loss_db'] == round(expected, 2) and values['jammer_processed'] == 1

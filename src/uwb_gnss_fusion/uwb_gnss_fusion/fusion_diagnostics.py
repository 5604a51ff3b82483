"""The fusion node's /diagnostics: its counters and the level (OK, WARN, ERROR) they set.

Pure core (no rclpy; the node builds the message with :func:`rfi_node_common.diagnostics.diagnostic_array`).

Values (:func:`accounting`): the node's counters, the filter's counters (``filter.<reason>``), the
subscriptions' counters (``input.<topic>.received`` / ``lost`` / ``middleware_lost`` / ``callback_errors``),
the current ``reorder_window_s`` and ``accounting_ok``: for GNSS, UWB and jammer messages, received ==
rejected by the node + processed + still buffered (lost messages never arrived: counted apart).

Levels (:meth:`FusionDiagnostics.report`), from fractions over ``diagnostics_window_s`` of stamp time:
ERROR when the output is not valid or the node is at fault: the accounting does not add up; the core, a
publisher or an input handler raised since the last report; the filter is not initialised although input
was processed (no solution is published; except OK "starting" while the first GNSS fix waits, up to ten
times ``divergence_fix_confirm_s``, for a second to confirm it); a non-finite estimate was suppressed within
the window. WARN when the inputs are degraded, the solution still published: more than
``warn_rejected_fraction`` of the GNSS epochs, UWB ranges (rejected by the node or by the filter), jammer
states or satellites rejected, more than ``warn_lost_fraction`` of the messages lost, a divergence (and
re-initialisation) within the window, GNSS excluded for spoofing, or a J/S costing more than
``warn_cn0_loss_db`` of C/N0 (Cao et al., eq. 4 at ``nominal_cn0_dbhz``: 3 dB at about 15 dB J/S). OK
otherwise, also before anything was processed ("starting"). Isolated rejections (a range gated now and
then on clean data) stay OK. With exactly three anchors heard within ``uwb_init_window_s`` and
``uwb_tag_side_of_anchor_plane`` 0, the OK message says that the mirror solution across their plane is
not ruled out (values ``uwb_anchors_heard``, ``uwb_mirror_ambiguous``; the node logs a warning once).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping
from typing import Any

from gnss_common.jamming_weights import effective_cn0_dbhz
from rfi_node_common.diagnostics import ERROR, OK, WARN, CountWindow, degraded_inputs, fraction

from .fusion_core import FusionCore
from .fusion_node_params import FusionNodeParams
from .fusion_output import FusionOutput
from .input_admission import KINDS, InputAdmission

MIRROR_WARNING = (
    'three UWB anchors heard and uwb_tag_side_of_anchor_plane is 0: the tag\'s mirror image across the '
    'anchors\' plane fits their ranges as well, and GNSS heights may not tell them apart; set the side '
    '(-1 below the plane, +1 above) if you know it (README, "UWB anchors")')
"""Logged once when the OK message first says that the mirror is not ruled out."""


def accounting(admission: InputAdmission, core: FusionCore, health_values: Mapping[str, object]) -> dict[str, object]:
    """Counters of the node, the core and the input subscriptions (``health_values``), and whether every
    input adds up: for each kind ``<kind>_received == <kind>_rejected + <kind>_processed + <kind>_buffered``
    (messages lost before the node, ``input.<topic>.lost`` / ``middleware_lost``, never arrived and are
    counted apart)."""
    counts = admission.counts
    values: dict[str, object] = dict(sorted(counts.items()))
    buffered = admission.buffered
    ok = True
    for kind in KINDS:
        values[f'{kind}_buffered'] = buffered[kind]
        ok = ok and counts[f'{kind}_received'] == (
            counts[f'{kind}_rejected'] + counts[f'{kind}_processed'] + buffered[kind])
    values['reorder_window_s'] = admission.reorder_window_s
    values.update({f'rejected.{k}': v for k, v in sorted(admission.reasons.items())})
    values.update({f'filter.{k}': v for k, v in sorted(core.filter_counts().items())})
    values.update(health_values)
    values['initialized'] = core.filter.initialized
    values['accounting_ok'] = ok
    return values


def jammer_cn0_loss_db(params: FusionNodeParams, jammer_to_signal_db: float) -> float:
    """C/N0 lost to the jammer in use (Cao et al., eq. 4, at ``nominal_cn0_dbhz`` with
    ``jammer_quality_factor``), dB; 0 when no J/S is in use (NaN)."""
    if not math.isfinite(jammer_to_signal_db):
        return 0.0
    return params.nominal_cn0_dbhz - float(effective_cn0_dbhz(params.nominal_cn0_dbhz, jammer_to_signal_db,
                                                              params.jammer_quality_factor))


class FusionDiagnostics:
    """What the levels remember between reports (module docstring).

    Args:
        window_s: ``diagnostics_window_s``.
    """

    def __init__(self, window_s: float) -> None:
        self.count_window = CountWindow(window_s)
        self.ever_initialized = False
        self.first_output_ns: int | None = None  # stamp of the first status published
        self.last_js_db = math.nan
        self.mirror_warned = False  # the three-anchor warning is logged once
        self._at_last_report = {'rejections': 0, 'faults': 0, 'handler_errors': 0, 'lost': 0}

    def count_outcome(self, out: FusionOutput, counts: Counter[str]) -> None:
        """Measurements used and rejected by the filter, divergences, J/S: what the levels need."""
        counts['satellites_used'] += out.satellites_used
        counts['satellites_rejected'] += out.satellites_rejected
        counts['uwb_used'] += out.uwb_used
        counts['uwb_rejected_by_filter'] += out.uwb_rejected
        counts['divergences'] += bool(out.diverged)
        self.last_js_db = out.jammer_to_signal_db
        if out.initialized:
            self.ever_initialized = True

    def note_output(self, stamp_ns: int) -> None:
        """A status is published for ``stamp_ns``."""
        if self.first_output_ns is None:
            self.first_output_ns = stamp_ns

    def confirming_first_fix(self, core: FusionCore, stamp_ns: int) -> bool:
        """The start-up wait of ``divergence_fix_confirm_s``: never initialised, a fix held for confirmation, and
        at most ten times that setting since the first status (later, no solution is an ERROR again: fixes that
        keep disagreeing under jamming)."""
        confirm_s = core.filter.params.divergence_fix_confirm_s
        return (not self.ever_initialized and confirm_s > 0 and core.filter.awaiting_fix_confirmation
                and self.first_output_ns is not None
                and stamp_ns - self.first_output_ns <= 10.0 * confirm_s * 1e9)

    def report(self, stamp_ns: int, params: FusionNodeParams, values: dict[str, Any], counts: Counter[str],
               core: FusionCore, messages: tuple[int, int, int], parameter_changes_refused: int
               ) -> tuple[bytes, str, bool]:
        """The level and message of a report at ``stamp_ns`` (the counts "since the last report" restart
        here), with ``values`` (:func:`accounting`) completed in place.

        Args:
            counts: the node's counters (:attr:`.input_admission.InputAdmission.counts`).
            messages: (received, lost, handler exceptions) of the input subscriptions, cumulative.

        Returns:
            (level, message, whether to log :data:`MIRROR_WARNING` now).
        """
        now = {'faults': counts['core_exceptions'] + counts['publish_exceptions'], 'handler_errors': messages[2]}
        new = {k: v - self._at_last_report.get(k, 0) for k, v in now.items()}
        self._at_last_report = now
        c = counts
        w = self.count_window.update(stamp_ns, {
            'gnss_received': c['gnss_received'], 'gnss_rejected': c['gnss_rejected'],
            'uwb_received': c['uwb_received'], 'uwb_rejected': c['uwb_rejected'] + c['uwb_rejected_by_filter'],
            'jammer_received': c['jammer_received'], 'jammer_rejected': c['jammer_rejected'],
            'satellites_used': c['satellites_used'], 'satellites_rejected': c['satellites_rejected'],
            'messages_received': messages[0], 'messages_lost': messages[1],
            'divergences': c['divergences'], 'suppressed': c['nonfinite_estimates_suppressed'],
        })
        checks = [('GNSS epochs rejected', w['gnss_rejected'], w['gnss_received']),
                  ('satellites rejected', w['satellites_rejected'], w['satellites_used'] + w['satellites_rejected']),
                  ('UWB ranges rejected', w['uwb_rejected'], w['uwb_received']),
                  ('jammer states rejected', w['jammer_rejected'], w['jammer_received'])]
        for what, n, total in checks:
            values[f'window.{what.replace(" ", "_").lower()}_fraction'] = round(fraction(n, total), 4)
        lost = ('messages lost', w['messages_lost'], w['messages_received'] + w['messages_lost'])
        values['window.messages_lost_fraction'] = round(fraction(lost[1], lost[2]), 4)
        values['window_s'] = params.diagnostics_window_s
        values['jammer_to_signal_db'] = self.last_js_db
        values['parameter_changes_refused'] = parameter_changes_refused
        exclusion, response, filt = core.exclusion, core.response, core.filter
        values['gnss_excluded_for_spoofing'] = exclusion.describe()
        # the side of the anchors' plane the filter holds while all GNSS is excluded (0: none held)
        values['anchor_plane_side_held'] = response.held_side if exclusion.all_gnss() else 0
        # the motion model the filter found (motion_detection): the static one, or the moving one
        values['motion_static'] = filt.motion_static
        values.update({f'integrity.{k}': v for k, v in exclusion.counts.items()})
        values.update({f'integrity.{k}': v for k, v in response.counts.items()})
        anchors = filt.uwb_anchors_heard(stamp_ns)
        mirror = anchors == 3 and filt.params.uwb_tag_side_of_anchor_plane == 0
        values['uwb_anchors_heard'] = anchors
        values['uwb_mirror_ambiguous'] = mirror
        warn_mirror = mirror and not self.mirror_warned
        self.mirror_warned = self.mirror_warned or mirror
        processed = c['gnss_processed'] + c['uwb_processed']
        if not values['accounting_ok']:
            level, text = ERROR, 'input accounting does not add up'
        elif new['faults']:
            level, text = ERROR, f'{new["faults"]} core or publishing exceptions since the last report'
        elif new['handler_errors']:
            level, text = ERROR, f'{new["handler_errors"]} input handler exceptions since the last report'
        elif not filt.initialized and processed and self.confirming_first_fix(core, stamp_ns):
            level, text = OK, 'starting: waiting for a second GNSS fix to confirm the first (divergence_fix_confirm_s)'
        elif not filt.initialized and processed:
            level, text = ERROR, ('no valid solution: filter not initialised' if not self.ever_initialized
                                  else 'no valid solution: filter reset, not re-initialised yet')
        elif w['suppressed']:
            level, text = ERROR, (f'{w["suppressed"]} non-finite estimates suppressed in the last '
                                  f'{params.diagnostics_window_s:g} s')
        elif not processed:
            level, text = OK, 'starting: nothing processed yet'
        else:
            level, text = self._degraded_level(params, values, checks, lost, w['divergences'], core)
        if mirror and level == OK and text == 'fusing':
            text = 'fusing; three UWB anchors: mirror across their plane not ruled out (uwb_tag_side_of_anchor_plane)'
        return level, text, warn_mirror

    def _degraded_level(self, params: FusionNodeParams, values: dict[str, Any], checks: list[tuple[str, int, int]],
                        lost: tuple[str, int, int], divergences: int, core: FusionCore) -> tuple[bytes, str]:
        """WARN with what is degraded, or OK ("fusing")."""
        degraded = (degraded_inputs(checks, params.warn_rejected_fraction)
                    + degraded_inputs([lost], params.warn_lost_fraction))
        if divergences:
            degraded.append(f'filter diverged {divergences} times')
        if core.exclusion.active:
            degraded.append(f'spoofing: {core.exclusion.describe()} excluded (gnss_integrity)')
        loss_db = jammer_cn0_loss_db(params, self.last_js_db)
        values['jammer_cn0_loss_db'] = round(loss_db, 2)
        if loss_db > params.warn_cn0_loss_db:
            degraded.append(f'jammer reported: J/S {self.last_js_db:.1f} dB costs {loss_db:.1f} dB of C/N0')
        if degraded:
            return WARN, f'inputs degraded (window {params.diagnostics_window_s:g} s): ' + '; '.join(degraded)
        return OK, 'fusing'

"""The fusion node's core: the filter with what surrounds it, fed one admitted input at a time.

Pure core (no rclpy). :class:`FusionCore` holds the :class:`.fusion_filter.FusionFilter` (the
tightly-coupled CKF of Cao et al.), the spoofing response (:class:`.spoofing_response.SpoofingResponse`:
GNSS excluded on a /gnss/integrity alarm, roll-back, re-anchoring on UWB) and the single-point reference
(:class:`.spp_reference.SppReferenceCache`). :meth:`FusionCore.process` takes the items the admission
(:class:`.input_admission.InputAdmission`) releases in stamp order and returns the filter's output of a
measurement.

Jammer information. A /rfi/jammer_state J/S goes to the filter's measurement weighting (Cao et al.,
eq. 4) in stamp order with the measurements (the node admits it: :func:`.input_admission.admit_jammer_state`);
a /gnss/integrity verdict's C/N0-based J/S is used where no SDR J/S is fresher than
``jammer_info_timeout_s``.

SPP. The filter re-initialises after a divergence from a single-point fix
(:class:`gnss_common.spp.SinglePointPositioner`, ``use_spp_reference``): the most recent valid
(RAIM-consistent) fix no older than ``reference_max_age_s``. The core keeps the GNSS epochs of that
window and solves them only when the filter asks (``FusionFilter(reference_provider=...)``), newest
first until one is valid; a solved epoch is not solved again. The reference is the one an SPP run on
every epoch would have supplied (up to the solver's convergence tolerance, as its iteration starts from
the last valid fix), at a fraction of the cost: SPP is not published, and solving every 5 Hz epoch took
about 15% of a replay. ``spp_valid`` / ``spp_invalid`` count the epochs solved. The first
initialisation is the filter's own (robust snapshot fix of the first epoch with ``min_satellites_init``
satellites, or UWB multilateration from three anchors).

A filter exception on an input (it should not happen; the filter counts bad input itself) is caught,
counted (``core_exception``) and logged; the next input gets its turn.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from collections.abc import Callable

from gnss_common.spp import SinglePointPositioner

from .fusion_filter import FusionFilter, FusionOutput
from .fusion_node_params import FusionNodeParams
from .fusion_params import FusionParams
from .input_admission import Item
from .integrity_policy import IntegrityVerdict, integrity_jammer_to_signal
from .output_messages import reason_lists
from .spoofing_response import SpoofingResponse
from .spp_reference import SppReferenceCache

_NS = 1_000_000_000


class FusionCore:
    """The filter, the spoofing response and the SPP reference (module docstring).

    Args:
        params: the node's parameters.
        counts, reasons: the node's counters (:attr:`.input_admission.InputAdmission.counts`, ``reasons``),
            to which the core adds ``<kind>_processed``, ``core_exceptions``, ``spp_valid`` ...
        log: ``log(text, level)`` with level ``'info'``, ``'warn'``, ``'error'`` (errors are throttled by the node).
    """

    def __init__(self, params: FusionNodeParams, counts: Counter[str], reasons: Counter[str],
                 log: Callable[[str, str], None]) -> None:
        self.params = params
        self.counts = counts
        self.reasons = reasons
        self._log = log
        self.spp = SinglePointPositioner()
        self.spp_cache = SppReferenceCache(self.spp, params.reference_max_age_s, self._count_spp)
        self.response = SpoofingResponse(params.integrity_readmit_clean_s, params.act_on_integrity,
                                         params.integrity_rollback_s)
        self.exclusion = self.response.exclusion
        self._retired_filter_counts: Counter[str] = Counter()
        self.filter = self._new_filter()
        self.sdr_js_ns: int | None = None  # stamp of the last SDR J/S processed (it takes precedence)
        self.excluded_now = 0  # satellites excluded from the epoch being published
        self._reasons_cache: tuple[tuple, dict[str, int], tuple[list[str], list[int]]] | None = None

    def _new_filter(self) -> FusionFilter:
        use_spp = self.params.use_spp_reference and self.params.use_gnss
        provider = self.spp_cache.reference if use_spp else None
        return FusionFilter(self.filter_params(), reference_provider=provider)

    def filter_params(self) -> FusionParams:
        """The filter's parameters: the node's, as :class:`SpoofingResponse` changes them while all GNSS is
        excluded for spoofing."""
        return self.response.filter_params(self.params.fusion_params())

    def _count_spp(self, valid: bool) -> None:
        self.counts['spp_valid' if valid else 'spp_invalid'] += 1

    def restart(self) -> None:
        """A fresh filter (a confirmed stamp jump); the old filter's counts are kept (:meth:`filter_counts`)."""
        self._retired_filter_counts.update(self.filter.rejection_counts)
        self.filter = self._new_filter()
        self.spp_cache.clear()
        self.response.reset()

    def filter_counts(self) -> dict[str, int]:
        """The filter's cumulative counts (including filters replaced after a stamp jump)."""
        total = Counter(self._retired_filter_counts)
        total.update(self.filter.rejection_counts)
        return dict(total)

    def rejection_reasons(self) -> dict[str, int]:
        """Cumulative reasons and counts of the node (``reasons``) and of the filter, merged."""
        total = Counter(self.filter_counts())
        total.update({k: v for k, v in self.reasons.items() if v})
        return dict(total)

    def status_reasons(self, restarts: int) -> tuple[dict[str, int], tuple[list[str], list[int]]]:
        """(:meth:`rejection_reasons`, its sorted names and clamped counts for FusionStatus), recomputed only
        when a count changed: the key holds the filter's counts, the node's reasons and the number of
        ``restarts`` (which retire filter counts)."""
        key = (self.filter.rejection_counts_key(), tuple(self.reasons.items()), restarts)
        cache = self._reasons_cache
        if cache is None or cache[0] != key:
            reasons = self.rejection_reasons()
            cache = self._reasons_cache = (key, reasons, reason_lists(reasons))
        return cache[1], cache[2]

    def set_params(self, new: FusionNodeParams) -> None:
        """New node parameters (a runtime change): the filter reads them from its next message on."""
        self.params = new
        if self.response.set_acting(new.act_on_integrity, self.filter, new.fusion_params()):
            self._log('act_on_integrity switched off: the GNSS excluded for spoofing is readmitted', 'warn')
        self.filter.params = self.filter_params()

    def process(self, item: Item) -> FusionOutput | None:
        """Apply one released input: the filter's output of a GNSS epoch or a UWB range, None for a J/S, a
        verdict, an epoch excluded for spoofing or a filter exception (counted)."""
        try:
            out = self._apply(item)
        except Exception as err:
            # The filter validates its input and counts rejections; an exception here is a filter bug.
            self.counts[f'{item.kind}_processed'] += 1
            self.counts['core_exceptions'] += 1
            self.reasons['core_exception'] += 1
            self._log(f'fusion core raised on a {item.kind} message at {item.stamp_ns} ns: '
                      f'{type(err).__name__}: {err}', 'error')
            return None
        self.counts[f'{item.kind}_processed'] += 1
        return out

    def _apply(self, item: Item) -> FusionOutput | None:
        if item.kind == 'jammer':
            self.filter.set_jammer_to_signal(item.stamp_ns, item.payload)
            self.sdr_js_ns = item.stamp_ns
            return None
        if item.kind == 'integrity':
            self._apply_integrity(item.payload)
            return None
        if item.kind == 'gnss':
            epoch, excluded = self.exclusion.filter_epoch(item.payload)
            self.excluded_now = excluded
            self.counts['satellites_excluded_spoofing'] += excluded
            if epoch is None:  # all GNSS excluded for spoofing: counted, never applied
                return None
            if self.params.use_spp_reference and self.params.use_gnss:
                self.spp_cache.add(epoch)
            out = self.filter.process_gnss(epoch)
            if item.dropped_satellites:  # dropped by the node's checks: rejected satellites too
                out = dataclasses.replace(out, satellites_rejected=out.satellites_rejected + item.dropped_satellites)
        else:
            self.excluded_now = 0
            out = self.filter.process_uwb(item.payload)
        self.response.after_message(item.stamp_ns, self.filter, item.payload if item.kind == 'uwb' else None)
        return out

    def _apply_integrity(self, verdict: IntegrityVerdict) -> None:
        """Exclusion and readmission of GNSS (logged), and the C/N0 J/S where no SDR J/S is fresh."""
        done = self.response.apply(verdict, self.filter, self.params.fusion_params())
        if done.change == 'excluded':
            self.spp_cache.clear()  # the SPP reference must not bring the spoofed position back
            how = (f'went back to the filter of {done.rolled_back_to_ns} ns (before the first alarm) and applied '
                   f'{done.ranges_replayed} UWB ranges again' if done.rolled_back_to_ns is not None else
                   're-anchored on UWB' if done.reanchored else 'kept the state (fewer than three anchors)')
            self._log(f'spoofing detected at {verdict.stamp_ns} ns: excluding '
                      f'{self.exclusion.describe()} from the fusion (gnss_integrity); {how}', 'warn')
        elif done.change == 'readmitted':
            self._log(f'GNSS readmitted at {verdict.stamp_ns} ns after '
                      f'{self.params.integrity_readmit_clean_s:g} s without spoofing', 'warn')
        if not self.params.act_on_integrity:
            return
        js = integrity_jammer_to_signal(verdict)
        timeout_ns = self.filter.params.jammer_info_timeout_s * _NS
        sdr_fresh = self.sdr_js_ns is not None and verdict.stamp_ns - self.sdr_js_ns <= timeout_ns
        if js is not None and not sdr_fresh:
            self.filter.set_jammer_to_signal(verdict.stamp_ns, js)
            self.counts['integrity_js_applied'] += 1

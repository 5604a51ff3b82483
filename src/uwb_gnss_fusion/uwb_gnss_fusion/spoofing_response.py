"""What the fusion does with gnss_integrity's verdicts: one implementation for the node and the benchmarks.

Pure core (no rclpy). :class:`SpoofingResponse` holds the exclusion state machine
(:class:`.integrity_policy.GnssExclusion`) and acts on a :class:`.fusion_filter.FusionFilter`:

* at an exclusion the state the spoofer dragged before the detection is dropped. With all GNSS
  excluded the filter goes back to its copy of ``rollback_s`` before the episode's first alarm and
  applies the UWB ranges since then again (:mod:`.rollback`); without such a copy (off, or an alarm
  older than the history) it re-anchors on UWB multilateration (three or more anchors,
  :meth:`FusionFilter.reanchor_on_uwb`);
* while all GNSS is excluded the filter runs as without GNSS (``use_gnss`` false: the rules of UWB
  alone) on the side of three coplanar anchors' plane that GNSS held the tag on (unless
  ``uwb_tag_side_of_anchor_plane`` is set): three anchors alone cannot tell the tag from its mirror,
  and on bags/spoofed the state drifted there in 1-2 s (1.3 m up, 0.12 m horizontal);
* at the readmission the caller's parameters come back.

The caller clears its own SPP reference cache at an exclusion (the SPP must not bring the spoofed
position back) and keeps feeding :meth:`after_message` with what the filter processed.
"""

from __future__ import annotations

import dataclasses

from .fusion_params import FusionParams
from .integrity_policy import GnssExclusion, IntegrityVerdict
from .rollback import RollbackHistory

NS_PER_S = 1_000_000_000
ROLLBACK_PERIOD_S = 1.0
"""A copy of the filter at most this often for ``rollback_s``, s of stamp time."""
ROLLBACK_HISTORY_S = 60.0
"""How far back the copies reach, s: a first alarm older than this at the detection re-anchors instead."""


@dataclasses.dataclass
class ResponseOutcome:
    """What one verdict did.

    Attributes:
        change: ``GnssExclusion.update``'s answer: "excluded", "readmitted" or None.
        rolled_back_to_ns: the stamp of the filter copy gone back to (None: no roll-back).
        ranges_replayed: UWB ranges applied again after the roll-back.
        reanchored: the filter re-anchored on UWB multilateration.
    """

    change: str | None = None
    rolled_back_to_ns: int | None = None
    ranges_replayed: int = 0
    reanchored: bool = False


class SpoofingResponse:
    """The exclusion, roll-back or re-anchor, and the filter's parameters while GNSS is out (module docstring).

    Args:
        readmit_clean_s: ``integrity_readmit_clean_s`` (hysteresis of the readmission), s.
        act: ``act_on_integrity`` (False: verdicts counted, nothing excluded).
        rollback_s: ``integrity_rollback_s``: how long before the first alarm to go back to, s (0: never).
    """

    def __init__(self, readmit_clean_s: float, act: bool, rollback_s: float) -> None:
        self.exclusion = GnssExclusion(readmit_clean_s, act)
        self.rollback_s = float(rollback_s)
        self.held_side = 0  # the side of three anchors' plane kept while all GNSS is excluded
        self.history = RollbackHistory(ROLLBACK_PERIOD_S, ROLLBACK_HISTORY_S)
        self.counts = {"rollbacks": 0, "rollbacks_unavailable": 0, "reanchors": 0}

    @property
    def keeps_history(self) -> bool:
        return self.exclusion.act_on_spoofing and self.rollback_s > 0.0

    def reset(self) -> None:
        """A restart of the input: the history is of another time line."""
        self.history.clear()

    def set_acting(self, act: bool, filt, base: FusionParams) -> bool:
        """``act_on_integrity`` changed while running: switched off, whatever was excluded is readmitted at
        once (returns True then) and the filter gets ``base`` back."""
        self.exclusion.act_on_spoofing = bool(act)
        readmitted = not act and self.exclusion.clear()
        if not act:
            self.history.clear()
        filt.params = self.filter_params(base)
        return readmitted

    def after_message(self, stamp_ns: int, filt, uwb_range=None) -> None:
        """The filter has processed a message stamped ``stamp_ns`` (``uwb_range``: it was this range)."""
        if not self.keeps_history:
            return
        if uwb_range is not None:
            self.history.add_range(uwb_range)
        self.history.note(stamp_ns, filt)

    def filter_params(self, base: FusionParams) -> FusionParams:
        """The filter's parameters: ``base`` (the caller's), or, while all GNSS is excluded, ``base``
        without GNSS on the held side of the anchors' plane (module docstring)."""
        if not self.exclusion.all_gnss():
            return base
        side = base.uwb_tag_side_of_anchor_plane or self.held_side
        return dataclasses.replace(base, use_gnss=False, uwb_tag_side_of_anchor_plane=side)

    def apply(self, verdict: IntegrityVerdict, filt, base: FusionParams) -> ResponseOutcome:
        """One verdict, in stamp order before the GNSS epoch of the same stamp; ``filt`` is changed in place
        (state, parameters) and ``base`` is the caller's parameters for the filter."""
        out = ResponseOutcome(self.exclusion.update(verdict))
        if out.change == "excluded":
            if self.exclusion.all_gnss():
                self._roll_back(verdict, filt, base, out)
            if out.rolled_back_to_ns is None:
                self.held_side = filt.side_of_anchor_plane(verdict.stamp_ns)
                out.reanchored = bool(filt.reanchor_on_uwb(verdict.stamp_ns))
                self.counts["reanchors"] += int(out.reanchored)
            filt.params = self.filter_params(base)
        elif out.change == "readmitted":
            filt.params = self.filter_params(base)
        return out

    def _roll_back(self, verdict: IntegrityVerdict, filt, base: FusionParams, out: ResponseOutcome) -> None:
        if not self.keeps_history or verdict.first_alarm_ns <= 0:
            return
        before_ns = verdict.first_alarm_ns - round(self.rollback_s * NS_PER_S)
        replay = self.history.roll_back(filt, before_ns)
        if replay is None:
            self.counts["rollbacks_unavailable"] += 1
            return
        out.rolled_back_to_ns = filt.time_ns
        self.held_side = filt.side_of_anchor_plane(filt.time_ns)
        filt.params = self.filter_params(base)
        for meas in replay:
            filt.process_uwb(meas)
        out.ranges_replayed = len(replay)
        self.counts["rollbacks"] += 1

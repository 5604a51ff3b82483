"""What the "stft" estimator remembers of a sweep across blocks (pure module, no ROS).

A weak block's own sweep period is published only when it is confirmed (``PERIOD_CONFIRM_MARGIN_DB``): by the period
the evidence over blocks found (integration module), else by a recent block's own; a block period that is a multiple
of the window's is a sub-harmonic lock (``SUBHARMONIC_TOLERANCE``). The sample-resolution hook test of a saw-tooth
runs on at most one block per ``HOOK_RECHECK_S`` of a tracked chirp; the blocks in between keep its verdict.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque

from rfi_monitor import ridge as rg

HOOK_RECHECK_S = 0.1
"""While the "stft" estimator tracks a chirp, the sample-resolution hook test of a saw-tooth (``ridge.fine_profile``:
0.3-1.4 ms per block, as much as the rest of a tracking block's analysis) runs on at most one block per this many
seconds of stamps; the blocks in between keep its verdict for a saw-tooth of the same period (within
``SUBHARMONIC_TOLERANCE``): a jammer's sweep shape does not change within a tenth of a second, and a hook is a
property of the sweep, not of a block. Any block that starts a track, and any change of period, is tested again."""
SUBHARMONIC_TOLERANCE = 0.02
"""A block's ridge period within this fraction of an integer multiple (>= 3; 2 for a block below the detection J/N)
of the period the evidence over blocks found is that multiple (a sub-harmonic lock), not a second jammer."""


PERIOD_CONFIRM_MARGIN_DB = 3.0
"""A block's own sweep period is published unconfirmed only from ``detect_jn_db`` + this J/N. Below, it must agree
with the evidence over blocks' period when there is one, else, from ``detect_jn_db`` on, with one of the last
``PERIOD_HISTORY`` blocks' own periods (within ``PERIOD_AGREEMENT``; consecutive weak blocks can agree on twice the
period, so the window's period, when there is one, decides).
Measured (3 rates x 6 periods x 3 J/N, saw-tooths, I/Q): before, 14 of 2,036 published periods were 1.1-100 % off, all
from single blocks at J/N -5 dB, just above the detection level, mostly isolated among right ones; after, 0 of 2,002
(the window's period agreeing within PERIOD_AGREEMENT, not SUBHARMONIC_TOLERANCE: 2 of 2,004, 1.1 and 1.3 % off)."""
PERIOD_HISTORY = 4
"""Recent blocks' own periods kept for the confirmation above (stamped within PERIOD_HISTORY_S)."""
PERIOD_HISTORY_S = 1.0
"""How old a recent block's period may be to confirm another's, s of stamps."""
PERIOD_AGREEMENT = 0.01
"""Relative agreement of two blocks' own periods that confirms them (the issue's 1 % goal)."""


def agrees(period: float, base: float, tolerance: float = SUBHARMONIC_TOLERANCE) -> bool:
    """Whether period is within tolerance (relative) of base (False when either is not finite)."""
    ok = math.isfinite(period) and math.isfinite(base) and base > 0
    return ok and abs(period - base) <= tolerance * base


def multiple(period: float, base: float) -> int:
    """m if period is an integer multiple m >= 2 of base within SUBHARMONIC_TOLERANCE (relative), else 0."""
    if not (math.isfinite(period) and math.isfinite(base) and base > 0):
        return 0
    m = round(period / base)
    return m if m >= 2 and abs(period - m * base) <= SUBHARMONIC_TOLERANCE * m * base else 0


class SweepMemory:
    """The window's sweep period, the recent blocks' own periods and the last hook verdict (module docstring).

    Args:
        window_s: the integration window, s (the window's period is valid for this long after its decision).
    """

    def __init__(self, window_s: float) -> None:
        self.window_s = float(window_s)
        self.integrated: tuple[float, int] | None = None
        """(period in samples, stamp in ns) of the evidence over blocks' last CHIRP decision with a period."""
        self._block_periods: deque[tuple[float, int]] = deque(maxlen=PERIOD_HISTORY)
        self._hook_memory: tuple[float, bool, int] | None = None   # (period, hooked, stamp) of the last hook test

    def forget(self) -> None:
        """A new stream: nothing carries over."""
        self._hook_memory = None
        self.integrated = None
        self._block_periods.clear()

    def add_block_period(self, period: float, stamp_ns: int) -> None:
        """A block's own sweep period, samples."""
        self._block_periods.append((float(period), int(stamp_ns)))

    def integrated_period(self, stamp_ns: int) -> float:
        """The sweep period (samples) of the evidence over blocks' last CHIRP decision, if it was made within the
        integration window before stamp_ns; else NaN."""
        if self.integrated is None:
            return math.nan
        per, at = self.integrated
        return per if 0 <= stamp_ns - at <= self.window_s * 1e9 else math.nan

    def period_confirmed(self, period: float, stamp_ns: int, detected: bool) -> bool:
        """Whether a weak block's own sweep period is confirmed (PERIOD_CONFIRM_MARGIN_DB): by the evidence over blocks'
        period when there is one within its window (it is the authority: consecutive weak blocks can agree on twice
        the period); else, for a block at or above the detection J/N (detected), by one of the last PERIOD_HISTORY
        blocks' own periods stamped within PERIOD_HISTORY_S, within PERIOD_AGREEMENT."""
        p_int = self.integrated_period(stamp_ns)
        if math.isfinite(p_int):
            return agrees(period, p_int, PERIOD_AGREEMENT)
        horizon = PERIOD_HISTORY_S * 1e9
        return detected and any(0 < stamp_ns - at <= horizon and agrees(period, p, PERIOD_AGREEMENT)
                                for p, at in self._block_periods)

    def hook_test_due(self, stamp_ns: int, chirp: bool) -> bool:
        """Whether this block's analysis runs the sample-resolution hook test (``HOOK_RECHECK_S``)."""
        mem = self._hook_memory
        return not (chirp and mem is not None and 0 <= stamp_ns - mem[2] < HOOK_RECHECK_S * 1e9)

    def remember_hook(self, rr: rg.RidgeResult, stamp_ns: int) -> rg.RidgeResult:
        """Keep the verdict of a block whose analysis ran the hook test; give it to a saw-tooth of the same period
        analysed without the test (``HOOK_RECHECK_S``)."""
        if rr.hook_checked:
            self._hook_memory = (rr.period_samples, rr.shape == rg.HOOKED_SAWTOOTH, int(stamp_ns))
            return rr
        mem = self._hook_memory
        if (mem is not None and mem[1] and rr.shape in (rg.SAWTOOTH_UP, rg.SAWTOOTH_DOWN)
                and agrees(rr.period_samples, mem[0])):
            return dataclasses.replace(rr, shape=rg.HOOKED_SAWTOOTH)
        return rr

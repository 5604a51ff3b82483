"""Named layouts of the fused loop's state (``tracker.track_block``): one place per state variable.

The compiled loop keeps its scalar state in packed arrays (numba loads them into local variables
once per block and stores them back at its end). Each packed array has one layout here, an
``IntEnum`` whose members are the slot indices (numba folds them to constants, so the compiled code
is the same as with integer literals):

* :class:`MonitorFloat` (``TrackerState.mst``, float64) and :class:`MonitorInt`
  (``TrackerState.mist``, int64): the measurement window, running power, reset lattice, LPD
  accumulators and tracking mode of the fused loop;
* :class:`MonitorParam` (float64, built by the monitor once per kind of input): its switches and
  gains.

The filter's and the sweep-period estimator's packed states keep their layouts in their own modules
(``tracking_filters.FilterFloat`` / ``FilterInt``, ``sweep_period.SweepFloat`` / ``SweepInt`` /
``SweepParam``), which run alone too.
:class:`TrackerState` names every array of the loop's state and :class:`TraceBuffers` its per-sample
outputs; ``track_block`` unpacks both once, at the call of the compiled kernel, so that its
arguments are never listed by a caller. A new scalar state variable is one new enum member (and its
initial value in :func:`new_tracker_state` if that is not 0).

After editing this module delete the numba cache of ``tracker`` (``rfi_monitor/__pycache__/*.nbi``,
``*.nbc``): the cached kernel holds the old slot indices as constants, and numba invalidates a cache
only when the cached function's own file changes.
"""

from __future__ import annotations

import math
from enum import IntEnum
from typing import NamedTuple

import numpy as np

from rfi_monitor.if_measurement import N_STATUS
from rfi_monitor.sweep_period import AR_ORDER, LPD_LAG, N_SFSTATE, N_SISTATE, PEAK_RING

CHUNK = 16
"""Length of the aligned chunks whose measurements are computed ahead in a vectorised loop (power of two)."""
DF_LAG = 2 * CHUNK
"""Samples by which the df used in the chirp correction lags the filter (measured one chunk ahead)."""
Z_RING = 64
"""Recent measurements kept for the sweep-start fit (power of two, > 2 * max refine window)."""
DEC_HISTORY = 4096
"""Decimated measurements kept for the block-level periodicity detector (power of two)."""


class MonitorFloat(IntEnum):
    """Slots of ``TrackerState.mst`` (float64). Frequencies in cycles/sample, times in samples."""

    RE2 = 0        # the two samples carried to the next block (real part), oldest first
    IM2 = 1        # (imaginary part, complex input)
    RE1 = 2
    IM1 = 3
    POW = 4        # running power P of the near-zero guard and the noise compensation, sample units^2
    NEXT = 5       # next predicted sweep start (lattice), absolute sample; < 0: no lattice
    F0 = 6         # filter frequency just after the last sweep reset (NaN before the first)
    P11_0 = 7      # its variance P(1,1)
    TLAT = 8       # lattice period, samples
    PPRED = 9      # predicted start of the current sweep
    ZG = 10        # LPD recursion output (eq. 23)
    ACC = 11       # LPD output summed over the current decimation block
    ZACC = 12      # measurements summed over the current decimation block
    FLOOR = 13     # calibrated noise floor N (input, set by the monitor; 0 unknown)
    L11 = 14       # lattice filter covariance (start, period), samples^2
    L12 = 15
    L22 = 16
    IKAP = 17      # noise compensation factor 1 / kappa of the current aligned window


class MonitorInt(IntEnum):
    """Slots of ``TrackerState.mist`` (int64)."""

    NBUF = 0           # samples of the three-sample window filled at stream start (0..2)
    LAST_START = 1     # sample of the last sweep reset
    NRESETS = 2        # sweep resets so far
    STARTED = 3        # not used by the loop (carried unchanged)
    NMEAS = 4          # measurements so far
    FITAT = 5          # sample at which the next sweep-start fit runs; -1 none
    MISSES = 6         # consecutive failed sweep-start fits
    DECN = 7           # samples in the current decimation block
    LATSRC = 8         # lattice source: LAT_NONE, LAT_LPD, LAT_COARSE
    NDEC = 9           # decimated measurements written to zdec
    NFIT = 10          # successful sweep-start fits so far
    ZPOS = 11          # position in the LPD delay line (0 .. 2 LPD_LAG - 1)
    NLEV = 12          # LPD peaks queued in lev
    NCONS = 13         # consecutive successful fits (tracking mode)
    TRACK = 14         # tracking mode requested (1) by the fits
    SWAT = 15          # first sample of the aligned window from which SWMODE applies; -1 none
    SWMODE = 16        # tracking mode decided at the end of the last window
    LPDOFF = 17        # the LPD / AR(10) / peak pass is suspended (1)
    NSUSP = 18         # suspensions of the period search so far


class MonitorParam(IntEnum):
    """Slots of the packed monitor parameters (float64; booleans 0 / 1)."""

    CHIRP_CORR = 0     # chirp correction of eq. 10 (real input)
    MIN_ABS = 1        # near-zero guard ratio
    DOMAIN = 2         # arccos domain margin
    POW_LAMBDA = 3     # running power forgetting factor, 1 / time constant
    RESET = 4          # reset at the predicted sweep starts (eq. 21-22)
    PHASE_GAIN = 5     # paper lattice: phase correction gain
    WRAP = 6           # measurements wrap (complex input)
    MAX_DF = 7         # clamp of |df| in the chirp correction, cycles/sample^2
    REFINE_W = 8       # half-window of the sweep-start step fit; 0: paper lattice
    LAT_DRIFT = 9      # relative random walk of the lattice period per sweep
    NOISE_COMP = 10    # noise compensation (real input)
    RESET_CROSS = 11   # exact covariance of eq. 21 at a reset
    CONFIRM = 12       # fits in a row that start the tracking mode; 0 never


LAT_NONE, LAT_LPD, LAT_COARSE = 0, 1, 2
"""Lattice sources (``MonitorInt.LATSRC``): none, the LPD period lock, the block-level detector."""


class TrackerState(NamedTuple):
    """All per-sample state of the fused loop (arrays, mutated in place by ``track_block``).

    Field order is the compiled kernel's argument order (tested).
    """

    fst: np.ndarray        # filter floats (tracking_filters.FilterFloat)
    ist: np.ndarray        # filter ints (tracking_filters.FilterInt)
    ring: np.ndarray       # filter innovation window
    sf: np.ndarray         # sweep-period floats (sweep_period.SweepFloat)
    si: np.ndarray         # sweep-period ints (sweep_period.SweepInt)
    zhist: np.ndarray      # LPD delay line, LPD_LAG
    gam: np.ndarray        # AR(10) coefficients
    pmat: np.ndarray       # AR(10) covariance (low-rank form)
    hist: np.ndarray       # AR(10) regressor history
    peaks: np.ndarray      # recent peak times, PEAK_RING
    mst: np.ndarray        # MonitorFloat
    mist: np.ndarray       # MonitorInt
    counters: np.ndarray   # measurement status counts, if_measurement.N_STATUS
    dfring: np.ndarray     # df of the last DF_LAG samples (chirp correction)
    zring: np.ndarray      # last Z_RING measurements (sweep-start fit)
    zdec: np.ndarray       # decimated measurements for the periodicity detector, DEC_HISTORY
    lev: np.ndarray        # LPD peaks queued for the lattice, 4 values each
    pdev: np.ndarray       # power deviations of the current aligned window, CHUNK


class TraceBuffers(NamedTuple):
    """Per-sample outputs of ``track_block`` (each of the block's length)."""

    idx: np.ndarray        # int64 absolute sample index
    z: np.ndarray
    f: np.ndarray
    df: np.ndarray
    p11: np.ndarray
    zar: np.ndarray
    reset: np.ndarray      # bool


def new_trace_buffers(n: int) -> TraceBuffers:
    """Uninitialised output buffers for n samples."""
    return TraceBuffers(np.empty(n, dtype=np.int64), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
                        np.empty(n), np.empty(n, dtype=np.bool_))


def new_tracker_state(fst: np.ndarray, ist: np.ndarray, ring: np.ndarray, sp_state: tuple) -> TrackerState:
    """The state at stream start, from the filter's (``TrackingFilterParams.initial_state``) and the
    sweep-period estimator's (``sweep_period.initial_state``) initial states."""
    sf, si, zhist, gam, pmat, hist, peaks = sp_state
    assert sf.size == N_SFSTATE and si.size == N_SISTATE
    assert zhist.size == LPD_LAG and gam.size == AR_ORDER and peaks.size == PEAK_RING
    mst = np.zeros(len(MonitorFloat))
    mst[MonitorFloat.NEXT] = -1.0
    mst[MonitorFloat.F0] = math.nan
    mst[MonitorFloat.P11_0] = math.nan
    mst[MonitorFloat.TLAT] = math.nan
    mst[MonitorFloat.IKAP] = 1.0
    mist = np.zeros(len(MonitorInt), dtype=np.int64)
    mist[MonitorInt.FITAT] = -1
    mist[MonitorInt.SWAT] = -1
    return TrackerState(fst, ist, ring, sf, si, zhist, gam, pmat, hist, peaks, mst, mist,
                        np.zeros(N_STATUS, dtype=np.int64), np.zeros(DF_LAG), np.zeros(Z_RING),
                        np.zeros(DEC_HISTORY), np.zeros(4 * CHUNK), np.zeros(CHUNK))

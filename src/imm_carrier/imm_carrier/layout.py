"""Named layouts of the packed arrays of the compiled IMM, PLL and per-channel tracker kernels.

Each packed array has one layout here, an ``IntEnum`` whose members are the slot indices (numba folds
them to constants, so the compiled code is the same as with integer literals). A new state variable,
output, counter or batch column is one new member:

* :class:`ImmState` / :class:`ImmOut`: the IMM filter's state vector and step output (``imm.imm_step``);
* :class:`PllState` / :class:`PllOut`: the Costas PLL's state vector and step output (``pll.pll_step``);
* :class:`Counter`: the tracker's counters (``CarrierTracker.counters`` keys are the lower-case names);
* :class:`BatchColumn`: the columns of ``CarrierPhaseBatch.values`` (the fields of rfi_msgs/CarrierPhase);
* :class:`KernelConfig`: the tracker kernel's float configuration vector.

After editing this module delete the numba caches of imm, pll and tracker
(``imm_carrier/__pycache__/*.nbi``, ``*.nbc``): the cached kernels hold the slot indices as
constants, and numba invalidates a cache only when the cached function's own file changes.
"""

from __future__ import annotations

from enum import IntEnum


class ImmState(IntEnum):
    """First slots of the blocks of the IMM state vector (float64[IMM_STATE_LEN]); rad, rad/s."""

    X1 = 0         # mode 1 (data bit +1) state [phase, angular frequency], 2 slots
    P1 = 2         # mode 1 covariance [P11, P12, P22], 3 slots
    X2 = 5         # mode 2 (data bit -1) state, 2 slots
    P2 = 7         # mode 2 covariance, 3 slots
    LOGMU = 10     # natural logarithms of the mode probabilities [log mu_1, log mu_2], 2 slots
    SAT = 12       # accumulated predicted satellite phase, rad (wrapped)


IMM_STATE_LEN = 13
"""Length of the IMM state vector."""


class ImmOut(IntEnum):
    """Slots of the IMM step's output vector (float64[len(ImmOut)])."""

    PHI = 0            # combined phase estimate, rad
    OMEGA = 1          # combined angular frequency, rad/s
    P11 = 2            # combined covariance, rad^2, rad^2/s, rad^2/s^2
    P12 = 3
    P22 = 4
    MU1 = 5            # mode probabilities after the update
    MU2 = 6
    PRIOR_P11 = 7      # combined prior (predicted) covariance
    PRIOR_P22 = 8
    PRIOR_PHI = 9      # combined prior phase, rad
    USED = 10          # 1 if the measurement was used


IMM_OUT_LEN = len(ImmOut)


class PllState(IntEnum):
    """Slots of the Costas PLL state vector (float64[len(PllState)])."""

    NCO_PHASE = 0      # residual NCO phase, rad
    NCO_RATE = 1       # NCO rate, rad/s
    VELOCITY = 2       # velocity integrator, rad/s
    ACCELERATION = 3   # acceleration integrator, rad/s^2
    SAT_PHASE = 4      # accumulated satellite phase, rad (wrapped)
    ELAPSED = 5        # elapsed time, s
    EMA_DIFF = 6       # exponential average of I'^2 - Q'^2 (lock metric)
    EMA_SUM = 7        # exponential average of I'^2 + Q'^2


PLL_STATE_LEN = len(PllState)


class PllOut(IntEnum):
    """Slots of the PLL step's output vector (float64[len(PllOut)])."""

    PHASE = 0          # phase estimate (NCO residual phase + discriminator), rad
    FREQUENCY = 1      # velocity integrator, rad/s
    DISCRIMINATOR = 2  # rad
    BANDWIDTH = 3      # loop noise bandwidth, Hz
    LOCK_METRIC = 4


PLL_OUT_LEN = len(PllOut)


class Counter(IntEnum):
    """Counters of the per-channel tracker; ``CarrierTracker.counters`` keys are the lower-case names."""

    PROCESSED = 0
    CHANNELS_STARTED = 1
    CHANNELS_DROPPED_TIMEOUT = 2
    CHANNELS_RESTARTED_GAP = 3
    REJECTED_NONFINITE_IQ = 4
    REJECTED_INTEGRATION_TIME = 5
    REJECTED_CN0_RANGE = 6
    CN0_MISSING_USED_LAST = 7
    REJECTED_CN0_MISSING = 8
    REJECTED_PREDICTED_PHASE = 9
    REJECTED_STAMP_BACKWARDS = 10
    REJECTED_INVALID_SVID = 11
    REJECTED_DUPLICATE_CHANNEL = 12
    SLIPS_DETECTED = 13
    CHANNELS_RESTARTED_NONFINITE = 14
    REJECTED_IQ_MAGNITUDE = 15
    LOCKED_SUPPRESSED_INVALID = 16
    CHANNELS_RESTARTED_DIVERGED = 17
    CHANNELS_RESTARTED_STAMP_JUMP = 18
    CORRELATOR_LOCK_UNKNOWN = 19       # processed correlators whose producer did not say its carrier lock
    CORRELATOR_UNLOCKED = 20           # processed correlators whose producer's carrier loop was not in lock
    LOCKED_ON_CORRELATOR_UNLOCKED = 21  # of these, estimates published locked
    SLIPS_ON_CORRELATOR_UNLOCKED = 22  # slips detected on these (also in slips_detected)
    COASTED_CORRELATOR_UNLOCKED = 23   # of these, IMM steps that coasted (correlator_unlocked: coast)


COUNTER_KEYS = tuple(c.name.lower() for c in Counter)
"""Keys of CarrierTracker.counters (their order is the compiled kernel's counter index)."""


class BatchColumn(IntEnum):
    """Columns of CarrierPhaseBatch.values (the fields of rfi_msgs/CarrierPhase, lower-case names)."""

    CONSTELLATION = 0
    SVID = 1
    PHASE_RAD = 2
    PHASE_STD_RAD = 3
    FREQUENCY_HZ = 4
    FREQUENCY_STD_HZ = 5
    DATA_BIT = 6
    DATA_BIT_PROBABILITY = 7
    MODE_PROBABILITY_PLUS = 8
    MODE_PROBABILITY_MINUS = 9
    LOCKED = 10
    CYCLE_SLIPS = 11


BATCH_COLUMNS = tuple(c.name.lower() for c in BatchColumn)
"""Columns of CarrierPhaseBatch.values, in order (the fields of rfi_msgs/CarrierPhase)."""
N_BATCH_COLUMNS = len(BatchColumn)


class KernelConfig(IntEnum):
    """Slots of the tracker kernel's float configuration vector (``TrackerParams``, SI units)."""

    QF = 0                 # clock white-FM spectral density S_f
    QG = 1                 # clock random-walk-FM spectral density S_g
    FORM = 2               # process noise form code
    UNIT_NOISE = 3         # I/Q scaled to unit noise (1) or unit amplitude (0)
    P_BIT = 4              # bit transition probability
    BIT_PERIOD = 5         # s
    INIT_PHASE_STD = 6     # rad
    INIT_FREQ_STD = 7      # Hz
    LOCK_STD = 8           # IMM lock threshold on the phase 1-sigma, rad
    SLIP_THR = 9           # cycle-slip threshold, rad
    MAX_GAP = 10           # intervals
    BW_START = 11          # PLL bandwidth schedule, Hz, Hz, s
    BW_END = 12
    BW_DURATION = 13
    LOCK_TC = 14           # PLL lock metric time constant, s
    LOCK_THR = 15          # PLL lock threshold
    T_MIN = 16             # integration time range, s
    T_MAX = 17
    IQ_RATIO = 18          # max I/Q magnitude ratio
    COAST_UNLOCKED = 19    # 1: the IMM coasts (prediction only) on a correlator whose carrier lock was lost


KERNEL_CONFIG_LEN = len(KernelConfig)

"""GPS L1 C/A tracking: per channel a DLL and an FLL-assisted PLL closing on 1-ms early/prompt/late
correlators, in one compiled kernel per block of samples (no Python per sample).

Each channel holds two numerically controlled oscillators (NCOs):

* the **carrier NCO**, at the frequency the stream carries the satellite's carrier,
  ``f_c = carrier_frequency_hz(f_d)`` (IF + Doppler, or |IF| - Doppler for a spectrally inverted real
  IF); its Doppler phase ``phi_nco = 2 pi int f_d dt`` (rad, from the channel's start) is reported;
* the **code NCO**, at ``f_chip (1 + f_d / f_L1)`` (carrier aiding) plus the DLL's correction.

Per sample: ``y_n = x_n exp(-j 2 pi phi_c(n))`` (carrier wipe-off: a rotation table per 256-sample chunk, the
chunk's exact base phasor applied to its sums, ``CHUNK``), then ``E, P, L += y_n c(chip_n +- d)``, ``c(chip_n)``
with ``d`` = ``early_late_offset_chips`` (0.5: one chip between early and late), the four replicas of a sample from
one packed table entry (``_code_bits``). Inside a code period both phases of sample k are computed from k (no
running sum, no test per sample, so the inner loop vectorises); the kernel cuts the block at the period ends and
closes the loops there. The
prompts of one code period (1 ms, chip 0 to chip 1022, so a period never straddles a data bit edge)
close the loops at the period's end (T = that period's duration):

* **PLL** (Costas, insensitive to the data bit): ``e_p = atan(Q_P / I_P)`` rad;
* **FLL** (cross/dot of consecutive prompts, insensitive to a bit flip between them):
  ``e_f = atan(cross / dot) / T`` rad/s, ``cross = I_{k-1} Q_k - Q_{k-1} I_k``,
  ``dot = I_{k-1} I_k + Q_{k-1} Q_k``; unambiguous for |frequency error| < 1 / (4 T) = 250 Hz;
* **carrier loop filter**: the second-order PLL with first-order FLL assist of Ward, Betz & Hegarty
  (Kaplan & Hegarty, "Understanding GPS", 2nd ed., Fig. 5-23 and Table 5-6), bilinear integrator:

      w_k = w_{k-1} + T (w0p^2 e_p + w0f e_f),     Omega_k = (w_k + w_{k-1}) / 2 + a2 w0p e_p,

  ``w0p = B_pll / 0.53``, ``a2 = 1.414``, ``w0f = 4 B_fll`` (noise bandwidths B in Hz); Doppler of the
  next period ``f_d = f_acq + Omega_k / (2 pi)``. The FLL assist pulls in acquisition errors of tens of
  Hz that the PLL alone does not (on simulated IF a 15-Hz PLL alone lost 25 and 50 Hz offsets; with a
  5-Hz FLL assist both were pulled in); it is switched off (``w0f = 0``) after ``fll_assist_ms``
  periods, because its 1-ms cross-product discriminator is noisy (on the real 4 MHz capture a 10-20 Hz
  assist delayed lock by 50-100 ms against 5 Hz). A second-order loop follows a frequency ramp
  R (Hz/s) with a static phase error 2 pi R / w0p^2 (0.008 rad per Hz/s at 15 Hz: a static receiver's
  satellite and TCXO drift of a few Hz/s costs a few hundredths of a radian). A third-order loop was
  tried and dropped: the ringing of its rate integrator after pull-in lasted 0.5 s on simulated IF.
* **DLL** (normalised non-coherent early-minus-late envelope, Kaplan & Hegarty Table 5-4):
  ``e_c = (1 - d) (|E| - |L|) / (|E| + |L|)`` chips (exact for the infinite-bandwidth triangle while
  |error| < d), a first-order loop of noise bandwidth ``B_dll``: code rate
  ``f_chip (1 + f_d / f_L1) + 4 B_dll e_c`` chips/s (B_n = K / 4 for a first-order loop).

Real samples are mixed with the complex NCO as they are: the image at ``-2 f_c`` integrates out over
1 ms (f_c >= ~1 MHz). For a spectrally inverted real IF the prompts are conjugated at each period's end,
so that every loop, phase and output is in terms of the Doppler (sign as the acquisition's).

C/N0, lock and slips: module ``channel_quality`` (the noise-reference C/N0, the lock rule, the wrap count).

Time and index conventions: samples are addressed by their absolute index in the stream (the
IfSamples ``first_sample_index``); a period's end ``end_index`` is fractional (where the code NCO
crossed chip 1023), so its time is ``stamp(first sample) + (end_index - first_sample_index) / fs``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from gnss_common.constants import GPS_CA_CHIP_RATE_HZ, GPS_CA_CODE_LENGTH_CHIPS, GPS_L1_FREQUENCY_HZ
from gnss_common.gps_ca import G2_DELAY_CHIPS, ca_code
from gnss_correlator.acquisition import MIN_SAMPLE_RATE_HZ
from gnss_correlator.channel_quality import (
    WRAP_THRESHOLD_RAD,
    lock_window,
    noise_offset_chips,
    window_quality,
)
from gnss_correlator.tracked_periods import TrackedPeriods

TWO_PI = 2.0 * math.pi
PLL_A2 = 1.414
"""a2 of the second-order PLL (Kaplan & Hegarty, Table 5-6)."""
PLL_W0_PER_BN = 1.0 / 0.53
"""w0 / B_n of the second-order PLL, rad/s per Hz (Kaplan & Hegarty, Table 5-6: B_n = 0.53 w0)."""
FLL_W0_PER_BN = 4.0
"""w0 / B_n of the first-order FLL assist, rad/s per Hz (Kaplan & Hegarty, Table 5-6: B_n = 0.25 w0)."""

# ---- layout of the kernel's per-channel state (float64 row) ---------------------------------------
S_CODE_PHASE = 0  # code NCO phase at the next sample, chips, [0, 1023)
S_CODE_CORR = 1  # DLL correction to the carrier-aided code rate, chips/s
S_CARR_CYC = 2  # carrier NCO phase of the sampled stream at the next sample, cycles, [0, 1)
S_DOPPLER = 3  # carrier NCO Doppler, Hz
S_DOPPLER_ACQ = 4  # Doppler the loop started from, Hz
S_W = 5  # carrier loop filter integrator w, rad/s
S_PHASE_RAD = 6  # accumulated Doppler phase of the NCO at the next sample, rad
S_E_RE, S_E_IM, S_P_RE, S_P_IM, S_L_RE, S_L_IM = 7, 8, 9, 10, 11, 12  # running sums of the period
S_N = 13  # samples summed into the running period
S_PREV_RE, S_PREV_IM = 14, 15  # previous period's prompt (0, 0: none)
S_PERIODS = 16  # periods closed since the start
S_PERIOD_START = 17  # fractional index where the running period started
S_PRN = 18
S_ACTIVE = 19  # 1 while the channel is tracked
S_RING_COUNT = 20  # full periods written to the channel's rings (C/N0 and lock windows)
S_NZ_RE, S_NZ_IM = 21, 22  # running sums of the period's noise-reference correlator
S_BLK_RE, S_BLK_IM, S_BLK_N = 23, 24, 25  # prompts summed over the running block of the slip detector, their count
S_BLK_PREV = 26  # Costas angle of the previous block, rad (NaN: none yet)
N_STATE = 27

# ---- layout of one output row (one closed code period of one channel) -----------------------------
O_END = 0  # fractional absolute sample index of the period's end (code NCO at chip 1023)
O_START = 1  # fractional absolute sample index of its start
O_E_RE, O_E_IM, O_P_RE, O_P_IM, O_L_RE, O_L_IM = 2, 3, 4, 5, 6, 7
O_DOPPLER = 8  # carrier NCO Doppler during the period, Hz
O_PHASE_RAD = 9  # NCO Doppler phase at the period's end, rad (since the channel's start)
O_CODE_RATE = 10  # code NCO rate during the period, chips/s
O_PLL_ERR = 11  # PLL discriminator, rad
O_FLL_ERR = 12  # FLL discriminator, Hz (0 on the first period)
O_DLL_ERR = 13  # DLL discriminator, chips
O_N = 14  # samples in the period
O_PERIOD = 15  # period count since the channel's start (0 = the first, usually partial)
O_CN0 = 16  # C/N0 over the last window of prompts, dB-Hz (NaN until the window is full)
O_LOCK = 17  # PLL lock indicator over the same window (NaN until full)
O_NOISE = 18  # noise power of one prompt (both components) over the same window, (input units x samples)^2
O_NZ_RE, O_NZ_IM = 19, 20  # noise-reference correlator (same code, NOISE_OFFSET chips away), re and im
O_CN0_M2M4 = 21  # C/N0 of the moments (M2M4) estimator over the C/N0 window, dB-Hz (NaN until full)
O_ERR_STD = 22  # std of the PLL discriminator over the lock window, rad (NaN until full)
O_WRAPS = 23  # half-cycle wraps of the PLL discriminator over the lock window (NaN until full)
O_LOCKED = 24  # 1: locked by the lock rule (module docstring), 0: not (also 0 until the lock window is full)
N_OUT = 25


@dataclass(frozen=True)
class TrackingConfig:
    """Loop parameters of every channel.

    Attributes:
        pll_bandwidth_hz: noise bandwidth of the second-order PLL, Hz, (0, 50]. 15-18 Hz: a static or
            slow receiver with a TCXO at 1-ms integration (Kaplan & Hegarty: thermal noise
            sigma_PLL grows as sqrt(B_n), dynamic stress falls as 1 / B_n^2).
        fll_bandwidth_hz: noise bandwidth of the first-order FLL assist during pull-in, Hz, [0, 50].
        fll_assist_ms: code periods (ms) with the FLL assist on after a channel starts, >= 0; then a
            pure second-order PLL.
        dll_bandwidth_hz: noise bandwidth of the first-order DLL, Hz, (0, 10]; carrier aiding removes
            the dynamics, so 1-2 Hz is enough.
        early_late_offset_chips: d, offset of the early and late replicas from the prompt, chips,
            (0, 0.5]; 0.5 = one chip between early and late.
        cn0_window_ms: prompts of the C/N0 estimates and the lock indicator, >= 10.
        lock_window_ms: periods of the lock rule (discriminator std and half-cycle wraps), >= 10
            (the issue's "over the last 100 ms").
        lock_phase_std_max_rad: the lock rule's largest std of the Costas discriminator over the lock window,
            rad, (0, pi / 2]. 0.5: the 1-ms discriminator's noise alone reaches it near 33 dB-Hz
            (1 / sqrt(2 T C/N0)); an unlocked channel's uniform error gives pi / sqrt(12) = 0.91. The same
            number as imm_carrier's ``lock_phase_std_max_rad``.
        wrap_block_ms: prompts summed per block of the slip detector, [1, lock_window_ms / 2]: 1 compares
            consecutive 1-ms discriminators (fastest, but noise wraps them below ~38 dB-Hz); K > 1 compares
            the Costas angles of consecutive K-ms sums (noise sqrt(K) lower; a slip seen up to K ms later).
    """

    pll_bandwidth_hz: float = 15.0
    fll_bandwidth_hz: float = 5.0
    fll_assist_ms: int = 100
    dll_bandwidth_hz: float = 2.0
    early_late_offset_chips: float = 0.5
    cn0_window_ms: int = 50
    lock_window_ms: int = 100
    lock_phase_std_max_rad: float = 0.5
    wrap_block_ms: int = 1

    def __post_init__(self) -> None:
        checks = (
            ('pll_bandwidth_hz', 0.0 < self.pll_bandwidth_hz <= 50.0, '(0, 50]'),
            ('fll_bandwidth_hz', 0.0 <= self.fll_bandwidth_hz <= 50.0, '[0, 50]'),
            ('fll_assist_ms', self.fll_assist_ms >= 0, '>= 0'),
            ('dll_bandwidth_hz', 0.0 < self.dll_bandwidth_hz <= 10.0, '(0, 10]'),
            ('early_late_offset_chips', 0.0 < self.early_late_offset_chips <= 0.5, '(0, 0.5]'),
            ('cn0_window_ms', self.cn0_window_ms >= 10, '>= 10'),
            ('lock_window_ms', self.lock_window_ms >= 10, '>= 10'),
            ('lock_phase_std_max_rad', 0.0 < self.lock_phase_std_max_rad <= 0.5 * math.pi, '(0, pi / 2]'),
            ('wrap_block_ms', 1 <= self.wrap_block_ms <= self.lock_window_ms // 2, '[1, lock_window_ms / 2]'),
        )
        for name, ok, rule in checks:
            if not ok:
                raise ValueError(f'{name} must be {rule}, got {getattr(self, name)}')


@njit(cache=True, nogil=True)
def _close_period(st: np.ndarray, out: np.ndarray, ring: np.ndarray, noise_ring: np.ndarray, err_ring: np.ndarray,
                  row: int, end_index: float, code_rate: float, inverted: bool, w0p: float, w0f: float,
                  assist_periods: float, k_dll: float, d_chips: float, sign: float, if0: float, fs: float,
                  lock_std_max: float, wrap_block: float) -> float:
    """Write the period's output row, run the discriminators and loop filters, reset the sums.

    Returns the new carrier NCO frequency of the stream, Hz.
    """
    n = st[S_N]
    t = n / fs
    e_re, e_im = st[S_E_RE], st[S_E_IM]
    p_re, p_im = st[S_P_RE], st[S_P_IM]
    l_re, l_im = st[S_L_RE], st[S_L_IM]
    n_re, n_im = st[S_NZ_RE], st[S_NZ_IM]
    if inverted:  # conjugate: phases in terms of the Doppler
        e_im, p_im, l_im, n_im = -e_im, -p_im, -l_im, -n_im
    # discriminators
    pll = math.atan(p_im / p_re) if p_re != 0.0 else (0.5 * math.pi if p_im > 0 else -0.5 * math.pi)
    fll = 0.0
    if st[S_PREV_RE] != 0.0 or st[S_PREV_IM] != 0.0:
        cross = st[S_PREV_RE] * p_im - st[S_PREV_IM] * p_re
        dot = st[S_PREV_RE] * p_re + st[S_PREV_IM] * p_im
        if dot != 0.0:
            fll = math.atan(cross / dot) / t
        else:
            fll = (0.5 * math.pi if cross > 0 else -0.5 * math.pi) / t
    ea = math.sqrt(e_re * e_re + e_im * e_im)
    la = math.sqrt(l_re * l_re + l_im * l_im)
    dll = (1.0 - d_chips) * (ea - la) / (ea + la) if ea + la > 0 else 0.0
    out[row, O_END] = end_index
    out[row, O_START] = st[S_PERIOD_START]
    out[row, O_E_RE], out[row, O_E_IM] = e_re, e_im
    out[row, O_P_RE], out[row, O_P_IM] = p_re, p_im
    out[row, O_L_RE], out[row, O_L_IM] = l_re, l_im
    out[row, O_DOPPLER] = st[S_DOPPLER]
    out[row, O_PHASE_RAD] = st[S_PHASE_RAD]
    out[row, O_CODE_RATE] = code_rate
    out[row, O_PLL_ERR] = pll
    out[row, O_FLL_ERR] = fll / TWO_PI
    out[row, O_DLL_ERR] = dll
    out[row, O_N] = n
    out[row, O_PERIOD] = st[S_PERIODS]
    out[row, O_CN0] = math.nan
    out[row, O_LOCK] = math.nan
    out[row, O_NOISE] = math.nan
    out[row, O_NZ_RE], out[row, O_NZ_IM] = n_re, n_im
    out[row, O_CN0_M2M4] = math.nan
    out[row, O_ERR_STD] = math.nan
    out[row, O_WRAPS] = math.nan
    out[row, O_LOCKED] = 0.0
    if st[S_PERIODS] > 0:  # the first period is partial: left out of the windows
        w = ring.shape[0]
        wl = err_ring.shape[0]
        count = int(st[S_RING_COUNT])
        ring[count % w] = complex(p_re, p_im)
        noise_ring[count % w] = complex(n_re, n_im)
        # slip detector: the Costas angle of blocks of wrap_block prompts (a data bit flip inside a block leaves
        # its angle modulo pi unchanged); a change by more than pi/2 from the previous block is a wrap
        st[S_BLK_RE] += p_re
        st[S_BLK_IM] += p_im
        st[S_BLK_N] += 1.0
        wrap = 0.0
        if st[S_BLK_N] >= wrap_block:
            b_re, b_im = st[S_BLK_RE], st[S_BLK_IM]
            ang = math.atan(b_im / b_re) if b_re != 0.0 else (0.5 * math.pi if b_im > 0 else -0.5 * math.pi)
            prev = st[S_BLK_PREV]
            if prev == prev and abs(ang - prev) > WRAP_THRESHOLD_RAD:
                wrap = 1.0
            st[S_BLK_PREV] = ang
            st[S_BLK_RE] = st[S_BLK_IM] = st[S_BLK_N] = 0.0
        err_ring[count % wl, 0] = pll
        err_ring[count % wl, 1] = wrap
        st[S_RING_COUNT] += 1.0
        if st[S_RING_COUNT] >= w:
            out[row, O_CN0], out[row, O_CN0_M2M4], out[row, O_LOCK], out[row, O_NOISE] = \
                window_quality(ring, noise_ring, t)
        if st[S_RING_COUNT] >= wl:
            std, wraps = lock_window(err_ring)
            out[row, O_ERR_STD], out[row, O_WRAPS] = std, wraps
            out[row, O_LOCKED] = 1.0 if (std <= lock_std_max and wraps == 0.0) else 0.0
    # carrier loop (Kaplan & Hegarty Fig. 5-23): second-order PLL, first-order FLL assist while pulling in
    w0f_now = w0f if st[S_PERIODS] < assist_periods else 0.0
    w_old = st[S_W]
    w_new = w_old + t * (w0p * w0p * pll + w0f_now * fll)
    omega = 0.5 * (w_old + w_new) + PLL_A2 * w0p * pll
    st[S_W] = w_new
    st[S_DOPPLER] = st[S_DOPPLER_ACQ] + omega / TWO_PI
    st[S_CODE_CORR] = k_dll * dll
    st[S_PREV_RE], st[S_PREV_IM] = p_re, p_im
    st[S_E_RE] = st[S_E_IM] = st[S_P_RE] = st[S_P_IM] = st[S_L_RE] = st[S_L_IM] = 0.0
    st[S_NZ_RE] = st[S_NZ_IM] = 0.0
    st[S_N] = 0.0
    st[S_PERIODS] += 1.0
    st[S_PERIOD_START] = end_index
    return if0 + sign * st[S_DOPPLER]


CHUNK = 256
"""Samples per chunk of the carrier wipe-off: inside a chunk the samples are multiplied by a table of
exp(-j 2 pi k cstep), k < CHUNK, built once per segment by a complex rotation recurrence (relative error ~k x 1e-16,
below 3e-14), and the chunk's correlator sums are then rotated by its base phasor exp(-j 2 pi phase at the chunk's
start), computed exactly (cos and sin of the NCO's float64 phase): sum_k x_k b t_k c_k = b sum_k x_k t_k c_k, four
fewer multiplications per sample than forming b t_k per sample."""


@njit(cache=True, nogil=True)
def _code_bits(code: np.ndarray, ncode: np.ndarray) -> np.ndarray:
    """The replicas of one channel packed for ``_segment``: entry ip (0..1023, the prompt's chip index) holds in
    bit s (s = 0, 1, 2) whether ``code[ip + s]`` is +1 (``code`` with its one chip of wrap each side: entries ip,
    ip + 1, ip + 2 are chips ip - 1, ip, ip + 1 mod 1023, the late, prompt and early replicas' candidates for
    d <= 0.5), in bit 3 whether ``ncode[ip + 1]`` is +1."""
    n = code.shape[0] - 2
    bits = np.empty(n + 1, dtype=np.int32)
    for ip in range(n + 1):
        third = code[ip + 2] if ip + 2 <= n + 1 else code[(ip + 1) % n + 1]
        bits[ip] = (np.int32(code[ip] > 0.0) | (np.int32(code[ip + 1] > 0.0) << 1) | (np.int32(third > 0.0) << 2)
                    | (np.int32(ncode[ip + 1] > 0.0) << 3))
    return bits


@njit(cache=True, nogil=True, fastmath=True)
def _segment(xr: np.ndarray, xi: np.ndarray | None, i0: int, m: int, cyc0: float, cstep: float, cp0: float,
             code_step: float, bits: np.ndarray, d_plus: float, d_minus: float,
             tr: np.ndarray, ti: np.ndarray) -> tuple[float, float, float, float, float, float, float, float]:
    """E, P, L and noise-reference sums (re, im) of samples i0 .. i0 + m - 1, all inside one code period (no
    branch per sample: the carrier phasor and the code phase of sample k are computed from k, so the inner loop
    vectorises; checked with ``inspect_asm``: AVX-512 on this machine).

    ``y_k = x_k exp(-j 2 pi (cyc0 + k cstep))``, chips ``cp0 + k code_step`` (+- the early and late offsets);
    ``xi`` None for real samples. ``bits``: the packed replica table of ``_code_bits`` (one int32 gather per
    sample gives all four replicas). ``tr``, ``ti``: scratch of CHUNK floats for the rotation table.
    """
    # rotation table exp(-j 2 pi k cstep), k < CHUNK: a recurrence from the exact one-step rotation
    w_re = math.cos(TWO_PI * cstep)
    w_im = -math.sin(TWO_PI * cstep)
    tr[0] = 1.0
    ti[0] = 0.0
    for k in range(1, min(CHUNK, m)):
        tr[k] = tr[k - 1] * w_re - ti[k - 1] * w_im
        ti[k] = tr[k - 1] * w_im + ti[k - 1] * w_re
    er = ei = pr = pi = lr = li = nr = ni = 0.0
    for k0 in range(0, m, CHUNK):
        ph = TWO_PI * ((cyc0 + k0 * cstep) % 1.0)
        b_re = math.cos(ph)
        b_im = -math.sin(ph)
        n = min(CHUNK, m - k0)
        cer = cei = cpr = cpi = clr = cli = cnr = cni = 0.0
        for k in range(n):  # sums of x_k exp(-j 2 pi (k - k0) cstep) c_k: the chunk's base phasor applied after
            c_re = tr[k]
            c_im = ti[k]
            a = xr[i0 + k0 + k]
            if xi is None:
                yr = a * c_re
                yi = a * c_im
            else:
                b = xi[i0 + k0 + k]
                yr = a * c_re - b * c_im
                yi = a * c_im + b * c_re
            chips = cp0 + (k0 + k) * code_step
            ip = int(chips)
            w = bits[ip]
            # bit s of w: code table entry ip + s (s = 0, 1, 2), bit 3: the noise code's entry ip + 1
            cpv = float(((w >> 1) & 1) * 2 - 1)
            cev = float(((w >> (int(chips + d_plus) - ip)) & 1) * 2 - 1)
            clv = float(((w >> (int(chips + d_minus) - ip)) & 1) * 2 - 1)
            cnv = float(((w >> 3) & 1) * 2 - 1)
            cnr += yr * cnv
            cni += yi * cnv
            cpr += yr * cpv
            cpi += yi * cpv
            cer += yr * cev
            cei += yi * cev
            clr += yr * clv
            cli += yi * clv
        # rotate the chunk's sums by its base phasor b = exp(-j 2 pi (cyc0 + k0 cstep))
        er += b_re * cer - b_im * cei
        ei += b_re * cei + b_im * cer
        pr += b_re * cpr - b_im * cpi
        pi += b_re * cpi + b_im * cpr
        lr += b_re * clr - b_im * cli
        li += b_re * cli + b_im * clr
        nr += b_re * cnr - b_im * cni
        ni += b_re * cni + b_im * cnr
    return er, ei, pr, pi, lr, li, nr, ni


@njit(cache=True, nogil=True)
def track_block(xr: np.ndarray, xi: np.ndarray | None, first_index: int, fs: float, if0: float, sign: float,
                inverted: bool, state: np.ndarray, codes: np.ndarray, noise_codes: np.ndarray, rings: np.ndarray,
                noise_rings: np.ndarray, err_rings: np.ndarray, out: np.ndarray, n_out: np.ndarray, w0p: float,
                w0f: float, assist_periods: float, k_dll: float, d_chips: float, lock_std_max: float,
                wrap_block: float) -> None:
    """Track every active channel of ``state`` over one contiguous block of samples (compiled).

    Args:
        xr: real parts (real samples: the samples), shape (n,), float64.
        xi: imaginary parts, shape (n,), float64; None for real samples.
        first_index: absolute index of x[0].
        fs: sample rate, Hz.
        if0: the stream's carrier frequency at zero Doppler, Hz (IF, or -IF for an inverted real IF).
        sign: d f_c / d f_d: +1, or -1 for an inverted real IF.
        inverted: conjugate the prompts (spectral inversion).
        state: per-channel state, shape (n_ch, N_STATE), updated in place.
        codes: +-1 C/A code of each channel with one chip of wrap each side, shape (n_ch, 1025):
            ``codes[:, k + 1]`` is chip k mod 1023 for k = -1..1023.
        noise_codes: the same codes shifted by each channel's noise-reference offset (chip k + offset), same shape.
        rings: the last prompts of each channel (C/N0 window), shape (n_ch, window), complex128.
        noise_rings: the noise-reference correlators of the same periods, shape (n_ch, window), complex128.
        err_rings: per period of the lock window, the PLL discriminator and whether the slip detector found a
            wrap there (0 / 1), shape (n_ch, lock window, 2), float64.
        out: output rows, shape (n_ch, max_periods, N_OUT), written from row 0.
        n_out: rows written per channel, shape (n_ch,), set.
        w0p, w0f: natural frequencies of the PLL and the FLL assist, rad/s.
        assist_periods: periods with the FLL assist on.
        k_dll: DLL gain 4 B_dll, 1/s.
        d_chips: early/late offset, chips.
        lock_std_max: the lock rule's largest discriminator std, rad.
        wrap_block: prompts per block of the slip detector.
    """
    n_total = xr.shape[0]
    n_ch = state.shape[0]
    n_code = codes.shape[1] - 2
    d_plus = 1.0 + d_chips
    d_minus = 1.0 - d_chips
    tr = np.empty(CHUNK)
    ti = np.empty(CHUNK)
    for c in range(n_ch):
        n_out[c] = 0
        st = state[c]
        if st[S_ACTIVE] == 0.0:
            continue
        bits = _code_bits(codes[c], noise_codes[c])
        f_c = if0 + sign * st[S_DOPPLER]
        code_rate = GPS_CA_CHIP_RATE_HZ * (1.0 + st[S_DOPPLER] / GPS_L1_FREQUENCY_HZ) + st[S_CODE_CORR]
        code_step = code_rate / fs
        cstep = f_c / fs
        dstep = TWO_PI * st[S_DOPPLER] / fs
        cyc = st[S_CARR_CYC]
        cp = st[S_CODE_PHASE]
        e_re, e_im = st[S_E_RE], st[S_E_IM]
        p_re, p_im = st[S_P_RE], st[S_P_IM]
        l_re, l_im = st[S_L_RE], st[S_L_IM]
        n_re, n_im = st[S_NZ_RE], st[S_NZ_IM]
        n_in = 0  # samples since the running period's sums were last written to st
        i = 0
        while i < n_total:
            # samples k >= 0 of this period left: those with cp + k code_step < 1023
            n_left = max(1, int(math.ceil((n_code - cp) / code_step)))
            m = min(n_left, n_total - i)
            se_re, se_im, sp_re, sp_im, sl_re, sl_im, sn_re, sn_im = _segment(
                xr, xi, i, m, cyc, cstep, cp, code_step, bits, d_plus, d_minus, tr, ti)
            e_re += se_re
            e_im += se_im
            p_re += sp_re
            p_im += sp_im
            l_re += sl_re
            l_im += sl_im
            n_re += sn_re
            n_im += sn_im
            cp += m * code_step
            cyc = (cyc + m * cstep) % 1.0
            n_in += m
            i += m
            if m < n_left:
                break
            # the period ends inside the last sample step: close it
            cp = max(cp - n_code, 0.0)
            end_index = first_index + i - cp / code_step
            st[S_E_RE], st[S_E_IM] = e_re, e_im
            st[S_P_RE], st[S_P_IM] = p_re, p_im
            st[S_L_RE], st[S_L_IM] = l_re, l_im
            st[S_NZ_RE], st[S_NZ_IM] = n_re, n_im
            st[S_N] += n_in
            st[S_PHASE_RAD] += n_in * dstep
            row = n_out[c]
            if row >= out.shape[1]:  # no room (cannot happen with the sizes process() allocates): stop
                st[S_ACTIVE] = 0.0
                break
            f_c = _close_period(st, out[c], rings[c], noise_rings[c], err_rings[c], row, end_index, code_rate,
                                inverted, w0p, w0f, assist_periods, k_dll, d_chips, sign, if0, fs, lock_std_max,
                                wrap_block)
            n_out[c] = row + 1
            n_in = 0
            e_re = e_im = p_re = p_im = l_re = l_im = n_re = n_im = 0.0
            code_rate = GPS_CA_CHIP_RATE_HZ * (1.0 + st[S_DOPPLER] / GPS_L1_FREQUENCY_HZ) + st[S_CODE_CORR]
            code_step = code_rate / fs
            cstep = f_c / fs
            dstep = TWO_PI * st[S_DOPPLER] / fs
        st[S_E_RE], st[S_E_IM] = e_re, e_im
        st[S_P_RE], st[S_P_IM] = p_re, p_im
        st[S_L_RE], st[S_L_IM] = l_re, l_im
        st[S_NZ_RE], st[S_NZ_IM] = n_re, n_im
        st[S_N] += n_in
        st[S_PHASE_RAD] += n_in * dstep
        st[S_CARR_CYC] = cyc
        st[S_CODE_PHASE] = cp


class Tracker:
    """The channels of one sample stream (fixed rate, IF and sample type), fed contiguous blocks.

    Args:
        sample_rate_hz: fs, Hz (complex: I/Q pairs per second), >= 2 MHz.
        intermediate_frequency_hz: IF, Hz (0: complex baseband; < 0 with real samples: spectral inversion).
        is_complex: complex samples.
        config: loop parameters.

    Example:
        >>> import numpy as np
        >>> t = Tracker(4e6, 0.0, True)
        >>> t.add_channel(prn=3, code_delay_samples=100.0, doppler_hz=500.0, reference_index=0)
        >>> x = np.random.default_rng(0).normal(size=8000) + 0j
        >>> out = t.process(x, first_sample_index=0)
        >>> out.prn.tolist()
        [3, 3]
    """

    def __init__(self, sample_rate_hz: float, intermediate_frequency_hz: float, is_complex: bool,
                 config: TrackingConfig = TrackingConfig()) -> None:
        if not (math.isfinite(sample_rate_hz) and sample_rate_hz >= MIN_SAMPLE_RATE_HZ):
            raise ValueError(f'sample_rate_hz must be >= {MIN_SAMPLE_RATE_HZ:g}, got {sample_rate_hz}')
        if not math.isfinite(intermediate_frequency_hz):
            raise ValueError(f'intermediate_frequency_hz must be finite, got {intermediate_frequency_hz}')
        self.fs = float(sample_rate_hz)
        self.if_hz = float(intermediate_frequency_hz)
        self.is_complex = bool(is_complex)
        self.config = config
        self.inverted = (not self.is_complex) and self.if_hz < 0
        self._if0 = -self.if_hz if self.inverted else self.if_hz
        self._sign = -1.0 if self.inverted else 1.0
        self._state = np.zeros((0, N_STATE))
        self._codes = np.zeros((0, GPS_CA_CODE_LENGTH_CHIPS + 2))
        self._noise_codes = np.zeros((0, GPS_CA_CODE_LENGTH_CHIPS + 2))
        self._rings = np.zeros((0, config.cn0_window_ms), dtype=np.complex128)
        self._noise_rings = np.zeros((0, config.cn0_window_ms), dtype=np.complex128)
        self._err_rings = np.zeros((0, config.lock_window_ms, 2))
        self.next_index: int | None = None

    @property
    def prns(self) -> tuple[int, ...]:
        """PRNs of the active channels."""
        return tuple(int(p) for p in self._state[self._state[:, S_ACTIVE] > 0, S_PRN])

    def add_channel(self, prn: int, code_delay_samples: float, doppler_hz: float, reference_index: int) -> None:
        """Start a channel from an acquisition.

        Args:
            prn: 1..37, not already tracked.
            code_delay_samples: samples from ``reference_index`` to a start of chip 0 (acquisition's
                ``code_delay_samples`` of a search whose first sample was ``reference_index``).
            doppler_hz: the acquisition's Doppler, Hz.
            reference_index: absolute index of the acquisition window's first sample; at most the
                next sample to be processed (the code phase is carried forward to it).
        """
        if int(prn) not in G2_DELAY_CHIPS:
            raise ValueError(f'prn must be in 1..37, got {prn}')
        if int(prn) in self.prns:
            raise ValueError(f'PRN {prn} is already tracked')
        if not (math.isfinite(code_delay_samples) and math.isfinite(doppler_hz)):
            raise ValueError('code_delay_samples and doppler_hz must be finite')
        start = reference_index if self.next_index is None else self.next_index
        if reference_index > start:
            raise ValueError(f'reference_index {reference_index} is after the next sample {start}')
        rate = GPS_CA_CHIP_RATE_HZ * (1.0 + doppler_hz / GPS_L1_FREQUENCY_HZ)
        chips = ((start - reference_index - code_delay_samples) * rate / self.fs) % GPS_CA_CODE_LENGTH_CHIPS
        row = np.zeros(N_STATE)
        row[S_CODE_PHASE] = chips
        row[S_DOPPLER] = row[S_DOPPLER_ACQ] = doppler_hz
        row[S_PERIOD_START] = start
        row[S_PRN] = prn
        row[S_ACTIVE] = 1.0
        row[S_BLK_PREV] = math.nan
        keep = self._state[:, S_ACTIVE] > 0
        self._state = np.vstack([self._state[keep], row[None, :]])
        code = ca_code(int(prn)).astype(np.float64)
        wrapped = np.concatenate([code[-1:], code, code[:1]])
        shifted = np.roll(code, -noise_offset_chips(int(prn)))  # chip k + offset
        noise_wrapped = np.concatenate([shifted[-1:], shifted, shifted[:1]])
        w = self.config.cn0_window_ms
        self._codes = np.vstack([self._codes[keep], wrapped[None, :]])
        self._noise_codes = np.vstack([self._noise_codes[keep], noise_wrapped[None, :]])
        self._rings = np.vstack([self._rings[keep], np.zeros((1, w), dtype=np.complex128)])
        self._noise_rings = np.vstack([self._noise_rings[keep], np.zeros((1, w), dtype=np.complex128)])
        self._err_rings = np.concatenate([self._err_rings[keep], np.zeros((1, self.config.lock_window_ms, 2))])

    def drop_channel(self, prn: int) -> None:
        """Stop tracking a PRN (no error if it is not tracked)."""
        keep = self._state[:, S_PRN] != prn
        self._state, self._codes, self._rings = self._state[keep], self._codes[keep], self._rings[keep]
        self._noise_codes, self._noise_rings = self._noise_codes[keep], self._noise_rings[keep]
        self._err_rings = self._err_rings[keep]

    def reset(self) -> None:
        """Drop every channel and forget the stream position."""
        self._state = np.zeros((0, N_STATE))
        self._codes = np.zeros((0, GPS_CA_CODE_LENGTH_CHIPS + 2))
        self._noise_codes = np.zeros((0, GPS_CA_CODE_LENGTH_CHIPS + 2))
        self._rings = np.zeros((0, self.config.cn0_window_ms), dtype=np.complex128)
        self._noise_rings = np.zeros((0, self.config.cn0_window_ms), dtype=np.complex128)
        self._err_rings = np.zeros((0, self.config.lock_window_ms, 2))
        self.next_index = None

    def process(self, samples: np.ndarray, first_sample_index: int) -> TrackedPeriods:
        """Track every channel over one block.

        Args:
            samples: real or complex samples (complex iff the tracker's ``is_complex``), shape (n,).
            first_sample_index: absolute index of samples[0]; must be the previous block's end (the
                first block sets the stream position).

        Returns:
            the code periods closed in the block.

        Raises:
            ValueError: a gap or overlap, a sample type that is not the tracker's, non-finite samples.
        """
        x = np.asarray(samples)
        if x.ndim != 1:
            raise ValueError(f'samples must be one-dimensional, got shape {x.shape}')
        if bool(np.iscomplexobj(x)) != self.is_complex:
            raise ValueError(f'samples must be {"complex" if self.is_complex else "real"}')
        if self.next_index is not None and first_sample_index != self.next_index:
            raise ValueError(f'block starts at {first_sample_index}, expected {self.next_index} (gap or overlap)')
        x = x.astype(np.complex128 if self.is_complex else np.float64)
        if not np.all(np.isfinite(x)):
            raise ValueError('samples hold NaN or infinity')
        self.next_index = int(first_sample_index) + x.size
        n_ch = self._state.shape[0]
        max_periods = int(x.size * GPS_CA_CHIP_RATE_HZ * 1.01 / (GPS_CA_CODE_LENGTH_CHIPS * self.fs)) + 2
        out = np.zeros((n_ch, max_periods, N_OUT))
        n_out = np.zeros(n_ch, dtype=np.int64)
        cfg = self.config
        if n_ch:
            xr = np.ascontiguousarray(x.real) if self.is_complex else x
            xi = np.ascontiguousarray(x.imag) if self.is_complex else None
            track_block(xr, xi, int(first_sample_index), self.fs, self._if0, self._sign, self.inverted, self._state,
                        self._codes, self._noise_codes, self._rings, self._noise_rings, self._err_rings, out, n_out,
                        cfg.pll_bandwidth_hz * PLL_W0_PER_BN, cfg.fll_bandwidth_hz * FLL_W0_PER_BN,
                        float(cfg.fll_assist_ms), 4.0 * cfg.dll_bandwidth_hz, cfg.early_late_offset_chips,
                        cfg.lock_phase_std_max_rad, float(cfg.wrap_block_ms))
        rows = [out[c, :n_out[c]] for c in range(n_ch)]
        prns = np.concatenate([np.full(n_out[c], self._state[c, S_PRN], dtype=np.int64) for c in range(n_ch)]) \
            if n_ch else np.zeros(0, dtype=np.int64)
        table = np.concatenate(rows) if n_ch else np.zeros((0, N_OUT))
        order = np.argsort(table[:, O_END], kind='stable')
        return TrackedPeriods(
            prn=prns[order], end_index=table[order, O_END], start_index=table[order, O_START],
            early=table[order, O_E_RE] + 1j * table[order, O_E_IM],
            prompt=table[order, O_P_RE] + 1j * table[order, O_P_IM],
            late=table[order, O_L_RE] + 1j * table[order, O_L_IM],
            doppler_hz=table[order, O_DOPPLER], nco_phase_rad=table[order, O_PHASE_RAD],
            code_rate_hz=table[order, O_CODE_RATE], pll_error_rad=table[order, O_PLL_ERR],
            fll_error_hz=table[order, O_FLL_ERR], dll_error_chips=table[order, O_DLL_ERR],
            n_samples=table[order, O_N].astype(np.int64), period=table[order, O_PERIOD].astype(np.int64),
            noise_reference=table[order, O_NZ_RE] + 1j * table[order, O_NZ_IM],
            cn0_dbhz=table[order, O_CN0], cn0_m2m4_dbhz=table[order, O_CN0_M2M4], lock_indicator=table[order, O_LOCK],
            noise_power=table[order, O_NOISE], phase_error_std_rad=table[order, O_ERR_STD],
            half_cycle_wraps=table[order, O_WRAPS], locked=table[order, O_LOCKED] > 0.5)


def warm_up() -> None:
    """Load the tracking kernel from numba's cache (or compile it) for real and complex samples: a node calls this
    while it starts, so that its first tracked block does not pay it (about 1 s of CPU at a warm cache, tens of
    seconds after an edit of the suite, measured in docs/gnss_correlator/live_stream.md)."""
    for is_complex in (False, True):
        tracker = Tracker(4.0e6, 0.0 if is_complex else 1.0e6, is_complex, TrackingConfig())
        tracker.add_channel(1, 0.0, 0.0, 0)
        with np.errstate(all='ignore'):  # zeros: no signal, no noise
            tracker.process(np.zeros(4000, dtype=np.complex128 if is_complex else np.float64), 0)

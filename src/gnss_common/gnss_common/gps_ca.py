"""GPS L1 C/A (Gold) code generator.

The C/A code of PRN ``i`` is ``G1 xor G2_i``, where G1 and G2 are 10-stage maximal-length shift
registers (G1: 1 + x^3 + x^10, G2: 1 + x^2 + x^3 + x^6 + x^8 + x^9 + x^10, both initialised to all
ones) and G2_i is G2 delayed by the PRN's chip delay (IS-GPS-200, Table 3-Ia and Fig. 3-9).

Example
-------
>>> from gnss_common.gps_ca import ca_code_bits
>>> ''.join(str(b) for b in ca_code_bits(1)[:10])   # octal 1440
'1100100000'
"""

from __future__ import annotations

from functools import cache

import numpy as np

from gnss_common.constants import GPS_CA_CODE_LENGTH_CHIPS

G2_DELAY_CHIPS: dict[int, int] = {
    1: 5, 2: 6, 3: 7, 4: 8, 5: 17, 6: 18, 7: 139, 8: 140, 9: 141, 10: 251,
    11: 252, 12: 254, 13: 255, 14: 256, 15: 257, 16: 258, 17: 469, 18: 470, 19: 471, 20: 472,
    21: 473, 22: 474, 23: 509, 24: 512, 25: 513, 26: 514, 27: 515, 28: 516, 29: 859, 30: 860,
    31: 861, 32: 862, 33: 863, 34: 950, 35: 947, 36: 948, 37: 950,
}
"""G2 delay per PRN, chips (IS-GPS-200, Table 3-Ia; PRN 34 and 37 share a code)."""


def _mls(taps: tuple[int, ...]) -> np.ndarray:
    """One period (1023 chips) of a 10-stage LFSR output (stage 10), all-ones initial state.

    Args:
        taps: feedback stages, 1-based (e.g. (3, 10) for 1 + x^3 + x^10).

    Returns:
        uint8 array, shape (1023,), values 0/1.
    """
    reg = [1] * 10
    out = np.empty(GPS_CA_CODE_LENGTH_CHIPS, dtype=np.uint8)
    for k in range(GPS_CA_CODE_LENGTH_CHIPS):
        out[k] = reg[9]
        fb = 0
        for t in taps:
            fb ^= reg[t - 1]
        reg = [fb] + reg[:9]
    return out


@cache
def _ca_bits_cached(prn: int) -> bytes:
    g1 = _mls((3, 10))
    g2 = _mls((2, 3, 6, 8, 9, 10))
    g2i = np.roll(g2, G2_DELAY_CHIPS[prn])
    return (g1 ^ g2i).tobytes()


def ca_code_bits(prn: int) -> np.ndarray:
    """C/A code chips of one PRN as logic levels.

    Args:
        prn: satellite PRN, 1..37.

    Returns:
        uint8 array, shape (1023,), values 0/1 (chip 0 first).

    Raises:
        ValueError: unknown PRN.
    """
    if int(prn) not in G2_DELAY_CHIPS:
        raise ValueError(f"PRN must be in 1..37, got {prn}")
    return np.frombuffer(_ca_bits_cached(int(prn)), dtype=np.uint8).copy()


def ca_code(prn: int) -> np.ndarray:
    """C/A code chips of one PRN as BPSK levels (logic 0 -> +1, logic 1 -> -1).

    Args:
        prn: satellite PRN, 1..37.

    Returns:
        int8 array, shape (1023,), values +1/-1.
    """
    return (1 - 2 * ca_code_bits(prn).astype(np.int8)).astype(np.int8)

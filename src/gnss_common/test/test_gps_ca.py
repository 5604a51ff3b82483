"""Oracle tests of the GPS L1 C/A code generator (IS-GPS-200, Table 3-Ia)."""

import numpy as np
import pytest

from gnss_common.gps_ca import ca_code, ca_code_bits


def _octal_first10(prn: int) -> str:
    return oct(int("".join(str(b) for b in ca_code_bits(prn)[:10]), 2))[2:]


def test_ca_code_first_chips_match_is_gps_200():
    # IS-GPS-200 Table 3-Ia, "first 10 chips octal"
    assert _octal_first10(1) == "1440"
    assert _octal_first10(2) == "1620"
    assert _octal_first10(32) == "1712"


def test_ca_code_gold_correlation_properties():
    c1 = ca_code(1).astype(float)
    c2 = ca_code(2).astype(float)
    auto = np.array([c1 @ np.roll(c1, k) for k in range(1023)])
    assert auto[0] == 1023 and set(np.unique(auto[1:])) <= {-65.0, -1.0, 63.0}
    cross = {c1 @ np.roll(c2, k) for k in range(1023)}
    assert cross <= {-65.0, -1.0, 63.0}


def test_ca_code_bad_prn():
    with pytest.raises(ValueError):
        ca_code(0)

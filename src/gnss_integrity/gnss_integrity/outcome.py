"""What every integrity test returns: statistic, thresholds, decision, and what it implicates.

Pure (no rclpy). The constants mirror rfi_msgs/IntegrityTest and rfi_msgs/GnssIntegrity (a test
checks they are equal), so the cores never import ROS types.

Thresholds come from a false-alarm probability per evaluation, not from a tuned number:
:func:`normal_threshold` and :func:`chi2_threshold` turn ``false_alarm_probability`` into the
statistic's threshold under the test's clean-data model (documented per test).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

from scipy.special import chdtri, ndtri

# rfi_msgs/GnssIntegrity STATE_* and SCOPE_*: shared with the fusion, so defined in gnss_common
from gnss_common.integrity_codes import SCOPE_ALL as SCOPE_ALL
from gnss_common.integrity_codes import SCOPE_CONSTELLATIONS as SCOPE_CONSTELLATIONS
from gnss_common.integrity_codes import SCOPE_NONE as SCOPE_NONE
from gnss_common.integrity_codes import SCOPE_SATELLITES as SCOPE_SATELLITES
from gnss_common.integrity_codes import STATE_DETECTED as STATE_DETECTED
from gnss_common.integrity_codes import STATE_NONE as STATE_NONE
from gnss_common.integrity_codes import STATE_SUSPECTED as STATE_SUSPECTED
from gnss_common.integrity_codes import STATE_UNKNOWN as STATE_UNKNOWN

# rfi_msgs/IntegrityTest CATEGORY_*
CATEGORY_JAMMING = 1
CATEGORY_CN0 = 2
CATEGORY_CLOCK = 3
CATEGORY_KINEMATICS = 4
CATEGORY_CONSISTENCY = 5
CATEGORY_EXTERNAL = 6

# rfi_msgs/IntegrityTest DECISION_*
DECISION_UNKNOWN = 0
DECISION_PASS = 1
DECISION_SUSPECT = 2
DECISION_ALARM = 3

# rfi_msgs/GnssIntegrity EVIDENCE_* (jamming_evidence bits)
EVIDENCE_CN0_ELEVATION = 1
EVIDENCE_CN0_COMMON_DROP = 2
EVIDENCE_RECEIVER_AGC = 4
EVIDENCE_RECEIVER_FLAG = 8
EVIDENCE_RECEIVER_SPECTRUM = 16
EVIDENCE_SDR_MONITOR = 32


@dataclass(frozen=True)
class TestOutcome:
    """One test at one evaluation (see rfi_msgs/IntegrityTest).

    Attributes:
        name: stable test name (``docs/gnss_integrity/tests.md``).
        category: ``CATEGORY_*``.
        decision: ``DECISION_*``; UNKNOWN whenever the inputs are missing (statistic NaN).
        statistic: the statistic, in ``unit``.
        suspect_threshold, alarm_threshold: thresholds of SUSPECT and ALARM, in ``unit``.
        false_alarm_probability: per-evaluation probability on clean data of reaching
            ``suspect_threshold`` (the parameter that set it).
        unit: unit of statistic and thresholds ("1" dimensionless, "dB", "m", ...).
        scope: ``SCOPE_*`` the test implicates when it is SUSPECT or ALARM.
        constellations: constellations it implicates (rfi_msgs/GnssMeasurement codes).
        satellites: ``(constellation, svid)`` pairs it implicates.
    """

    __test__ = False  # not a pytest class despite its name

    name: str
    category: int
    decision: int
    statistic: float
    suspect_threshold: float
    alarm_threshold: float
    false_alarm_probability: float
    unit: str = "1"
    scope: int = SCOPE_NONE
    constellations: tuple[int, ...] = ()
    satellites: tuple[tuple[int, int], ...] = ()


def decide(statistic: float, suspect_threshold: float, alarm_threshold: float) -> int:
    """DECISION_* of a statistic against its thresholds (NaN statistic: UNKNOWN)."""
    if not math.isfinite(statistic):
        return DECISION_UNKNOWN
    if statistic >= alarm_threshold:
        return DECISION_ALARM
    if statistic >= suspect_threshold:
        return DECISION_SUSPECT
    return DECISION_PASS


def unknown(name: str, category: int, suspect_threshold: float = math.nan, alarm_threshold: float = math.nan,
            false_alarm_probability: float = math.nan, unit: str = "1") -> TestOutcome:
    """The outcome of a test that could not run (inputs missing or not enough history)."""
    return TestOutcome(name, category, DECISION_UNKNOWN, math.nan, suspect_threshold, alarm_threshold,
                       false_alarm_probability, unit)


@lru_cache(maxsize=4096)
def normal_threshold(false_alarm_probability: float, two_sided: bool = False) -> float:
    """Threshold of a standard normal statistic (|z| if two-sided) exceeded with that probability
    (memoised: a scipy special function call costs about 10 us, and the tests ask for the same few)."""
    p = false_alarm_probability / (2.0 if two_sided else 1.0)
    return float(-ndtri(p))


@lru_cache(maxsize=4096)
def chi2_threshold(false_alarm_probability: float, dof: int) -> float:
    """Threshold of a chi-square statistic with ``dof`` degrees of freedom exceeded with that probability
    (memoised as :func:`normal_threshold`)."""
    return float(chdtri(dof, false_alarm_probability))


def check_false_alarm_probabilities(params: Any) -> None:
    """Refuse a test's parameters unless 0 < ``alarm_false_alarm_probability`` <= ``false_alarm_probability``
    < 0.5 (the alarm threshold at or beyond the suspect one, both beyond the median).

    Raises:
        ValueError: naming the parameter class and both values.
    """
    alarm = params.alarm_false_alarm_probability
    suspect = params.false_alarm_probability
    if not 0.0 < alarm <= suspect < 0.5:
        raise ValueError(f"{type(params).__name__}: need 0 < alarm_false_alarm_probability ({alarm!r}) <= "
                         f"false_alarm_probability ({suspect!r}) < 0.5")

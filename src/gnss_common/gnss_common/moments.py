"""Signal and noise power from the second and fourth moments of complex samples (the M2M4 estimator).

Pure module (no ROS). The moments estimator of Pauluzzi & Beaulieu (IEEE Trans. Commun. 48(10), 2000; Matzner
1993), complex-sample form: for samples x = s + n with a constant-envelope part s (``|s|^2 = P_s``) and circular
Gaussian noise n of power P_n,

    ``M2 = E|x|^2 = P_s + P_n``,  ``M4 = E|x|^4 = P_s^2 + 4 P_s P_n + 2 P_n^2``,

hence ``2 M2^2 - M4 = P_s^2``: ``P_s = sqrt(2 M2^2 - M4)``, ``P_n = M2 - P_s``.

The one implementation of the formula; the moment sums stay with their callers, which take them differently
(``gnss_correlator.channel_quality``: coherent prompts, their C/N0; ``rfi_monitor.constant_envelope``: IF samples,
complex or the analytic signal of real ones, the noise under a CW or chirp jammer).
"""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, nogil=True)
def m2m4_powers(m2: float, m4: float) -> tuple[float, float]:
    """(P_s, P_n) of the M2M4 estimator (module docstring) from the moments M2 = mean |x|^2 and M4 = mean |x|^4,
    in the samples' unit squared: ``P_s = sqrt(max(2 M2^2 - M4, 0))`` (0 when the moments hold no
    constant-envelope part: noise alone scatters to 2 M2^2 < M4), ``P_n = M2 - P_s`` (not floored: it is <= 0 when
    the moments leave no noise, e.g. a limited block). NaN moments give NaN powers. Callable from numba kernels."""
    ps = math.sqrt(max(2.0 * m2 * m2 - m4, 0.0))  # max(nan, 0.0) is nan, in Python and in numba
    return ps, m2 - ps

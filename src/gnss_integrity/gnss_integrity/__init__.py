"""GNSS integrity: jamming and spoofing detection from any receiver (C/N0, AGC, flags, spectrum,
clock, kinematics, consistency), published as a vendor-neutral state that the fusion acts on.
"""

from gnss_common import numba_cache as _numba_cache  # noqa: F401  (first: kernels cached on the suite's sources)

"""Simulators of the suite's inputs: IF samples with jammers, GNSS/UWB measurements, correlator outputs."""

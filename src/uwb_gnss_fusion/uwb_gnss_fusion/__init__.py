"""Tightly-coupled GNSS/UWB cubature Kalman filter on asynchronous pseudorange, Doppler and UWB ranges,
robust to jamming (Cao et al.).
"""

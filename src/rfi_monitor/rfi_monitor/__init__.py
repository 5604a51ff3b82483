"""Detect, classify and track GNSS jammers (CW, chirp, wideband) from IF sample blocks with an adaptive
fading Kalman filter (Kang et al.).
"""

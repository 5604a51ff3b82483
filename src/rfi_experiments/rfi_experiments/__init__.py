"""Jamming experiments for the suite: scenario simulation, bag play and record, in-process bag replay,
evaluation and reports.
"""

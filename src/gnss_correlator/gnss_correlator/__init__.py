"""GNSS correlators from front-end IF samples (issue 29): GPS L1 C/A acquisition first; tracking and
the node that publishes /gnss/correlators for imm_carrier come next.
"""

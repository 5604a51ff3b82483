"""Scenario stream builders: each module has build(scenario, section, seed) -> (stamp_ns, topic, msg)."""

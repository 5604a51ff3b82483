"""The integrity state and scope codes of rfi_msgs/GnssIntegrity, for pure cores.

The monitor that sets them (``gnss_integrity``) and the fusion that acts on them
(``uwb_gnss_fusion.integrity_policy``) both use these; ``gnss_integrity``'s tests check that they
equal the message's constants, so the cores never import ROS types.
"""

# rfi_msgs/GnssIntegrity STATE_* (jamming_state, spoofing_state)
STATE_UNKNOWN = 0
STATE_NONE = 1
STATE_SUSPECTED = 2
STATE_DETECTED = 3

# rfi_msgs/GnssIntegrity SCOPE_* (spoofing_scope: what a consumer should exclude)
SCOPE_NONE = 0
SCOPE_SATELLITES = 1
SCOPE_CONSTELLATIONS = 2
SCOPE_ALL = 3

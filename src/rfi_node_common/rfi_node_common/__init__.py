"""ROS plumbing shared by the nodes of the suite (the algorithm cores never import it)."""

"""ROS 2 faces of the engine: the estimator node, its pure rules, replay and record."""

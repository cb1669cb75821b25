"""Pure core: types, hand conventions, geometry and errors (no ROS, no model)."""

"""Visual outputs as plain numpy: per-hand output fields and marker descriptions (no rclpy)."""

"""Sparse bundle adjustment: binary keyframe pool, correspondences, solver, pose corrections."""

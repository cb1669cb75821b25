"""Evaluation: the paper's detection, camera-space and world-space metrics (appendix A)."""

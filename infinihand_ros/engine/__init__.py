"""The streaming engine: frames in, per-frame camera and world-space hand results out."""

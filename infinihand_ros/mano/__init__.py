"""Hand kinematic models: the built-in skeleton (default) and real MANO from user files."""

"""Output heads of the geometry branch: causal camera head, DPT depth head and DPT mask head."""

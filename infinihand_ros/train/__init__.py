"""Training of InfiniHand (paper Sec. 3.2-3.3, Sec. 4.1 and appendix B).

Subpackages: ``losses`` (every loss term of appendix B as a pure function of plain tensors,
with its weights in ``config/train_losses.yaml``). The Stage I / Stage II loops come later and
adapt the model's outputs to those functions' arguments.
"""

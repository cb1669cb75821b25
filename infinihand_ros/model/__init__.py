"""PyTorch model of InfiniHand: geometry branch (aggregator, streaming memory, heads) and I/O.

Entry points: ``GeometryModel`` (module tree mirroring LingBot-Map name for name) and
``GeometryStream`` (frames in, per-frame pose encoding, depth, hand masks and patch features out).
"""

"""Datasets: the training-sample format and its PyTorch loader."""

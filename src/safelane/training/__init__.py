"""Training of the neural planners: teacher-labelled data, DAgger, PyTorch training (``safelane[train]``).

Importing this package does not import PyTorch; :func:`~safelane.training.train.train` does, lazily.
"""

"""Figures and reports of experiment results.

Nothing in the package imports this subpackage except the CLI and :mod:`safelane.experiments.reproduce`, and
matplotlib is imported lazily inside the figure functions, so ``import safelane`` never pulls in plotting.
"""

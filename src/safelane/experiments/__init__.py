"""Experiments of the paper and beyond: registry, grid runner, calibration, claims, reproduction."""

"""The neural planner distilled from the calibrated nominal planner of the ``paper`` preset (docs/reproduction.md).

The paper's planners are neural networks trained to imitate a nominal planner; ours is the calibrated rule-based
planner of the ``paper`` preset (:class:`~safelane.planners.base.ExpertPlanner` with the preset's knobs: lateral
natural frequency, position and speed gains, gap position, comfort braking limit). ``safelane train --config
src/safelane/models/distill_paper.yaml`` distils it into the two MLP heads of :class:`~safelane.planners.nn.MLPPlanner`
(same features and export as the shipped ``mlp``); the result ships as ``safelane/models/mlp_paper.npz`` and is
registered as the nominal planner ``mlp_paper``.
"""

from __future__ import annotations

from .nn import MLPPlanner

MODEL = "mlp_paper"


def load_distilled_planner() -> MLPPlanner:
    """The shipped ``mlp_paper`` network (``safelane/models/mlp_paper.npz``)."""
    from importlib.resources import as_file, files

    with as_file(files("safelane") / "models" / f"{MODEL}.npz") as path:
        return MLPPlanner.load(path)

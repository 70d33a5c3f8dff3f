"""Training states for the neural planners: sampled observations, teacher labels, DAgger aggregation.

Two sampled components (mixed by ``paper_fraction``), both ego-relative with a random absolute offset:

* **paper** — around the experiments of §4. A third are initial states as the paper samples them, widened:
  ``p_y = v_y = 0``, ego speed ``U[28, 32]`` (paper ``U[29, 31]``) m/s, ``F`` and ``L1`` at ``30 ± 0.5`` m/s,
  both gaps ``δp ~ U[15, 24]`` (paper ``U[17, 22]``) m. The rest are states of a lane change under way:
  ``p_y ∈ [−0.3, 3.8]`` m, ``v_y ∈ [−1.2, 1.5]`` m/s, ego speed ``U[24, 32]``, ``L1`` ``U[20, 31]`` (it may
  have braked), ``F`` ``U[24, 32]`` m/s, gaps ``U[5, 30]`` m. ``L1``'s plan: cruising, braking within the
  0.5 m/s² promise, or braking hard (up to 6 m/s²) for part of the plan.
* **broad** — well beyond it: ego speed ``U[5, 40]``, relative speeds ``±10`` m/s, gaps ``U[2, 60]`` m, any
  lateral state in ``[−0.8, 4.3]`` m × ``[−2, 2]`` m/s, random piecewise-constant ``L1`` plans within the
  mechanical limits.

Connectivity is drawn per state: ``L1`` connected with ``l1_connected_prob`` (otherwise its plan is zeros, the
constant-speed prediction), ``F`` with ``f_connected_prob``. All randomness comes from the ``Generator`` passed in.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import fields, replace

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ..params import Params
from ..planners.base import Observation
from ..planners.features import features


class DataConfig(BaseModel):
    """Size and mix of the sampled training states."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    n_states: int = Field(100_000, ge=10, description="Sampled states labelled by the teacher.")
    paper_fraction: float = Field(0.5, ge=0.0, le=1.0, description="Share drawn around the paper's experiments.")
    plan_horizon_s: float = Field(4.0, ge=0.0, description="Length of L1's V2X plan [s].")
    l1_connected_prob: float = Field(0.8, ge=0.0, le=1.0, description="Probability that L1 is connected.")
    f_connected_prob: float = Field(0.5, ge=0.0, le=1.0, description="Probability that F is connected.")


def _plans(rng: np.random.Generator, n: int, h: int, paper: bool, prm: Params) -> np.ndarray:
    """``L1`` plans ``(n, h)`` [m/s²]: paper-like braking episodes or random piecewise-constant profiles."""
    if paper:
        kind = rng.integers(0, 3, n)  # 0 cruise, 1 braking within the promise, 2 hard braking
        decel = np.where(kind == 1, rng.uniform(0.0, 0.5, n), rng.uniform(0.0, min(6.0, prm.a_x_d), n))
        decel = np.where(kind == 0, 0.0, decel)
        start = rng.integers(0, max(h, 1), n)
        length = rng.integers(1, h + 2, n)
        steps = np.arange(h)
        on = (steps[None, :] >= start[:, None]) & (steps[None, :] < (start + length)[:, None])
        return np.where(on, -decel[:, None], 0.0)
    n_seg = 3
    cuts = np.sort(rng.integers(0, h + 1, (n, n_seg - 1)), axis=1)
    values = rng.uniform(-prm.a_x_d, prm.a_x_a, (n, n_seg))
    seg = (np.arange(h)[None, :, None] >= cuts[:, None, :]).sum(axis=-1)
    return np.take_along_axis(values, seg, axis=1)


def sample_observations(n: int, rng: np.random.Generator, params: Params, cfg: DataConfig) -> Observation:
    """``n`` random observations from the mix described in the module docstring."""
    n_paper = round(cfg.paper_fraction * n)
    h = round(cfg.plan_horizon_s / params.dt)
    parts = []
    for size, paper in ((n_paper, True), (n - n_paper, False)):
        if paper:
            start = rng.random(size) < 1 / 3
            delta_p = rng.uniform(15.0, 24.0, size)  # the paper's δp ~ U[17, 22], widened
            v_x = np.where(start, rng.uniform(28.0, 32.0, size), rng.uniform(24.0, 32.0, size))
            v_x_l = np.where(start, rng.uniform(29.5, 30.5, size), rng.uniform(20.0, 31.0, size))
            v_x_f = np.where(start, rng.uniform(29.5, 30.5, size), rng.uniform(24.0, 32.0, size))
            gap_l = np.where(start, delta_p, rng.uniform(5.0, 30.0, size))
            gap_f = np.where(start, delta_p, rng.uniform(5.0, 30.0, size))
            p_y = np.where(start, 0.0, rng.uniform(-0.3, 3.8, size))
            v_y = np.where(start, 0.0, rng.uniform(-1.2, 1.5, size))
        else:
            v_x = rng.uniform(5.0, 40.0, size)
            v_x_l = np.maximum(v_x + rng.uniform(-10.0, 10.0, size), 0.0)
            v_x_f = np.maximum(v_x + rng.uniform(-10.0, 10.0, size), 0.0)
            gap_l, gap_f = rng.uniform(2.0, 60.0, size), rng.uniform(2.0, 60.0, size)
            p_y, v_y = rng.uniform(-0.8, 4.3, size), rng.uniform(-2.0, 2.0, size)
        l1_conn = rng.random(size) < cfg.l1_connected_prob
        plan = np.where(l1_conn[:, None], _plans(rng, size, h, paper, params), 0.0)
        p_x = rng.uniform(0.0, 1000.0, size)
        parts.append(
            Observation(
                p_x=p_x,
                p_y=p_y,
                v_x=v_x,
                v_y=v_y,
                p_x_l=p_x + gap_l,
                v_x_l=v_x_l,
                p_x_f=p_x - gap_f,
                v_x_f=v_x_f,
                l1_plan=plan,
                l1_connected=l1_conn,
                f_connected=rng.random(size) < cfg.f_connected_prob,
                completed=p_y > params.y_boundary,
            )
        )
    return concat_observations(parts)


def concat_observations(batches: Sequence[Observation]) -> Observation:
    """One :class:`Observation` holding all ``batches`` (``t`` of the first; plans zero-padded to the longest)."""
    if not batches:
        raise ValueError("no observations to concatenate")
    h = max(np.asarray(b.l1_plan).shape[1] for b in batches)
    out = {}
    for f in fields(Observation):
        if f.name == "t":
            continue
        if f.name == "scenario_id":  # ids only where every batch has them
            ids = [b.scenario_id for b in batches]
            out[f.name] = None if any(i is None for i in ids) else np.concatenate(ids)
            continue
        if f.name == "l1_plan":
            arrays = [np.pad(np.asarray(b.l1_plan, float), ((0, 0), (0, h - np.shape(b.l1_plan)[1]))) for b in batches]
        else:
            arrays = [np.asarray(getattr(b, f.name)) for b in batches]
        out[f.name] = np.concatenate(arrays, axis=0)
    return Observation(**out, t=batches[0].t)


def take(obs: Observation, index: np.ndarray) -> Observation:
    """The sub-batch ``obs[index]`` (``index``: integer or boolean array over the batch)."""
    return replace(
        obs,
        **{
            f.name: np.asarray(getattr(obs, f.name))[index]
            for f in fields(Observation)
            if f.name != "t" and getattr(obs, f.name) is not None
        },
    )


def label(obs: Observation, params: Params, teacher) -> tuple[np.ndarray, np.ndarray]:
    """Model inputs ``x`` ``(B, F)`` and teacher actions ``y`` ``(B, 2)`` [m/s²] for a batch of states."""
    a_x, a_y = teacher(obs, params)
    return features(obs, params), np.stack([a_x, a_y], axis=-1)

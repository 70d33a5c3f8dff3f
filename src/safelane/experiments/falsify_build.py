"""The falsifier's specs made real (:mod:`safelane.experiments.falsify_space` makes the specs): :func:`build` turns
a spec into a :class:`~safelane.sim.ScenarioBatch` and says which rows satisfy the assumptions at ``t = 0`` (the
others are dropped and counted): the ego's evasion plan under the most conservative assumptions exists
(:func:`safelane.safety.plan_evasion`), the leader chain is safe (:func:`safelane.safety.leader_chain`, ``unsafe``
False) and F can keep its margin behind L1 braking at ``a_x_d`` (the same analysis on the F–L1 pair).
:func:`planner_for` is each row's adversarial nominal planner, :func:`hooks_for` its traffic hooks.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..params import Params
from ..planners.adversarial import HugFollower, HugLeader, Mixture, Oscillating, RecklessMerge
from ..safety import leader_chain, plan_evasion
from ..sim.scenario import ScenarioBatch
from .falsify_space import lin


def planner_for(spec: dict, prm: Params) -> Mixture:
    """The adversarial nominal planner of each row (:class:`Mixture` over the four adversaries)."""
    q = spec["planner"]
    gains = dict(
        k_p=lin(q[:, 0], 0.1, 10.0),
        k_v=lin(q[:, 1], 0.0, 10.0),
        offset_m=lin(q[:, 2], -1.0, 3.0) ** 3 / 9,
        omega=lin(q[:, 3], 0.3, 2.0),
        zeta=lin(q[:, 4], 0.05, 1.5),
    )
    osc = Oscillating(
        period_s=lin(q[:, 5], prm.dt, 3.0),
        phase_x=q[:, 6],
        phase_y=q[:, 7],
        amp_x=lin(q[:, 8], 0.0, prm.a_x_d),
        mean_x=lin(q[:, 9], -prm.a_x_d, prm.a_x_a),
        amp_y=lin(q[:, 10], 0.0, prm.a_y_m),
        mean_y=lin(q[:, 11], -0.5, prm.a_y_m),
    )
    reckless = RecklessMerge(a_x=lin(q[:, 9], -prm.a_x_d, prm.a_x_a), lateral_gain=lin(q[:, 10], 0.2, 1.0))
    return Mixture((HugLeader(**gains), HugFollower(**gains), osc, reckless), spec["mode"])


def build(spec: dict, prm: Params, *, profiles: bool) -> tuple[ScenarioBatch, np.ndarray]:
    """The batch of ``spec`` and the mask of rows that satisfy the assumptions at ``t = 0`` (module docstring).

    ``profiles``: give L(N+1) the spec's piecewise-constant profile (:func:`safelane.sim.traffic.with_last_profile`);
    otherwise it brakes suddenly at ``decel_last`` from ``brake_start_s``.
    """
    n = spec["n"]
    bsz = len(n)
    k = int(n.max()) + 2
    slots = np.arange(k)[None, :]
    valid = slots <= n[:, None] + 1
    connected = (slots >= 1) & (slots <= n[:, None])
    connected = connected | ((slots == 0) & spec["f_connected"][:, None])
    human = (slots >= 1) & (slots <= n[:, None]) & _leaders(spec["human"], k)
    margin = np.where(human, prm.p_m_human, prm.p_m)
    v = np.zeros((bsz, k))
    for j in range(k - 1, 0, -1):  # back to front from L(N+1)
        ahead = v[:, j + 1] if j + 1 < k else spec["base_v"]
        v[:, j] = np.where(
            j == n + 1, spec["base_v"], np.where(j <= n, np.maximum(ahead + spec["lv_dv"][:, j - 1], 0.0), ahead)
        )
    ego_vx = np.maximum(v[:, 1] + spec["ego_dv"], 0.0)
    v[:, 0] = np.maximum(ego_vx + spec["f_dv"], 0.0)
    x = np.zeros((bsz, k))
    x[:, 1] = prm.p_m + spec["l1_slack"]
    for j in range(1, k - 1):
        step = np.where(j <= n, margin[:, j] + spec["slack"][:, j - 1], 1e6)
        x[:, j + 1] = x[:, j] + step
    x[:, 0] = -(prm.p_m + spec["f_slack"])
    batch = ScenarioBatch(
        ego_x=np.zeros(bsz),
        ego_y=spec["ego_y"].astype(float),
        ego_vx=ego_vx,
        ego_vy=spec["ego_vy"].astype(float),
        x=x,
        v=v,
        valid=valid,
        connected=connected,
        human=human,
        promise_decel=np.where(connected & (slots >= 1), _leaders(spec["promise_decel"], k), 0.5),
        promise_accel=np.where(connected & (slots >= 1), _leaders(spec["promise_accel"], k), 0.5),
        n_connected=n.astype(np.int64),
        follower_aggressive=spec["f_aggressive"] & ~spec["f_connected"],
        decel_last=spec["decel_last"].astype(float),
        p_v=np.zeros(bsz),
        variant=spec["variant"].astype(np.int64),
        scenario_id=np.arange(bsz, dtype=np.int64),
    )
    if profiles:
        from ..sim.traffic import with_last_profile

        batch = with_last_profile(batch, spec["profile_t"], spec["profile_a"], prm)
    if "l0_present" in spec:  # the realistic world: L0 (the shield's own initial check decides what is evadable)
        l0_v = np.maximum(ego_vx + spec["l0_dv"], 0.0)
        batch = dataclasses.replace(
            batch, l0_x=np.where(spec["l0_present"], prm.p_m + spec["l0_slack"], np.inf), l0_v=l0_v,
            l0_profile_t=spec["l0_profile_t"].astype(float), l0_profile_a=spec["l0_profile_a"].astype(float),
            world_key=spec["world_key"].astype(np.int64),
        )  # fmt: skip
        if np.any(spec.get("own_n", 0)):  # a connected own lane (specs written before it have no "own_n")
            batch = _own_chain(batch, spec, prm)
    return batch, _assumptions_hold(batch, prm)


def _own_chain(batch, spec: dict, prm: Params):
    """The own lane as a chain (sim/own_chain.py): ``own_n`` connected vehicles from L0 on, then the head; each a
    slack ahead of the one behind it, slots beyond a row's head empty (``+inf``)."""
    n = spec["own_n"].astype(np.int64)
    j = n.max()
    slot = np.arange(1, j + 1)[None, :]
    x = batch.l0_x[:, None] + np.cumsum(prm.p_m + spec["own_slack"][:, :j], axis=1)
    v = np.maximum(batch.l0_v[:, None] + np.cumsum(spec["own_dv"][:, :j], axis=1), 0.0)
    present = slot <= n[:, None]
    return dataclasses.replace(
        batch, own_ahead_x=np.where(present, x, np.inf), own_ahead_v=np.where(present, v, 0.0),
        own_promise=np.where(slot <= n[:, None], spec["own_promise"][:, :j], 0.0), own_n_connected=n,
        own_brake_t=spec["own_brake_t"][:, :j].astype(float),
    )  # fmt: skip


def _leaders(a: np.ndarray, k: int) -> np.ndarray:
    """Per-leader ``(B, L)`` columns placed on slots ``1..k−1`` of a ``(B, k)`` array (slot 0 copies slot 1)."""
    out = a[:, : k - 1]
    return np.concatenate([out[:, :1], out], axis=1)


def _assumptions_hold(b: ScenarioBatch, prm: Params) -> np.ndarray:
    """Rows whose ``t = 0`` state satisfies the assumptions (module docstring)."""
    plan = plan_evasion(
        b.ego_x, b.ego_y, b.ego_vx, b.ego_vy, b.x[:, 1], b.v[:, 1], prm.a_x_d, b.x[:, 0], b.v[:, 0], True, prm
    )
    ok = np.asarray(plan.feasible, bool).copy()
    # F behind L1, L1 braking at a_x_d: the chain analysis on the F–L1 pair.
    f_pair = leader_chain(
        np.stack([b.x[:, 0], b.x[:, 1]], 1), np.stack([b.v[:, 0], b.v[:, 1]], 1), np.full((len(b), 1), prm.a_x_d), prm
    )
    ok &= ~np.asarray(f_pair.unsafe, bool)
    for n in np.unique(b.n_connected):
        rows = np.flatnonzero(b.n_connected == n)
        if n == 0:
            continue
        chain = leader_chain(
            b.x[rows, 1 : n + 2],
            b.v[rows, 1 : n + 2],
            b.promise_decel[rows, 1 : n + 1],
            prm,
            human_driven=b.human[rows, 1 : n + 1],
        )
        ok[rows] &= ~np.asarray(chain.unsafe, bool)
    return ok


def hooks_for(spec: dict, prm: Params, recorder=None, k: int | None = None):
    """:class:`~safelane.sim.traffic.WaveHooks` driving the leaders' own tasks and F's wish from the spec (square
    waves between two levels: inside each leader's promise, inside F's ``[−a_x_d, a_x_a]``), as data the compiled
    closed loop reads. ``recorder``: a :class:`~safelane.experiments.falsify.LaneGapRecorder` whose running minimum
    the hooks keep (sampled at the start of every period); ``k``: the batch's slots (default: the spec's largest
    ``N`` plus 2)."""
    from ..sim.traffic import WaveHooks

    k = int(spec["n"].max()) + 2 if k is None else k
    pd_, pa = _leaders(spec["promise_decel"], k), _leaders(spec["promise_accel"], k)
    lane = {}
    if recorder is not None:
        lane = dict(lane_valid=recorder.pairs, lane_margin=recorder.margin, lane_ratio=recorder.min_ratio)
    return WaveHooks(
        task_low=-pd_, task_span=pd_ + pa, task_hi=_leaders(spec["task_hi"], k), task_lo=_leaders(spec["task_lo"], k),
        # Each leader's wave is shifted by a slot-dependent share of the period.
        task_phase=spec["task_phase"][:, None] + 0.37 * np.arange(k)[None, :], task_period=spec["task_period_s"],
        f_period=spec["f_period_s"], f_phase=spec["f_phase"], f_hi=spec["f_hi"], f_lo=spec["f_lo"], **lane,
    )  # fmt: skip


def with_profile_fields() -> bool:
    """Whether :class:`ScenarioBatch` carries L(N+1) profiles yet (the extension point is being wired)."""
    return "last_profile_t" in {f.name for f in dataclasses.fields(ScenarioBatch)}

"""The paper's traffic bound to one batch (:class:`safelane.sim.traffic.PaperTraffic`): per-period accelerations of
the target-lane vehicles from :mod:`safelane.sim.behaviours`."""

from __future__ import annotations

import numpy as np

from ..params import Params
from ..safety._backend import ARRAY
from .behaviours import follower_accel, last_accel, leader_accels, leader_roles, leader_task, reactive_leader_accels
from .rng import counter_uniform
from .traffic import TrafficHooks, TrafficView, hook_output, profile_segment


class BoundPaperTraffic:
    """Constant per-batch arrays of the paper's behaviours; ``__call__(view)`` gives one period's accelerations."""

    def __init__(self, batch, seed: int, prm: Params, cfg, hooks: TrafficHooks, leader_rule: str):
        if leader_rule not in ("worst_case", "reactive"):
            raise ValueError(f"leader_rule must be 'worst_case' or 'reactive'; got {leader_rule!r}")
        self.b, self.seed, self.prm, self.cfg, self.hooks, self.rule = batch, seed, prm, cfg, hooks, leader_rule
        k = batch.x.shape[1]
        self.gap0 = batch.ego_x - batch.x[:, 0]
        self.any_violation = bool((batch.p_v > 0.0).any())
        self.v_desired = np.asfortranarray(batch.v.copy())
        self.margin = np.where(batch.human, prm.p_m_human, prm.p_m)
        self.roles = leader_roles(batch.valid, batch.connected, batch.n_connected)
        self.last_slot_mask = np.arange(k)[None, :] == (batch.n_connected + 1)[:, None]

    def __call__(self, view: TrafficView):
        b, prm, cfg, hooks = self.b, self.prm, self.cfg, self.hooks
        x, v = view.x, view.v
        slots = np.arange(x.shape[1])
        violating = pick = None  # counter-based: skipping the draws when p_v = 0 everywhere changes nothing else
        if self.any_violation:
            draw = counter_uniform(self.seed, b.scenario_id[:, None], view.step, slots[None, :], 7)
            violating = draw < b.p_v[:, None]
            pick = counter_uniform(self.seed, b.scenario_id[:, None], view.step, slots[None, :], 8)
        wanted = None
        if hooks.leader_task is not None:
            wanted = hook_output("leader_task", hooks.leader_task(view, prm), x.shape)
        task = leader_task(v, self.v_desired, b.promise_decel, b.promise_accel, wanted)
        switch = None
        if b.last_profile_t is None:
            a_last = last_accel(ARRAY, view.t, cfg.brake_start_s, b.decel_last)
        else:
            a_last, t_sw, a2 = profile_segment(view.t, prm.dt, b.last_profile_t, b.last_profile_a)
            if (t_sw < prm.dt).any():
                on = self.last_slot_mask & (t_sw < prm.dt)[:, None]
                switch = (np.where(on, t_sw[:, None], prm.dt), np.where(on, a2[:, None], 0.0))
        if self.rule == "worst_case":
            acc = leader_accels(x, v, self.margin, self.roles, view.bounds, task, a_last, b.decel_last, violating,
                                pick, prm)  # fmt: skip
        else:
            acc = reactive_leader_accels(x, v, self.margin, self.roles, task, a_last, b.decel_last, violating, pick,
                                         prm)  # fmt: skip
        f_wish = None
        if hooks.follower_wish is not None:
            wish = hook_output("follower_wish", hooks.follower_wish(view, prm), (len(b),))
            f_wish = np.clip(wish, -prm.a_x_d, prm.a_x_a)
        acc[:, 0] = follower_accel(
            x[:, 0], v[:, 0], x[:, 1], v[:, 1], view.ego_x, view.ego_vx, b.follower_aggressive, view.completed,
            self.gap0, prm, cfg.follower_open_decel, cfg.follower_open_gap_m, wanted=f_wish,
            ignores_ego=cfg.follower_ignores_ego,
        )  # fmt: skip
        return acc, switch

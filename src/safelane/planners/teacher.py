"""Teacher of the neural planners: a batched short-horizon optimal-control planner (cross-entropy method, NumPy).

For each state of a batch it optimises the ego's accelerations over the next ``horizon_s`` seconds and returns
the first one (receding horizon), so it is itself a :class:`~safelane.planners.base.NominalPlanner` — slower
than a network, but better than :class:`~safelane.planners.base.ExpertPlanner`, which ignores the follower and
whether the gap is open. Everything is vectorised over the batch; no Python loop over states.

Model. Each axis's acceleration is piecewise linear through knots at ``knot_times_s`` (held after the last
knot), within the mechanical limits; the ego is a double integrator stepped exactly at ``params.dt``. ``L1``
follows its V2X plan (``obs.l1_plan``; constant speed after it, speed floored at 0); the follower, by default,
copies ``L1``'s speed changes (``follower_model="copies_l1"``: traffic behind a braking ``L1`` brakes too;
``"constant_speed"`` is the pessimistic alternative). Cost, integrated over the horizon at ``eval_every · dt``
(``y`` lateral centre, ``x`` ego position, ``g_l = x_l − x``, ``g_f = x − x_f``, ``ov ∈ [0, 1]`` the fraction of
the ego's width overlapping the target lane):

* progress ``w_lateral (y − w_l)²``, ``w_overshoot relu(y − w_l)²`` and, at the end, ``w_lateral_speed v_y²``;
* safety in the target lane ``ov · [w_gap (relu(p_m + m_l − g_l)² + relu(p_m + m_f − g_f)²)
  + w_collision (relu(p_m − g_l)² + relu(p_m − g_f)²)]`` with a larger rear margin ``m_f`` for a
  non-connected follower (it may be aggressive: accelerate at ``a_x_a``) than for a connected one;
* gap centring ``w_centre (x − x_target)²``, ``x_target = x_f + rear_share (x_l − x_f)`` (ahead of centre:
  the paper notes that being close to ``L1`` buys time against a follower that catches up);
* speed ``w_speed (v_x − v_l)²`` and ``w_stop relu(−v_x)²``;
* comfort ``w_ax a_x² + w_ay a_y²`` (mean over knots) and ``w_jerk`` on knot-to-knot changes.

Overlap gating is what makes the teacher wait (hesitate below the lane boundary) or abort (return) when the gap
is closed, and merge at full lateral authority when it is open. Optimiser: CEM with ``n_candidates`` samples,
``n_elites`` elites, ``n_iters`` rounds; the standard-normal perturbations are drawn once from ``seed`` and shared
by every state (common random numbers), so a state's label does not depend on the batch it comes in, and the
same call gives the same answer. The best of {final CEM mean, best sample seen} is then polished by
``n_refine`` rounds of a Gauss-Newton line search (exact gradient; block-diagonal Gauss-Newton curvature with the
hinge activity frozen), and its first knot is returned. About 25 s per 100k states on one core.
"""

from __future__ import annotations

import itertools
from functools import cached_property
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from ..params import Params
from .base import Observation

_NonNeg = Field(ge=0.0)


class TeacherConfig(BaseModel):
    """Horizon, cost weights [per unit²·s] and optimiser settings of :class:`OptimalControlTeacher`."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    horizon_s: float = Field(4.0, gt=0.0, description="Planning horizon [s].")
    knot_times_s: tuple[float, ...] = Field((0.0, 0.5, 1.5, 3.0), description="Acceleration knots [s], from 0.")
    eval_every: int = Field(2, ge=1, description="Cost evaluated every this many control periods.")
    w_lateral: float = Field(1.0, ge=0.0, description="Weight of (y − w_l)² [1/(m² s)].")
    w_lateral_speed: float = Field(2.0, ge=0.0, description="Weight of the final v_y² [s²/m²].")
    w_overshoot: float = Field(20.0, ge=0.0, description="Weight of relu(y − w_l)² (beyond the target centre).")
    w_gap: float = Field(10.0, ge=0.0, description="Weight of the squared margin shortfall in the target lane.")
    w_collision: float = Field(1000.0, ge=0.0, description="Weight of the squared shortfall below p_m.")
    margin_front_m: float = Field(2.0, ge=0.0, description="Desired gap to L1 beyond p_m [m].")
    margin_rear_m: float = Field(6.0, ge=0.0, description="Desired gap to a non-connected follower beyond p_m [m].")
    margin_rear_connected_m: float = Field(1.0, ge=0.0, description="Same, connected (collaborative) follower [m].")
    follower_model: Literal["copies_l1", "constant_speed"] = Field(
        "copies_l1", description="Predicted follower motion: L1's speed changes, or constant speed."
    )
    w_centre: float = Field(0.02, ge=0.0, description="Weight of (x − x_target)² [1/(m² s)].")
    rear_share: float = Field(0.55, ge=0.0, le=1.0, description="x_target's share of the F→L1 distance.")
    w_speed: float = Field(0.05, ge=0.0, description="Weight of (v_x − v_l)² [s/m²].")
    w_stop: float = Field(100.0, ge=0.0, description="Weight of negative ego speed squared.")
    w_ax: float = Field(0.02, ge=0.0, description="Comfort weight of a_x² [s⁴/m²].")
    w_ay: float = Field(0.2, ge=0.0, description="Comfort weight of a_y² [s⁴/m²].")
    w_jerk: float = Field(0.01, ge=0.0, description="Weight of squared knot-to-knot acceleration changes.")
    n_candidates: int = Field(64, ge=2, description="CEM samples per state and round.")
    n_elites: int = Field(8, ge=1, description="CEM elites.")
    n_iters: int = Field(4, ge=1, description="CEM rounds.")
    init_std_ax: float = Field(3.0, gt=0.0, description="Initial sampling std of a_x knots [m/s²].")
    init_std_ay: float = Field(1.0, gt=0.0, description="Initial sampling std of a_y knots [m/s²].")
    min_std: float = Field(0.05, gt=0.0, description="Floor of the sampling std [m/s²].")
    n_refine: int = Field(6, ge=0, description="Gauss-Newton line-search rounds after CEM.")
    refine_steps: tuple[float, ...] = Field((1.0, 0.5, 0.25, 0.1), description="Fractions of the GN step tried.")
    seed: int = Field(0, ge=0, description="Seed of the shared CEM perturbations.")
    chunk_size: int = Field(2048, ge=1, description="States optimised at once (memory ~ chunk·candidates·steps).")

    @model_validator(mode="after")
    def _check(self) -> TeacherConfig:
        knots = self.knot_times_s
        if not knots or knots[0] != 0.0 or any(b <= a for a, b in itertools.pairwise(knots)):
            raise ValueError(f"knot_times_s={knots} must start at 0 and increase")
        if knots[-1] > self.horizon_s:
            raise ValueError(f"last knot {knots[-1]} s lies beyond horizon_s={self.horizon_s}")
        if self.n_elites > self.n_candidates:
            raise ValueError(f"n_elites={self.n_elites} exceeds n_candidates={self.n_candidates}")
        return self


def _integration_maps(cfg: TeacherConfig, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(t, Mp, Mv, interp)``: eval times ``(T,)`` [s] and the linear maps from knots ``(K,)`` to the
    position and speed changes at those times ``(K, T)`` (exact for accelerations held over each ``dt``);
    ``interp`` ``(K, n)`` gives the acceleration at every control period."""
    n = max(round(cfg.horizon_s / dt), 1)
    t_steps = dt * np.arange(n)
    knots = np.asarray(cfg.knot_times_s)
    interp = np.stack([np.interp(t_steps, knots, np.eye(len(knots))[k]) for k in range(len(knots))])
    idx = np.arange(cfg.eval_every, n + 1, cfg.eval_every)
    i = np.arange(n)
    lower = i[None, :] < idx[:, None]  # (T, n): step i contributes to eval step idx
    mv = dt * lower
    mp = dt * dt * (idx[:, None] - i[None, :] - 0.5) * lower
    return dt * idx, (interp @ mp.T), (interp @ mv.T), interp


def _apply(u: np.ndarray, m: np.ndarray) -> np.ndarray:
    """``u @ m`` for ``u`` ``(B, C, K)`` and ``m`` ``(K, T)`` as one BLAS call (a stacked matmul loops over B)."""
    b, c, k = u.shape
    return (np.ascontiguousarray(u).reshape(b * c, k) @ m).reshape(b, c, m.shape[1])


class OptimalControlTeacher:
    """Receding-horizon CEM planner; ``teacher(obs, params) -> (a_x, a_y)``. See the module docstring."""

    def __init__(self, config: TeacherConfig | None = None) -> None:
        self.config = config or TeacherConfig()

    @cached_property
    def _eps(self) -> np.ndarray:
        cfg = self.config
        dim = 2 * len(cfg.knot_times_s)
        eps = np.random.default_rng(cfg.seed).standard_normal((cfg.n_iters, cfg.n_candidates, dim))
        eps[:, 0] = 0.0  # candidate 0 is the current mean
        return eps.astype(np.float32)

    def __call__(self, obs: Observation, params: Params) -> tuple[np.ndarray, np.ndarray]:
        """First action ``(a_x, a_y)`` [m/s²], each ``(B,)``, of the optimised plans of a batch."""
        n = np.asarray(obs.p_x).shape[0]
        a_x, a_y = np.empty(n), np.empty(n)
        step = self.config.chunk_size
        for s in range(0, n, step):
            a_x[s : s + step], a_y[s : s + step] = self._solve(obs, slice(s, s + step), params)
        return a_x, a_y

    def _solve(self, obs: Observation, sl: slice, prm: Params) -> tuple[np.ndarray, np.ndarray]:
        cfg = self.config
        t, mp, mv, interp = _integration_maps(cfg, prm.dt)
        k = len(cfg.knot_times_s)
        f32 = np.float32
        p_y, v_y, v_x = (np.asarray(getattr(obs, n), np.float64)[sl] for n in ("p_y", "v_y", "v_x"))
        gap_l0 = np.asarray(obs.p_x_l, np.float64)[sl] - np.asarray(obs.p_x, np.float64)[sl]
        gap_f0 = np.asarray(obs.p_x, np.float64)[sl] - np.asarray(obs.p_x_f, np.float64)[sl]
        v_l0, v_f = np.asarray(obs.v_x_l, np.float64)[sl], np.asarray(obs.v_x_f, np.float64)[sl]
        b = p_y.shape[0]
        # L1's predicted speed and position (relative to the ego's start) at the eval times.
        n_fine = interp.shape[1]
        plan = np.zeros((b, n_fine))
        raw = np.asarray(obs.l1_plan, np.float64)[sl][:, :n_fine]
        plan[:, : raw.shape[1]] = raw
        v_path = np.maximum(v_l0[:, None] + prm.dt * np.cumsum(plan, axis=1), 0.0)
        v_prev = np.concatenate([v_l0[:, None], v_path[:, :-1]], axis=1)
        p_path = gap_l0[:, None] + np.cumsum(0.5 * (v_prev + v_path) * prm.dt, axis=1)
        idx = np.round(t / prm.dt).astype(int) - 1
        x_l, v_l = p_path[:, idx], v_path[:, idx]
        x_f = -gap_f0[:, None] + v_f[:, None] * t
        if cfg.follower_model == "copies_l1":
            dv = np.maximum(v_path - v_l0[:, None], -v_f[:, None])  # F's speed change, floored at a stop
            x_f = x_f + np.cumsum(0.5 * (np.concatenate([np.zeros((b, 1)), dv[:, :-1]], 1) + dv) * prm.dt, 1)[:, idx]
        margin_f = np.where(np.asarray(obs.f_connected, bool)[sl], cfg.margin_rear_connected_m, cfg.margin_rear_m)
        ctx = {
            "y0": (p_y[:, None] + v_y[:, None] * t)[:, None, :].astype(f32),
            "vy0": v_y[:, None].astype(f32),
            "x0": (v_x[:, None] * t)[:, None, :].astype(f32),
            "vx0": v_x[:, None, None].astype(f32),
            "x_l": x_l[:, None, :].astype(f32),
            "v_l": v_l[:, None, :].astype(f32),
            "x_f": x_f[:, None, :].astype(f32),
            "x_target": (x_f + cfg.rear_share * (x_l - x_f))[:, None, :].astype(f32),
            "lim_f": (prm.p_m + margin_f)[:, None, None].astype(f32),
            "mp": mp.astype(f32),
            "mv": mv.astype(f32),
        }
        lo = np.array([-prm.a_x_d] * k + [-prm.a_y_m] * k, f32)
        hi = np.array([prm.a_x_a] * k + [prm.a_y_m] * k, f32)
        mean = np.zeros((b, 2 * k), f32)
        std = np.tile(np.array([cfg.init_std_ax] * k + [cfg.init_std_ay] * k, f32), (b, 1))
        best_u, best_c = mean.copy(), np.full(b, np.inf, f32)
        rows = np.arange(b)[:, None]
        for it in range(cfg.n_iters):
            u = np.clip(mean[:, None, :] + std[:, None, :] * self._eps[it], lo, hi)
            cost = self._cost(u, ctx, prm, t)
            elite = np.argpartition(cost, cfg.n_elites - 1, axis=1)[:, : cfg.n_elites]
            j = np.argmin(cost, axis=1)
            better = cost[rows[:, 0], j] < best_c
            best_c = np.where(better, cost[rows[:, 0], j], best_c)
            best_u = np.where(better[:, None], u[rows[:, 0], j], best_u)
            eu = u[rows, elite]
            mean, std = eu.mean(axis=1), np.maximum(eu.std(axis=1), cfg.min_std)
        final = self._cost(mean[:, None, :], ctx, prm, t)[:, 0]
        u = np.where((final <= best_c)[:, None], mean, best_u)
        u = self._refine(u, ctx, prm, t, lo, hi).astype(np.float64)
        return u[:, 0], u[:, k]

    def _refine(self, u: np.ndarray, ctx: dict, prm: Params, t: np.ndarray, lo, hi) -> np.ndarray:
        """Gauss-Newton line search from ``u`` ``(B, 2K)``: each round tries the fractions ``refine_steps`` of the
        (block-diagonal, hinge-activity-frozen) Gauss-Newton step of ``a_x``'s knots, of ``a_y``'s, and of both,
        and keeps the best candidate or stays."""
        cfg = self.config
        k = len(cfg.knot_times_s)
        steps = np.asarray(cfg.refine_steps, np.float32)
        rows = np.arange(u.shape[0])
        for _ in range(cfg.n_refine):
            _, g, h_x, h_y = self._cost(u[:, None, :], ctx, prm, t, grad=True)
            dirs = np.zeros((u.shape[0], 3, 2 * k), np.float32)
            for j, (sl, h) in enumerate(((slice(0, k), h_x), (slice(k, 2 * k), h_y))):
                dirs[:, j, sl] = dirs[:, 2, sl] = np.linalg.solve(h, g[:, 0, sl, None])[..., 0]
            cand = u[:, None, None, :] - steps[None, None, :, None] * dirs[:, :, None, :]
            cand = np.concatenate([u[:, None, :], cand.reshape(u.shape[0], -1, 2 * k)], axis=1)
            cand = np.clip(cand, lo, hi)
            u = cand[rows, np.argmin(self._cost(cand, ctx, prm, t), axis=1)]
        return u

    def _cost(self, u: np.ndarray, c: dict, prm: Params, t: np.ndarray, grad: bool = False):
        """Cost ``(B, C)`` of knot vectors ``u`` ``(B, C, 2K)`` (first ``K``: ``a_x``, then ``a_y``); with
        ``grad``, also its gradient ``(B, C, 2K)`` with respect to ``u`` (exact where the cost is smooth) and the
        Gauss-Newton blocks ``(B, K, K)`` of ``a_x`` and ``a_y`` (for ``C = 1``; curvature through ``ov`` left out)."""
        cfg = self.config
        k = len(cfg.knot_times_s)
        ux, uy = u[..., :k], u[..., k:]
        y = c["y0"] + _apply(uy, c["mp"])
        x = c["x0"] + _apply(ux, c["mp"])
        v_x = c["vx0"] + _apply(ux, c["mv"])
        v_y_end = c["vy0"] + _apply(uy, c["mv"][:, -1:])[..., 0]
        ov_raw = (y - (prm.lane_width - prm.vehicle_width)) / prm.vehicle_width
        ov = np.clip(ov_raw, 0.0, 1.0)
        short_front = np.maximum(prm.p_m + cfg.margin_front_m - (c["x_l"] - x), 0.0)
        short_rear = np.maximum(c["lim_f"] - (x - c["x_f"]), 0.0)
        hard_front = np.maximum(prm.p_m - (c["x_l"] - x), 0.0)
        hard_rear = np.maximum(prm.p_m - (x - c["x_f"]), 0.0)
        lane_cost = cfg.w_gap * (short_front**2 + short_rear**2) + cfg.w_collision * (hard_front**2 + hard_rear**2)
        beyond = np.maximum(y - prm.lane_width, 0.0)
        slow = np.minimum(v_x, 0.0)
        running = (
            cfg.w_lateral * (y - prm.lane_width) ** 2
            + cfg.w_overshoot * beyond**2
            + ov * lane_cost
            + cfg.w_centre * (x - c["x_target"]) ** 2
            + cfg.w_speed * (v_x - c["v_l"]) ** 2
            + cfg.w_stop * slow**2
        )
        dt_eval, horizon = t[0], t[-1]
        dux, duy = np.diff(ux, axis=-1), np.diff(uy, axis=-1)
        cost = (
            dt_eval * running.sum(-1)
            + cfg.w_lateral_speed * v_y_end**2
            + (cfg.w_ax * (ux**2).mean(-1) + cfg.w_ay * (uy**2).mean(-1)) * horizon
            + cfg.w_jerk * ((dux**2).sum(-1) + (duy**2).sum(-1))
        )
        if not grad:
            return cost
        d_ov = np.where((ov_raw > 0.0) & (ov_raw < 1.0), 1.0 / prm.vehicle_width, 0.0)
        d_y = 2 * cfg.w_lateral * (y - prm.lane_width) + 2 * cfg.w_overshoot * beyond + d_ov * lane_cost
        d_x = ov * (2 * cfg.w_gap * (short_front - short_rear) + 2 * cfg.w_collision * (hard_front - hard_rear))
        d_x = d_x + 2 * cfg.w_centre * (x - c["x_target"])
        d_vx = 2 * cfg.w_speed * (v_x - c["v_l"]) + 2 * cfg.w_stop * slow
        g_x = dt_eval * (_apply(d_x, c["mp"].T) + _apply(d_vx, c["mv"].T)) + 2 * cfg.w_ax * horizon / k * ux
        g_y = dt_eval * _apply(d_y, c["mp"].T) + 2 * cfg.w_ay * horizon / k * uy
        g_y = g_y + 2 * cfg.w_lateral_speed * v_y_end[..., None] * c["mv"][:, -1]
        for g, d in ((g_x, dux), (g_y, duy)):
            g[..., 1:] += 2 * cfg.w_jerk * d
            g[..., :-1] -= 2 * cfg.w_jerk * d
        active = (
            cfg.w_gap * ((short_front > 0).astype(np.float32) + (short_rear > 0))
            + cfg.w_collision * ((hard_front > 0).astype(np.float32) + (hard_rear > 0))
        )
        w_px = 2 * dt_eval * (ov * active + cfg.w_centre)[:, 0]
        w_vx = 2 * dt_eval * (cfg.w_speed + cfg.w_stop * (slow < 0))[:, 0]
        w_py = 2 * dt_eval * (cfg.w_lateral + cfg.w_overshoot * (beyond > 0))[:, 0]
        mp, mv = c["mp"], c["mv"]
        jerk = 2 * cfg.w_jerk * (np.diff(np.eye(k), axis=0).T @ np.diff(np.eye(k), axis=0))
        h_x = np.einsum("kt,bt,jt->bkj", mp, w_px, mp) + np.einsum("kt,bt,jt->bkj", mv, w_vx, mv)
        h_x = h_x + 2 * cfg.w_ax * horizon / k * np.eye(k) + jerk
        h_y = np.einsum("kt,bt,jt->bkj", mp, w_py, mp) + 2 * cfg.w_lateral_speed * np.outer(mv[:, -1], mv[:, -1])
        h_y = h_y + 2 * cfg.w_ay * horizon / k * np.eye(k) + jerk
        return cost, np.concatenate([g_x, g_y], axis=-1), h_x, h_y

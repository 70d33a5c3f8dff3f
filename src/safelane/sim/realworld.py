"""The simulator beyond the paper's world (real_roads.md): a leader ``L0`` in the ego's own lane, sensing error, delay.

* **L0** (:func:`with_own_lane`, :func:`own_lane_checks`; its motion: :mod:`.own_chain`): one vehicle ahead of the
  ego in its original lane, driving a piecewise-constant acceleration profile (by default: cruise, then brake at
  ``SimConfig.l0_decel_mps2`` from a random instant until it stops) — or, with ``SimConfig.own_lane_connected``, the
  first of a connected chain whose non-connected head drives that profile. The ego's collisions with ``L0``
  (footprints overlap: ``|dx| < vehicle_length`` while ``y < w_v``) and ``p_m`` violations (``|dx| < p_m`` at the
  same instants, before the lane change completes) are exact in continuous time and count as the ego's.
* **Sensing error** (:func:`measure`): each period the ego measures every other vehicle's position and speed with an
  error drawn uniformly inside its bound (:class:`~safelane.shield.SensingBounds`, by connectivity), from counters
  (seed, scenario, step, slot): the shield sees only the measurements and the bounds.
* **Actuation delay** (:class:`Actuator`): a command acts ``SimConfig.actuation_delay_s`` after it is issued; the
  ones issued before keep acting meanwhile (at the start: cruise).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..params import Params
from ..safety._backend import ARRAY, jitable
from ..shield.command import Command
from ..shield.situation import SensingBounds, Situation
from .checks import ego_verdict
from .kinematics import Motion, crossing_knots, windowed_gap_extrema
from .rng import counter_uniform

#: Counter slots of the draws made here (kept apart from the other per-step draws).
_SLOT_L0, _SLOT_NOISE = 7001, 7100
#: The measurement draws' slots (:func:`measure`): F's, then the chain's from ``+ 2`` (its first
#: :data:`CHAIN_SLOTS` vehicles; the ones beyond draw with one more counter, 1), the own lane's from ``+ 64``; the
#: counter added for the edge share's second draw.
SLOT_F, SLOT_CHAIN, SLOT_OWN, CHAIN_SLOTS, EDGE_COUNTER = _SLOT_NOISE, _SLOT_NOISE + 2, _SLOT_NOISE + 64, 31, 9


def with_own_lane(batch, seed: int, cfg, prm: Params):
    """``batch`` with an ``L0`` per scenario from the configured distribution (where it has none yet): gap to the
    ego uniform in ``[l0_gap_min_m, l0_gap_max_m]``, speed the ego's ``± l0_speed_spread_mps``, braking at
    ``l0_decel_mps2`` (default: the others' maximum ``a_o_d``, ``a_x_d`` unless set) from an instant uniform in
    ``[0, l0_brake_window_s]``."""
    if batch.l0_x is not None:
        return batch
    sid = _key(batch)
    u = [counter_uniform(seed, sid, _SLOT_L0, k) for k in range(3)]
    gap = cfg.l0_gap_min_m + (cfg.l0_gap_max_m - cfg.l0_gap_min_m) * u[0]
    speed = batch.ego_vx + cfg.l0_speed_spread_mps * u[1]  # not slower than the ego: a start it can evade
    t_brake = cfg.l0_brake_window_s * u[2]
    decel = prm.others_decel if cfg.l0_decel_mps2 is None else cfg.l0_decel_mps2
    times = np.stack([np.zeros_like(t_brake), t_brake], 1)
    accels = np.stack([np.zeros_like(t_brake), np.full_like(t_brake, -decel)], 1)
    out = dataclasses.replace(batch, l0_x=batch.ego_x + gap, l0_v=speed, l0_profile_t=times, l0_profile_a=accels)
    return out if cfg.own_lane_connected == 0 else _with_own_chain(out, seed, cfg, prm)


def _with_own_chain(batch, seed: int, cfg, prm: Params):
    """``batch`` with ``cfg.own_lane_connected`` connected vehicles from ``L0`` on and the non-connected head ahead
    of them: each ``l0_gap_*`` ahead of the one behind it and up to ``l0_speed_spread_mps`` faster, promising
    ``own_promise_decel`` and braking at it from an instant uniform in ``[0, l0_brake_window_s]``."""
    if cfg.own_promise_decel > prm.a_x_d:
        raise ValueError(f"SimConfig.own_promise_decel={cfg.own_promise_decel} must be <= a_x_d={prm.a_x_d} (a "
                         "promise no harder than the ego's own braking: Situation.own_promise)")  # fmt: skip
    sid, n = _key(batch), cfg.own_lane_connected
    x, v, brake = [batch.l0_x], [batch.l0_v], []
    for j in range(1, n + 1):  # counters 3j.. : L0's own draws (0, 1, 2) stay what they were
        u = [counter_uniform(seed, sid, _SLOT_L0, 3 * j + k) for k in range(3)]
        x.append(x[-1] + cfg.l0_gap_min_m + (cfg.l0_gap_max_m - cfg.l0_gap_min_m) * u[0])
        v.append(v[-1] + cfg.l0_speed_spread_mps * u[1])
        brake.append(cfg.l0_brake_window_s * u[2])
    rows = len(batch)
    return dataclasses.replace(
        batch, own_ahead_x=np.column_stack(x[1:]), own_ahead_v=np.column_stack(v[1:]),
        own_promise=np.full((rows, n), cfg.own_promise_decel), own_n_connected=np.full(rows, n, np.int64),
        own_brake_t=np.column_stack(brake),
    )  # fmt: skip


def _key(batch) -> np.ndarray:
    """The counter key of a scenario's draws here: ``batch.world_key`` where set (the falsifier's, so that a replayed
    row draws what it drew in the campaign), else the scenario id."""
    return batch.scenario_id if batch.world_key is None else batch.world_key


def measure(seed: int, batch, step: int, s: Situation, bounds: SensingBounds, edge_share: float = 0.0) -> Situation:
    """The situation as measured: every other vehicle's position and speed off by a uniform draw inside its bound
    (speeds stay ``>= 0``), the bounds attached. ``edge_share``: the share of draws put at either end of the bound
    (the box's corners, where a sound analysis is tightest)."""
    s = bounds.apply(s)
    sid = _key(batch)[:, None]

    def draw(*counters):
        u = counter_uniform(seed, sid, step, *counters)
        if edge_share <= 0.0:
            return u
        return edge_draw(ARRAY, u, counter_uniform(seed, sid, step, *counters, EDGE_COUNTER), edge_share)

    def noisy(x, v, err, slot0, own_slots=None):
        k = np.arange(x.shape[1])[None, :]
        ux = draw(slot0 + 2 * k)
        uv = draw(slot0 + 2 * k + 1)
        if own_slots is not None and x.shape[1] > own_slots:  # columns that would reach the own lane's slots
            far = k[:, own_slots:]  # draw on a counter of their own (one more element): nothing else uses it
            ux[:, own_slots:], uv[:, own_slots:] = draw(slot0 + 2 * far, 1), draw(slot0 + 2 * far + 1, 1)
        return measured(ARRAY, x, v, err[..., 0], err[..., 1], ux, uv)

    fx, fv = noisy(s.f_x[:, None], s.f_v[:, None], s.err_f[:, None, :], SLOT_F)
    # The chain's first 31 vehicles take the slots _SLOT_NOISE + 2 .. + 63, the own lane's from _SLOT_NOISE + 64.
    cx, cv = noisy(s.chain_x, s.chain_v, s.err_chain, SLOT_CHAIN, own_slots=CHAIN_SLOTS)
    out = dict(f_x=fx[:, 0], f_v=fv[:, 0], chain_x=cx, chain_v=cv)
    if s.own_x is not None:
        ox, ov = noisy(s.own_x, s.own_v, s.err_own, SLOT_OWN)
        out.update(own_x=np.where(np.isfinite(s.own_x), ox, np.inf), own_v=np.where(np.isfinite(s.own_x), ov, 0.0))
    return dataclasses.replace(s, **out)


def edge_draw(xp, u, w, edge_share):
    """A measurement draw ``u`` in ``[0, 1)`` put at either end of its bound where the second draw ``w`` falls below
    ``edge_share`` (``np.round(u)``: 0 up to 0.5 included, half to even, else 1). Backend-generic (the compiled
    closed loop's rows too: ``sim/_fast_world.py``)."""
    return xp.where(w < edge_share, xp.where(u > 0.5, 1.0, 0.0), u)


def measured(xp, x, v, err_x, err_v, ux, uv):
    """A vehicle's measured ``(x, v)`` from its true state, its error bounds and its two draws in ``[0, 1)``: off by
    ``err (2u − 1)``, the speed kept ``>= 0``. Backend-generic."""
    return x + err_x * (2.0 * ux - 1.0), xp.maximum(v + err_v * (2.0 * uv - 1.0), 0.0)


def executed_motion(cmd: Command, ego, dt: float):
    """``(lon, lat, plan)`` of the ego executing ``cmd`` from its actual state (exact; the aborting rows' segments
    integrated from where the ego is)."""
    ex, ey, evx, evy = ego
    lon = Motion.constant(ex, evx, cmd.a_x, dt)
    lat = Motion.free(ey, evy, cmd.a_y, dt)
    plan = None
    if cmd.rows.size:
        px, py, vx, vy = cmd.plan_samples(ex, ey, evx, evy)
        plan = (cmd.rows, Motion.from_samples(cmd.knots, px, vx), Motion.from_samples(cmd.knots, py, vy))
    return lon, lat, plan


def own_lane_checks(prm: Params, lon: Motion, lat: Motion, plan, l0: Motion, present, completed):
    """``(collided, violated, min_gap)`` of the ego against ``L0`` over the period: exact extrema of ``x_0 − x`` over
    the instants when the ego can overlap ``L0`` laterally (``y < w_v``; ``p_m`` counts there until the lane change
    completes)."""
    level = prm.vehicle_width
    n = len(present)
    lo, hi = np.full(n, np.inf), np.full(n, -np.inf)
    on_plan = np.zeros(n, bool)
    groups = []
    if plan is not None and plan[0].size:
        on_plan[plan[0]] = True
        keep = np.flatnonzero(present[plan[0]])
        groups.append((plan[0][keep], _take(plan[1], keep), _take(plan[2], keep)))
    rest = np.flatnonzero(present & ~on_plan)
    groups.append((rest, _take(lon, rest), _take(lat, rest)))
    for rows, m_lon, m_lat in groups:
        if rows.size == 0:
            continue
        neg = Motion(t=m_lat.t, x=-m_lat.x, v=-m_lat.v, acc=-m_lat.acc)  # y < level  <=>  -y > -level
        knots = crossing_knots(neg, -level)
        g_lo, g_hi = windowed_gap_extrema(m_lon, _take(l0, rows), neg, knots, -level)
        lo[rows], hi[rows] = g_lo, g_hi
    # as the target lane's verdict, the one window (y < w_v) for both: footprints overlap, p_m broken
    hit, close = ego_verdict(ARRAY, lo, hi, lo, hi, prm.vehicle_length, prm.p_m)
    return present & hit, present & ~completed & close, lo


def _take(m: Motion, rows) -> Motion:
    return Motion(t=m.t[rows], x=m.x[rows], v=m.v[rows], acc=m.acc[rows])


# The measurement's closed forms, compiled into the closed loop's rows (sim/_fast_world.py).
jitable(edge_draw, measured)

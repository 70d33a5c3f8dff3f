"""The multi-lane falsifier's world: other vehicles change lanes around the ego, inside the world model's assumptions.

The paper's simulator has two lanes and nobody but the ego changes lanes. This world has four lanes in the shield's
frame (lane ``i``'s centre at ``y = i·w_l``: −1 the lane on the ego's other side, 0 the ego's lane, 1 the target
lane, 2 the lane beyond it) and five other vehicles besides the ego, each a row's slot:

* ``F`` (target lane, behind): an aggressive follower (it closes on ``L1`` and ignores the ego until the lane change
  completes), a responsible follower of every vehicle ahead of it in a lane its body overlaps; it may *leave* for
  lane 2 at a drawn time;
* ``L1`` (target lane, ahead, not connected: ``N = 0``): brakes at a drawn rate up to the others' maximum ``a_o_d``
  from a drawn time;
* ``L0`` (own lane, ahead; in a drawn share of the rows): brakes like ``L1``; it may *leave* for lane −1;
* ``far`` (lane 2) enters the target lane, and ``side`` (lane −1) enters the ego's lane, each from a drawn time on,
  ahead of, beside or behind the ego by where it starts. Connected in a drawn share of the rows: then it announces the
  lane change over V2X (the lane and its earliest start, the drawn time) and does not move before it.

**Inside the assumptions** (docs/safety.md, "Other vehicles' lane changes"): every lateral acceleration is at most
``a_y_m`` (RSS's lateral bound with ρ = one period; a vehicle that may not enter brakes laterally at ``a_y_m``,
RSS's proper lateral response); every braking is at most ``a_o_d``; and an entrant enters a lane only at a safe
longitudinal distance to each vehicle that is in that lane — its body there, or its RSS lateral worst case reaching it
(the world model's reach, so a vehicle moving into the lane counts), the ego included: RSS's safe distance
(:func:`~safelane.baselines.rss.longitudinal_safe_distance_exact` — the rear vehicle accelerates at ``a_x_a`` for
one period, then brakes at ``a_x_d``; the front one brakes at ``a_o_d``) plus ``p_m`` between centres, so that a
rear vehicle that responds properly keeps ``p_m``. An entrant decides every period from the states at the period's
start (with a drawn extra margin, 0 at the knife edge); whether it kept the rule is judged at the first period start
at which its body overlaps the new lane. A row whose start is not inside the assumptions (no safe evasion plan
for the shield's initial check, or ``F`` unable to stay behind ``L1``) is counted and not judged; a row whose
entrant entered without the distance counts as *outside*, its outcomes reported apart, as rates.

The shield sees what a host gives it: F, the chain ``[L1]``, ``L0`` while their bodies overlap their lanes, and every
other vehicle as :class:`~safelane.shield.world.Others` (a vehicle that left its role joins them). Every function is
vectorised over the rows. The campaign: :mod:`.falsify_lanes` (the referee) and :mod:`.falsify_lanes_run`.
"""

from __future__ import annotations

import numpy as np

from ..baselines.rss import RssParams, longitudinal_safe_distance_exact, stated_braking_lateral
from ..params import Params
from ..safety._backend import ARRAY
from ..shield.situation import Situation
from ..shield.world import NO_LANE, Others
from ..sim.behaviours import follow_core

#: The other vehicles' slots and their home lanes.
SLOTS = ("F", "L1", "L0", "far", "side")
F, L1, L0, FAR, SIDE = range(5)
HOME = np.array([1, 1, 0, 2, -1])
#: The lane each slot may move to (F and L0 leave; the entrants enter; L1 stays).
GOAL = np.array([2, 1, -1, 1, 0])
ENTRANTS = (FAR, SIDE)
#: Where F is placed for the shield once it has left the target lane (far behind: never binding) [m].
NO_F_M = 1.0e3


def _u(rng, n, lo, hi):
    return rng.uniform(lo, hi, n)


def _edge(rng, n, lo, hi, at, p_at=0.3):
    """Uniform on ``[lo, hi]``, exactly ``at`` with probability ``p_at`` (the knife edge)."""
    return np.where(rng.random(n) < p_at, at, rng.uniform(lo, hi, n))


def draw(rng: np.random.Generator, n: int, prm: Params) -> dict[str, np.ndarray]:
    """``n`` rows of the search space (every range in the module docstring's families)."""
    a_o, w = prm.others_decel, prm.lane_width
    v = _u(rng, n, 15.0, 35.0)
    spec = {
        "ego_v": v,
        "ego_y": np.where(rng.random(n) < 0.7, 0.0, _u(rng, n, 0.0, 0.5 * w)),
        "ax_hi": _u(rng, n, -prm.a_x_d, prm.a_x_a), "ax_lo": _u(rng, n, -prm.a_x_d, prm.a_x_a),
        "ax_period": _u(rng, n, 0.2, 4.0), "lat_gain": _u(rng, n, 0.3, 3.0), "start_s": _edge(rng, n, 0.0, 3.0, 0.0),
        "f_slack": _edge(rng, n, 0.0, 30.0, 0.0, 0.1), "f_dv": _u(rng, n, -5.0, 5.0),
        "l1_slack": _edge(rng, n, 0.0, 40.0, 0.0, 0.1), "l1_dv": _u(rng, n, -8.0, 5.0),
        "l0_present": rng.random(n) < 0.5, "l0_slack": _u(rng, n, 0.0, 50.0), "l0_dv": _u(rng, n, -8.0, 5.0),
    }  # fmt: skip
    for who in ("l1", "l0"):
        spec[f"{who}_brake_t"] = _edge(rng, n, 0.0, 10.0, 0.0, 0.2)
        spec[f"{who}_decel"] = _edge(rng, n, 0.0, a_o, a_o)
    for who in ("f", "l0"):
        spec[f"{who}_leave"] = rng.random(n) < 0.3
        spec[f"{who}_leave_t"] = _u(rng, n, 0.0, 10.0)
    for who, lo in (("far", -60.0), ("side", -20.0)):
        spec[f"{who}_present"] = rng.random(n) < 0.85
        spec[f"{who}_x"] = _u(rng, n, lo, 80.0)
        spec[f"{who}_dv"] = _u(rng, n, -8.0, 8.0)
        spec[f"{who}_want_t"] = _edge(rng, n, 0.0, 8.0, 0.0, 0.2)
        spec[f"{who}_margin"] = _edge(rng, n, 0.0, 10.0, 0.0, 0.4)  # extra distance the entrant waits for [m]
        spec[f"{who}_connected"] = rng.random(n) < 0.3
        spec[f"{who}_brake_delay"] = _edge(rng, n, 0.0, 3.0, 0.0)
        spec[f"{who}_decel"] = _edge(rng, n, 0.0, a_o, a_o)
    return spec


def lanes_overlapped(y, prm: Params, lane, tol: float = 0.0) -> np.ndarray:
    """Whether a body centred at ``y`` overlaps lane ``lane`` by more than ``tol`` (arrays broadcast)."""
    half, w = 0.5 * prm.vehicle_width, prm.lane_width
    return (y + half > (lane - 0.5) * w + tol) & (y - half < (lane + 0.5) * w - tol)


def share_lane(y_a, y_b, prm: Params, tol: float = 0.0) -> np.ndarray:
    """Whether two bodies overlap a common lane (lanes −1..2)."""
    return np.any([lanes_overlapped(y_a, prm, i, tol) & lanes_overlapped(y_b, prm, i, tol) for i in (-1, 0, 1, 2)],
                  axis=0)  # fmt: skip


def safe_gap(v_rear, v_front, prm: Params):
    """The centre distance an entrant must leave (module docstring): RSS's safe distance plus ``p_m``."""
    # bumper gap >= d + (p_m − L), as a distance between centres
    return longitudinal_safe_distance_exact(v_front, v_rear, prm.dt, prm.a_x_a, prm.a_x_d, prm.others_decel) + prm.p_m


def _counts_in(y, vy, prm: Params, lane) -> np.ndarray:
    """Whether a vehicle counts in ``lane`` for an entrant's rule: its body overlaps it, or its RSS lateral worst case
    reaches it (the reach the world model gives a non-connected vehicle, ``RssParams.matched``:
    :func:`safelane.shield.world.lane_reach`'s rule 2) — the ego counts in a lane it is moving into."""
    rss = RssParams.matched(prm)
    rho, a, b, mu = rss.response_time_other, rss.lat_accel_max, rss.lat_brake_min, 0.5 * rss.lateral_fluctuation_margin
    half, w = 0.5 * prm.vehicle_width, prm.lane_width
    up = np.maximum(stated_braking_lateral(vy, rho, a, b), 0.0)
    down = np.maximum(stated_braking_lateral(-vy, rho, a, b), 0.0)
    return (y + half + up + mu > (lane - 0.5) * w) & (y - half - down - mu < (lane + 0.5) * w)


def may_enter(i: int, x, v, y, vy, ego, prm: Params, margin):
    """``(B,)`` whether entrant ``i`` may enter its goal lane now: the safe distance (plus ``margin``) to every
    vehicle that counts in that lane (:func:`_counts_in`), the ego included. ``ego``: ``(x, y, vx, vy)``."""
    lane = GOAL[i]
    ex, ey, evx, evy = ego
    ok = np.ones(len(ex), bool)
    movers = [(x[:, k], v[:, k], y[:, k], vy[:, k]) for k in range(x.shape[1]) if k != i] + [(ex, evx, ey, evy)]
    for xk, vk, yk, vyk in movers:
        there = _counts_in(yk, vyk, prm, lane)
        ahead = xk >= x[:, i]
        need = np.where(ahead, safe_gap(v[:, i], vk, prm), safe_gap(vk, v[:, i], prm)) + margin
        with np.errstate(invalid="ignore"):  # absent vehicles (x = +inf) are in no lane
            ok &= ~there | (np.abs(xk - x[:, i]) >= need)
    return ok


def _lateral(y, vy, goal_y, go, prm: Params):
    """Lateral acceleration: toward ``goal_y`` (bang-bang at ``a_y_m``, stopping at the lane's centre) where ``go``,
    else braking the lateral speed to zero at up to ``a_y_m`` (RSS's proper lateral response)."""
    a, dt = prm.a_y_m, prm.dt
    d = goal_y - y
    v_want = np.sign(d) * np.sqrt(2.0 * a * np.abs(d))
    toward = np.clip((v_want - vy) / dt, -a, a)
    stop = np.clip(-vy / dt, -a, a)
    return np.where(go, toward, stop)


def initial_state(spec: dict, prm: Params):
    """``(ego (x, y, vx, vy), x, v, y)`` at ``t = 0``: others ``(B, 5)`` in :data:`SLOTS` order (absent: ``x = +inf``
    for ``L0`` and the entrants)."""
    n = len(spec["ego_v"])
    ev = spec["ego_v"]
    x = np.zeros((n, 5))
    v = np.zeros((n, 5))
    x[:, F] = -(prm.p_m + spec["f_slack"])
    v[:, F] = np.maximum(ev + spec["f_dv"], 0.0)
    x[:, L1] = prm.p_m + spec["l1_slack"]
    v[:, L1] = np.maximum(ev + spec["l1_dv"], 0.0)
    x[:, L0] = np.where(spec["l0_present"], prm.p_m + spec["l0_slack"], np.inf)
    v[:, L0] = np.maximum(ev + spec["l0_dv"], 0.0)
    for i, who in ((FAR, "far"), (SIDE, "side")):
        x[:, i] = np.where(spec[f"{who}_present"], spec[f"{who}_x"], np.inf)
        v[:, i] = np.maximum(ev + spec[f"{who}_dv"], 0.0)
    y = np.broadcast_to(HOME * prm.lane_width, (n, 5)).astype(float).copy()
    ego = (np.zeros(n), spec["ego_y"].astype(float), ev.astype(float), np.zeros(n))
    return ego, x, v, y


def starts_inside(spec: dict, prm: Params) -> np.ndarray:
    """Rows whose start is inside the assumptions as far as the traffic goes: F can keep ``p_m`` behind L1 braking
    at ``a_o_d``, and the entrants' bodies start out of the ego's two lanes. (The ego's side: :func:`simulate` also
    asks the shield's own initial check, whose plan must be a safe evasion, L0 included.)"""
    from ..safety import leader_chain

    _, x, v, _ = initial_state(spec, prm)
    pair = leader_chain(x[:, [F, L1]], v[:, [F, L1]], np.full((len(x), 1), prm.others_decel), prm)
    ok = ~np.asarray(pair.unsafe, bool)
    for i in ENTRANTS:
        home = HOME[i] * prm.lane_width
        ok &= ~(np.isfinite(x[:, i]) & (lanes_overlapped(home, prm, 0) | lanes_overlapped(home, prm, 1)))
    return ok


def situation(t, ego, x, v, y, vy, spec: dict, prm: Params) -> Situation:
    """What the shield is given (module docstring)."""
    ex, ey, evx, evy = ego
    n = len(ex)
    f_here = lanes_overlapped(y[:, F], prm, 1)
    l0_here = np.isfinite(x[:, L0]) & lanes_overlapped(y[:, L0], prm, 0)
    f_x = np.where(f_here, x[:, F], ex - NO_F_M)
    f_v = np.where(f_here, v[:, F], 0.0)
    slots = [FAR, SIDE, F, L0]
    ox = np.stack([x[:, FAR], x[:, SIDE], np.where(f_here, np.inf, x[:, F]), np.where(l0_here, np.inf, x[:, L0])], 1)
    oy = y[:, slots]
    ovx = np.where(np.isfinite(ox), v[:, slots], 0.0)
    ovy = np.where(np.isfinite(ox), vy[:, slots], 0.0)
    oy = np.where(np.isfinite(ox), oy, 0.0)
    conn = np.zeros((n, 4), bool)
    lane = np.full((n, 4), NO_LANE, np.int64)
    at = np.full((n, 4), np.inf)
    for j, (i, who) in enumerate(((FAR, "far"), (SIDE, "side"))):
        c = spec[f"{who}_connected"] & np.isfinite(x[:, i])
        conn[:, j] = c
        lane[:, j] = np.where(c, GOAL[i], NO_LANE)
        at[:, j] = np.where(c, spec[f"{who}_want_t"], np.inf)
    return Situation(
        t=float(t), ego_x=ex, ego_y=ey, ego_vx=evx, ego_vy=evy, f_x=f_x, f_v=f_v,
        f_connected=np.zeros(n, bool), f_collaborative=np.zeros(n, bool),
        chain_x=x[:, [L1]], chain_v=v[:, [L1]], chain_promise=np.zeros((n, 0)), chain_human=np.zeros((n, 0), bool),
        n_connected=np.zeros(n, np.int64), f_aggressive_truth=np.ones(n, bool),
        own_x=np.where(l0_here, x[:, L0], np.inf)[:, None], own_v=np.where(l0_here, v[:, L0], 0.0)[:, None],
        own_promise=np.zeros((n, 0)), own_n_connected=np.zeros(n, np.int64),
        others=Others(ox, oy, ovx, ovy, conn, lane, at),
    )  # fmt: skip


def nominal(t, ego, spec: dict, prm: Params):
    """The adversarial nominal planner: ``a_x`` a square wave between two drawn levels; ``a_y`` saturated toward the
    target lane's centre from a drawn start (before it, lateral braking)."""
    _, ey, _, evy = ego
    up = np.floor(t / spec["ax_period"]) % 2 == 0
    ax = np.where(up, spec["ax_hi"], spec["ax_lo"])
    k = spec["lat_gain"]
    go = np.clip(k * (prm.lane_width - ey) - 2.0 * np.sqrt(k) * evy, -prm.a_y_m, prm.a_y_m)
    hold = np.clip(-evy / prm.dt, -prm.a_y_m, prm.a_y_m)
    return ax, np.where(t >= spec["start_s"], go, hold)


def others_accels(t, ego, x, v, y, vy, entered, entry_t, entry_ahead, completed, spec: dict, prm: Params):
    """``(a_x, a_y)`` of the five others for this period (module docstring's behaviours)."""
    ex, ey, evx, _ = ego
    n = len(ex)
    a_o, dt = prm.others_decel, prm.dt
    ax = np.zeros((n, 5))
    for i, who in ((L1, "l1"), (L0, "l0")):
        ax[:, i] = np.where(t >= spec[f"{who}_brake_t"], -spec[f"{who}_decel"], 0.0)
    ax[:, F] = np.clip(0.5 * (x[:, L1] - x[:, F] - prm.p_m - 1.0) + 1.5 * (v[:, L1] - v[:, F]), -a_o, prm.a_x_a)
    for i, who in ((FAR, "far"), (SIDE, "side")):
        brake = entered[:, i] & entry_ahead[:, i] & (t >= entry_t[:, i] + spec[f"{who}_brake_delay"])
        ax[:, i] = np.where(brake, -spec[f"{who}_decel"], 0.0)
    # Every other vehicle follows responsibly every vehicle ahead of it in a lane both bodies overlap (RSS's rear
    # vehicle), the ego included -- except F, which ignores the ego until the lane change completes.
    with np.errstate(all="ignore"):
        for j in range(5):
            a = ax[:, j]
            for k in range(5):
                if k != j:
                    ahead = np.isfinite(x[:, k]) & (x[:, k] > x[:, j]) & share_lane(y[:, j], y[:, k], prm)
                    slack = x[:, k] - x[:, j] - prm.p_m
                    a = np.where(ahead, follow_core(ARRAY, a, slack, v[:, j], v[:, k], a_o, dt), a)
            ego_ahead = (ex > x[:, j]) & share_lane(y[:, j], ey, prm) & (completed if j == F else True)
            a = np.where(ego_ahead, follow_core(ARRAY, a, ex - x[:, j] - prm.p_m, v[:, j], evx, a_o, dt), a)
            ax[:, j] = np.where(np.isfinite(x[:, j]), a, 0.0)
    # Lateral: the leavers from their drawn times; the entrants from theirs while entering is safe, then to the end.
    go = np.zeros((n, 5), bool)
    go[:, F] = spec["f_leave"] & (t >= spec["f_leave_t"])
    go[:, L0] = spec["l0_leave"] & (t >= spec["l0_leave_t"])
    for i, who in ((FAR, "far"), (SIDE, "side")):
        safe = may_enter(i, x, v, y, vy, ego, prm, spec[f"{who}_margin"])
        go[:, i] = entered[:, i] | ((t >= spec[f"{who}_want_t"]) & safe)
    ay = np.where(np.isfinite(x), _lateral(y, vy, GOAL * prm.lane_width, go, prm), 0.0)
    ay[:, L1] = 0.0
    return ax, ay

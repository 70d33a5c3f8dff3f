"""The closed loop for one scenario at a time, in Python floats on the scalar safety API. Test helper, not tests.

A straightforward re-implementation of :mod:`safelane.sim.engine`'s step — assessment, worst case by variant,
expert planner, supervisor (proceed / hesitate / abort with the completion guard and the within-period check),
leader and follower behaviours, exact integration, per-period checks — in Python floats, one scenario at a time.
Its checks are exact pair minima over each period, lateral-windowed only during an abort (where they are sampled
at 11 instants), so near-misses may be counted differently from the engine.

The loop (:func:`scenario_loop`) is a generator: the safety maths it needs — L1's worst case from the chain, an
evasion plan (verdict and motion), a follower's least deceleration (Eq. 3), a responsible acceleration — it asks
for by yielding a request ``(kind, args)`` and is sent the answer. Two oracles answer:

* :func:`loop_scenario` — the library's scalar API (``worst_case_leader_decel``, ``plan_evasion``) and the closed
  forms below, one call per request, as one would write without batching: the baseline of
  ``benchmarks/bench_sim.py``, and in ``tests/test_sim_scalar_loop.py`` a check of the engine's batching;
* ``scalar_loop_reference.reference_loop`` — the independent numeric reference (``tests/reference.py``:
  time stepping and bisection, no closed form of the library), with many scenarios run in lockstep so that each
  round of requests is one batched reference call: a check of the maths as well.
"""

from __future__ import annotations

import math

import numpy as np

from safelane import Params
from safelane.planners.variants import VARIANT_NAMES, VARIANTS
from safelane.safety import plan_evasion, worst_case_leader_decel

SAMPLES = np.linspace(0.0, Params().dt, 11)
LATERAL_TOL_M = 1e-9


def _advance(x, v, a, dt):
    """Exact constant-acceleration step with stopping (Python floats)."""
    if a < 0.0 and v + a * dt < 0.0:
        s = v / -a
        return x + v * s + 0.5 * a * s * s, 0.0
    return x + v * dt + 0.5 * a * dt * dt, v + a * dt


def _pair_min_gap(slack, v_f, a_f, v_l, a_l, dt):
    """Minimum over the period of ``x_l − x_f`` starting from ``slack`` (both stop rather than reverse)."""
    best = slack
    times = [dt]
    for v, a in ((v_f, a_f), (v_l, a_l)):
        if a < 0.0 and v / -a < dt:
            times.append(v / -a)
    if a_f != a_l:
        tau = (v_l - v_f) / (a_f - a_l)
        if 0.0 < tau < dt:
            times.append(tau)
    for t in times:
        xf, _ = _advance(0.0, v_f, a_f, t)
        xl, _ = _advance(slack, v_l, a_l, t)
        best = min(best, xl - xf)
    return best


def _min_follow_decel(slack, v_f, v_l, a_l):
    if slack < -1e-9:  # inside the margin beyond the 1 nm tolerance
        return math.inf
    slack = slack if slack > 5e-10 else max(slack + 5e-10, 0.0)  # keep the gap above margin - 0.5 nm
    lead = v_l * v_l / a_l if a_l > 0.0 else (math.inf if v_l > 0.0 else 0.0)
    dv = v_f - v_l
    if dv > 0.0:
        if slack == 0.0:
            return math.inf
        if 2.0 * slack * a_l <= v_l * dv:
            return a_l + dv * dv / (2.0 * slack)
    return v_f * v_f / (2.0 * slack + lead) if v_f > 0.0 else 0.0


def _final_stop_accel(slack, v_f, v_l, lead_decel, prm, dt, brake=None):
    brake = prm.a_x_d if brake is None else brake
    if lead_decel <= 0.0 and v_l > 0.0:
        return math.inf
    y = slack + (v_l * v_l / (2.0 * lead_decel) if lead_decel > 0.0 else 0.0)
    if y <= 0.0:
        return 0.0 if y == 0.0 and v_f == 0.0 else -math.inf
    w = -0.5 * brake * dt + math.sqrt(max(0.25 * brake * brake * dt * dt + brake * (2.0 * y - v_f * dt), 0.0))
    return (w - v_f) / dt if w >= 0.0 else -v_f * v_f / (2.0 * y)


def _responsible_bound(slack, v_f, v_l, d, prm, dt, brake=None):
    brake = prm.a_x_d if brake is None else brake
    if slack < 0.0:
        return -math.inf
    bound = _final_stop_accel(slack, v_f, v_l, d, prm, dt, brake)
    xl_end, u1 = _advance(slack, v_l, -d, dt)
    g = xl_end - v_f * dt
    if xl_end > 0.0:
        end = 2.0 * g / (dt * dt)
        bound = min(bound, end if v_f + end * dt >= 0.0 else -v_f * v_f / (2.0 * xl_end))
    else:
        bound = min(bound, -math.inf if xl_end < 0.0 else 0.0)
    dv = v_f - v_l
    if dv > 0.0:
        tau = 2.0 * slack / dv
        if tau < dt and v_l - d * tau > 0.0:
            bound = min(bound, -d - dv * dv / (2.0 * slack) if slack > 0.0 else -math.inf)
    c = brake - d
    r0 = v_f - u1
    disc = c * c * dt * dt + 4.0 * c * (2.0 * g + dt * r0)
    if c > 0.0 and disc >= 0.0 and u1 > 0.0:
        q = 0.5 * (-c * dt + math.sqrt(disc))
        if q > 0.0 and q * d <= c * u1:
            bound = min(bound, (q - r0) / dt)
    return bound


def _responsible_accel(a_wanted, slack, v_f, v_l, lead_decel, prm, dt):
    bound = _responsible_bound(slack, v_f, v_l, lead_decel, prm, dt)
    return a_wanted if bound > a_wanted else max(bound - 1e-9, -prm.a_x_d)


def _leader_accel(task, slack, v_f, v_l, d, own, prm, dt):
    """A connected leader's acceleration: its task while responsible (braking at ``own`` against the vehicle
    ahead at ``d``), else the largest responsible one, else ``-own``."""
    want = min(task, _responsible_bound(slack, v_f, v_l, d, prm, dt, own) - 1e-9)
    xf, vf = _advance(0.0, v_f, want, dt)
    xl, vl = _advance(slack, v_l, -d, dt)
    ok = _pair_min_gap(slack, v_f, want, v_l, -d, dt) >= -1e-9
    ok = ok and _min_follow_decel(xl - xf, vf, vl, d) <= own
    return max(want if ok else -own, -own)


def library_answer(prm: Params, kind: str, args):
    """One request of :func:`scenario_loop` answered by the library's scalar API and the closed forms above."""
    if kind == "chain":  # L1's worst case from the connected chain (Eqs. 1-3), and every link's bound
        x, v, promise, human = args
        bounds = [prm.a_x_d]
        for j in range(len(promise) - 1, -1, -1):  # the chain scan, written out: Eq. 3 link by link
            margin = prm.p_m_human if human[j] else prm.p_m
            z = _min_follow_decel(x[j + 1] - x[j] - margin, v[j], v[j + 1], bounds[0])
            bounds.insert(0, min(max(promise[j], z), prm.a_x_d))
        return float(worst_case_leader_decel(x, v, promise, prm, human_driven=human)), bounds
    if kind == "plan":  # an evasion plan (Eqs. 4-9): .feasible and .state(t)
        return plan_evasion(*args, prm)
    if kind == "follow":  # least deceleration keeping the margin (slack) to a leader braking at a_l (Eq. 3)
        return _min_follow_decel(*args)
    if kind == "responsible":  # the largest responsible acceleration up to `wanted` (braking at a_x_d after)
        return _responsible_accel(*args, prm, prm.dt)
    if kind == "leaders":  # each connected leader's acceleration (braking at its own bound after)
        return [_leader_accel(*leader, prm, prm.dt) for leader in args]
    raise ValueError(f"unknown request {kind!r}")


def loop_scenario(b, i: int, prm: Params, steps: int, **behaviour) -> dict:
    """One scenario of the batch ``b`` through the closed loop on the library's scalar API."""
    loop = scenario_loop(b, i, prm, steps, **behaviour)
    answer = None
    while True:
        try:
            kind, args = loop.send(answer)
        except StopIteration as done:
            return done.value
        answer = library_answer(prm, kind, args)


def scenario_loop(b, i: int, prm: Params, steps: int, open_decel=0.5, open_gap=3.0, window=5, thr=0.2):
    """One scenario of the batch ``b`` through the closed loop, one Python float at a time; a generator yielding
    the requests listed in the module docstring and returning the outcome row."""
    dt = prm.dt
    variant = VARIANTS[VARIANT_NAMES[int(b.variant[i])]]
    n = int(b.n_connected[i])
    k = n + 2
    x, v = [float(a) for a in b.x[i, :k]], [float(a) for a in b.v[i, :k]]
    v_desired = list(v)
    human = [bool(h) for h in b.human[i, :k]]
    promise_d = [float(a) for a in b.promise_decel[i, :k]]
    promise_a = [float(a) for a in b.promise_accel[i, :k]]
    f_conn, f_aggr_true, decel_last = bool(b.connected[i, 0]), bool(b.follower_aggressive[i]), float(b.decel_last[i])
    ex, ey, evx, evy = float(b.ego_x[i]), float(b.ego_y[i]), float(b.ego_vx[i]), float(b.ego_vy[i])
    gap0 = ex - x[0]
    plan = yield "plan", (ex, ey, evx, evy, x[1], v[1], prm.a_x_d, x[0], v[0], True)
    plan_t0, t, completed, t_complete = 0.0, 0.0, False, math.nan
    history, aggressive, latched = [], True, False
    collided = violated = leader_collided = False
    counts = [0, 0, 0]
    cap = [math.inf] * k
    times = [(j - (window - 1) / 2.0) * dt for j in range(window)]
    norm = sum(s * s for s in times)
    for _ in range(steps):
        # Assess F from its observed speed.
        history = [*history[-(window - 1) :], v[0]]
        if len(history) == window:
            slope = sum(h * s for h, s in zip(history, times, strict=True)) / norm
            latched = latched or slope >= thr
            aggressive = latched or (aggressive and slope > -thr)
        # The chain (Eqs. 1-3): L1's worst case, and every link's bound for the leaders' behaviour below.
        if n >= 1:
            chain_l1, link_bounds = yield "chain", (x[1:], v[1:], promise_d[1 : n + 1], human[1 : n + 1])
        else:
            chain_l1, link_bounds = prm.a_x_d, [prm.a_x_d]
        # Worst case by variant.
        l1_decel = chain_l1 if variant.uses_chain else prm.a_x_d
        f_aggr = False if (variant.uses_follower_v2x and f_conn) else (aggressive if variant.uses_assessment else True)
        # Expert planner.
        a_x = 0.3 * (0.5 * (x[1] + x[0]) - ex) + 0.8 * (v[1] - evx)
        a_x = min(max(a_x, -prm.a_x_d), prm.a_x_a)
        a_y = min(max(0.65**2 * (prm.lane_width - ey) - 1.3 * evy, -prm.a_y_m), prm.a_y_m)
        # Supervisor.
        behaviour, completing = 2, False
        if completed:
            a_x = yield "responsible", (a_x, x[1] - ex - prm.p_m, evx, v[1], l1_decel)
            a_y = min(max(0.8 * (prm.lane_width - ey) - 1.6 * evy, -prm.a_y_m), prm.a_y_m)
            behaviour = -1
        else:
            a_f = prm.a_x_a if f_aggr else -prm.a_x_d
            for code, lat in ((0, a_y), (1, min(max(-evy / dt, -prm.a_y_m), prm.a_y_m))):
                nx, nvx = _advance(ex, evx, a_x, dt)
                ny, nvy = ey + evy * dt + 0.5 * lat * dt * dt, evy + lat * dt
                lx, lv = _advance(x[1], v[1], -l1_decel, dt)
                fx, fv = _advance(x[0], v[0], a_f, dt)
                y_max = max(ey, ny, ey - evy * evy / (2.0 * lat) if lat < 0.0 < evy < -lat * dt else ey)
                ok = y_max <= prm.y_safe + LATERAL_TOL_M or (
                    _pair_min_gap(x[1] - ex - prm.p_m, evx, a_x, v[1], -l1_decel, dt) >= -1e-9
                    and _pair_min_gap(ex - x[0] - prm.p_m, v[0], a_f, evx, a_x, dt) >= -1e-9
                )
                candidate = yield "plan", (nx, ny, nvx, nvy, lx, lv, l1_decel, fx, fv, f_aggr)
                if ny >= prm.y_boundary:
                    ok = ok and (yield "follow", (lx - nx - prm.p_m, nvx, lv, l1_decel)) <= prm.a_x_d
                    ok = ok and (yield "follow", (nx - fx - prm.p_m, fv, nvx, prm.a_x_d)) <= prm.a_x_d
                else:
                    ok = ok and bool(candidate.feasible)
                if ok:
                    behaviour, completing, plan, plan_t0, a_y = code, ny >= prm.y_boundary, candidate, t + dt, lat
                    break
            counts[behaviour] += 1
        # Others act: each connected leader keeps its task while it could still keep its margin braking at its own
        # bound (never above the smallest it has had) against the vehicle ahead at that one's bound.
        bounds = [prm.a_x_d, *link_bounds]  # F's slot (unused), L1..LN, L(N+1) at a_x_d
        acc = [0.0] * k
        leaders = []
        for j in range(1, n + 1):
            cap[j] = min(cap[j], bounds[j])
            margin = prm.p_m_human if human[j] else prm.p_m
            task = min(max(0.5 * (v_desired[j] - v[j]), -promise_d[j]), promise_a[j])
            leaders.append((task, x[j + 1] - x[j] - margin, v[j], v[j + 1], bounds[j + 1], cap[j]))
        if leaders:
            acc[1 : n + 1] = yield "leaders", leaders
        acc[n + 1] = -decel_last if t + 1e-9 >= 0.0 else 0.0
        if f_aggr_true:
            wanted = min(max(0.5 * (x[1] - x[0] - prm.p_m - 1.0) + 1.5 * (v[1] - v[0]), -prm.a_x_d), prm.a_x_a)
        elif ex - x[0] < gap0 + open_gap:
            wanted = -open_decel
        else:
            wanted = min(max(evx - v[0], -open_decel), open_decel)
        a_f = yield "responsible", (wanted, x[1] - x[0] - prm.p_m, v[0], v[1], prm.a_x_d)
        if ex - x[0] > 0.0 and (not f_aggr_true or completed):
            a_f = yield "responsible", (a_f, ex - x[0] - prm.p_m, v[0], evx, prm.a_x_d)
        acc[0] = a_f
        # Exact integration (an abort follows the verified plan) and continuous-time checks; the abort's
        # motion switches acceleration inside the period, so its gaps are checked at 11 instants instead.
        if behaviour == 2:
            px, py, pvx, pvy = plan.state(t - plan_t0 + SAMPLES)
            nx, ny, nvx, nvy = float(px[-1]), float(py[-1]), float(pvx[-1]), float(pvy[-1])
            lateral_max = float(py.max())
        else:
            nx, nvx = _advance(ex, evx, a_x, dt)
            ny, nvy = ey + evy * dt + 0.5 * a_y * dt * dt, evy + a_y * dt
            lateral_max = max(ey, ny)
        if lateral_max > prm.y_safe + LATERAL_TOL_M:
            for j in range(k):
                if behaviour == 2:  # only the instants at which the ego is still out of its own lane count
                    others = [_advance(x[j], v[j], acc[j], float(s))[0] for s in SAMPLES]
                    out = py > prm.y_safe + LATERAL_TOL_M
                    g = min(abs(o - e) for o, e, w in zip(others, px.tolist(), out, strict=True) if w)
                elif j == 0:
                    g = _pair_min_gap(ex - x[0], v[0], acc[0], evx, a_x, dt)
                else:
                    g = _pair_min_gap(x[j] - ex, evx, a_x, v[j], acc[j], dt)
                violated = violated or g < prm.p_m - 1e-9
                collided = collided or (g < prm.vehicle_length and lateral_max > prm.lane_width - prm.vehicle_width)
        for j in range(k - 1):
            g = _pair_min_gap(x[j + 1] - x[j], v[j], acc[j], v[j + 1], acc[j + 1], dt)
            leader_collided = leader_collided or g < prm.vehicle_length
        for j in range(k):
            x[j], v[j] = _advance(x[j], v[j], acc[j], dt)
        ex, ey, evx, evy = nx, ny, nvx, nvy
        t += dt
        if completing and not completed:
            completed, t_complete = True, t
    return {
        "success": completed and not collided,
        "collision": collided,
        "safety_violation": violated,
        "leader_collision": leader_collided,
        "completion_time_s": t_complete,
        "counts": counts,
    }

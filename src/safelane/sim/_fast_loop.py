"""Optional compiled closed loop (numba, extra ``fast``): every period of every scenario in one compiled loop.

:func:`loop_kernel` runs a whole batch, scenario by scenario, period by period, with the state held in scalars and
small per-scenario arrays — no per-period NumPy arrays, no Python between the parts. One period is
:meth:`~.step.ClosedLoop.step` for the settings it covers (:func:`._fused.covers` says which): observe, the expert
planner, the chain analysis, **the shield** (:func:`safelane.shield.core.step`: the observed assessment, the
assumption monitor, proceed / hesitate / abort with the commit guard, the held plan, the responsible follow after
completion), the paper's traffic with the worst-case leader rule, the exact motion and the continuous-time checks.
It is built from the row functions of the part kernels (``_candidate``, ``_breach_row``, ``_chain_row``,
``_leader_row``, ``_follower_row``, ``_ego_row``, ``_general_pair``, ``_lane_row``), each tested bit for bit
against its NumPy function, with the held plan's evaluation from :mod:`._fast_held`, and writes the glue in the
NumPy path's evaluation order: the results table is the NumPy path's, bit for bit (``tests/test_fast_loop.py``,
several variants, sizes and settings).

:mod:`._fused` is the Python side (where it runs, the arrays in, the results out). Everything else runs period by
period (:mod:`.step`); ``SAFELANE_NO_NUMBA=1`` gives the NumPy path, the reference, and ``SAFELANE_NO_FUSED=1`` the
period-by-period path with its part kernels (what ``benchmarks/bench_core.py`` compares).
"""

from __future__ import annotations

import numba
import numpy as np

from ..planners.base import ExpertGains, expert_accel
from ..safety import _compile
from ..safety._backend import SCALAR, Limits, _clip
from ..safety._fast_base import (
    _max,
    _min,
    announce_compile,
)
from ..safety._fast_responsible import _responsible_bound
from ..safety.responsible import responsible_accel_core, responsible_ok_core
from ..shield._fast_decide import _candidate
from ..shield._fast_monitor import _breach_row
from ..shield.assessment import belief_core
from ..shield.decide import ABORT, COMPLETED, HESITATE, PROCEED, commit_guard_core, hesitate_core
from ..shield.proposals import proposal_core
from ..shield.stages import lane_keep_accel, worst_case_core
from ..tolerances import DIST_TOL_M
from ._fast_checks import _ego_row, _lane_row
from ._fast_general import _general_pair
from ._fast_held import _motion_max, _plan_motion
from ._fast_traffic import _chain_row, _follower_row, _leader_row
from .behaviours import hold_speed, last_accel, task_core
from .kinematics import constant_segment

_compile.register_rows()
announce_compile(__file__)

_INF = np.inf
#: Scalars of :func:`loop_kernel`'s ``prm`` vector, in order.
PRM = (
    "dt", "a_x_a", "a_x_d", "a_y_m", "y_safe", "p_m", "lane_width", "y_boundary", "vehicle_length", "conflict",
    "overlap", "lat_tol", "tol", "eps", "monitor_tol", "brake_start_s", "assess_threshold", "open_decel",
    "open_gap_m", "k_p", "k_v", "gap_fraction", "brake_comfort", "omega2", "two_omega", "a_o_d",
)  # fmt: skip
#: The plan fields the loop holds per scenario (the ones its evaluation needs), in order.
PLAN = (
    "ego_px", "ego_py", "ego_vx", "ego_vy", "l1_p", "l1_v", "l1_decel", "t_x1", "v_switch", "t_brake_end",
    "t_y_f", "t_y_switch", "y_acc_1", "y_acc_2", "t_y_end",
)  # fmt: skip
#: Float outputs per scenario.
OUT_F = ("t_complete", "min_gap_f", "min_gap_l1", "min_lane_ratio", "first_collaborative_s", "breach_first_s")
#: Bool outputs per scenario.
OUT_B = ("completed", "collided", "violated", "leader_collided", "leader_violated", "aggressive")


@numba.njit(cache=True, nogil=True, error_model="numpy")
def loop_kernel(
    n_steps, prm, window, x_init, v_init, ego_init, valid, n_connected, f_connected, f_aggressive, uses, promise,
    chain_margin, margin, is_last, acts, v_desired, promise_decel, promise_accel, decel_last, gap0, lane_valid,
    lane_margin, plan_init, follows_init, out_f, out_b, counts, n_invalid, breach_flags, bad_step,
):  # fmt: skip
    """Run every scenario of the batch through ``n_steps`` periods and the final observation (see the module
    docstring). Per scenario ``b``: inputs as :class:`~.step.ClosedLoop`'s arrays (``promise``, ``chain_margin``:
    ``(N, B)``; ``uses``: ``(B, 3)`` the variant's flags; ``plan_init``: ``(B, len(PLAN))`` the initial plan);
    outputs :data:`OUT_F`, :data:`OUT_B`, ``counts (B, 3)``, ``n_invalid``, ``breach_flags (B, 5)``, and
    ``bad_step`` (the first period whose state is not finite, ``-1`` if none)."""
    dt, a_a, a_d, a_ym, y_safe, p_m, lane_w, y_bound, length, conflict, overlap = prm[:11]
    lat_tol, tol, _eps, mon_tol, brake_start, thr, open_decel, open_gap = prm[11:19]
    k_p, k_v, gap_frac, brake_comfort, om2, two_om = prm[19:25]
    a_o = prm[25]  # the others' maximum braking (a_x_d: the ego's committed braking, its own limits only)
    a_lim = _max(a_a, a_d)
    gains, lim = ExpertGains(k_p, k_v, gap_frac, brake_comfort, om2, two_om), Limits(a_a, a_d, a_ym, y_safe)
    max_level = _max(conflict, overlap)
    bsz, k = x_init.shape
    m = k - 1
    # One scenario's vehicles: (1, K) arrays for the row functions, which index rows in place; 1-D views for the loop.
    x2, v2, bounds2, f_acc2, f_ts2, f_xe2, f_ve2 = (np.empty((1, k)), np.empty((1, k)), np.empty((1, k)),
                                                   np.empty((1, k)), np.empty((1, k)), np.empty((1, k)),
                                                   np.empty((1, k)))  # fmt: skip
    x, v, bounds, f_acc, f_ts, f_xe, f_ve = x2[0], v2[0], bounds2[0], f_acc2[0], f_ts2[0], f_xe2[0], f_ve2[0]
    acc, cap = np.empty(k), np.empty(k)
    snap_x2, snap_v2, snap_b2 = np.empty((1, m)), np.empty((1, m)), np.empty((1, m))
    snap_x, snap_v, snap_bounds = snap_x2[0], snap_v2[0], snap_b2[0]
    history = np.empty(window)
    general2 = np.zeros((1, k), np.bool_)
    general = general2[0]
    consts = (dt, p_m, a_lim, conflict, overlap, length, max_level)
    fleet = (x2, v2, f_acc2, f_ts2, f_xe2)  # (built once: a tuple of arrays costs reference counts each time)
    plan = np.empty(plan_init.shape[1])
    knots = np.empty((7, 8))  # the held plan's period: knots, samples, segment accelerations (_plan_motion)
    kt, kx, kv, ky, kvy, kax, kay = knots[0], knots[1], knots[2], knots[3], knots[4], knots[5], knots[6]
    scratch = np.empty(64)
    lon_t, lon_x, lon_v, lon_a = np.empty(3), np.empty(3), np.empty(3), np.empty(2)
    lat_t, lat_x, lat_v, lat_a = np.empty(2), np.empty(2), np.empty(2), np.empty(1)
    o_t, o_x, o_v, o_a = np.empty(3), np.empty(3), np.empty(3), np.empty(2)
    lo, hi = np.empty(2), np.empty(2)
    times = np.empty(window)
    for j in range(window):
        times[j] = (j - (window - 1) / 2.0) * dt
    den = times[0] * times[0]
    for j in range(1, window):
        den = den + times[j] * times[j]
    for b in range(bsz):
        for i in range(k):
            x[i], v[i], acc[i], cap[i] = x_init[b, i], v_init[b, i], 0.0, _INF
        ex, ey, evx, evy = ego_init[b, 0], ego_init[b, 1], ego_init[b, 2], ego_init[b, 3]
        for j in range(plan.shape[0]):
            plan[j] = plan_init[b, j]
        follows = follows_init[b]
        plan_t0, plan_f_aggr = 0.0, True
        uses_chain, uses_f_v2x, uses_assess = uses[b, 0], uses[b, 1], uses[b, 2]
        nc = n_connected[b]
        trusted = uses_f_v2x and f_connected[b]  # F connected and collaborative (a connected F declares itself so)
        completed, t_complete = False, np.nan
        collided = violated = l_collided = l_violated = False
        gap_f, gap_l1, lane_ratio = _INF, _INF, _INF
        n_pro = n_hes = n_abo = n_inv = 0
        for j in range(window):
            history[j] = 0.0
        count, aggressive, latched, first_collab = 0, True, False, np.nan
        br0 = br1 = br2 = br3 = False
        first_s = np.nan
        has_last = False
        snap_fx = snap_fv = snap_limit = snap_l1d = 0.0
        snap_active = False
        bad = -1
        t = 0.0
        for step in range(n_steps + 1):
            # --- the monitor's view of the last period (core.step / core.observe; after the last: finish) ---
            if has_last:
                f0, f1, f2, f3 = _breach_row(snap_x2, snap_v2, snap_b2, 0, x2, 0, 1, nc, snap_l1d, snap_fx, snap_fv,
                                             snap_limit, snap_active, x[0], True, dt, mon_tol)  # fmt: skip
                new = (f0 and not br0) or (f1 and not br1) or (f2 and not br2) or (f3 and not br3)
                if first_s != first_s and new:
                    first_s = t
                br0, br1, br2, br3 = br0 or f0, br1 or f1, br2 or f2, br3 or f3
            if step == n_steps:
                break
            # --- observe, the expert planner (planners.base.ExpertPlanner), the proposal checked ---
            ax_n, ay_n = expert_accel(SCALAR, x[0], x[1], v[1], ex, ey, evx, evy, gains, lane_w, lim)
            ok, ax_ok, ay_ok = proposal_core(SCALAR, ax_n, ay_n, lim)
            invalid = not ok
            a_x, a_y = _clip(ax_ok, -a_d, a_a), _clip(ay_ok, -a_ym, a_ym)
            # --- the chain analysis (ClosedLoop.chain) ---
            unsafe = _chain_row(x2, v2, 0, promise, chain_margin, b, a_o, bounds2)
            # --- the shield: assessment, worst cases ---
            for j in range(window - 1):
                history[j] = history[j + 1]
            history[window - 1] = v[0]
            count += 1
            num = history[0] * times[0]
            for j in range(1, window):
                num = num + history[j] * times[j]
            slope = num / den
            latched, aggressive = belief_core(SCALAR, slope, count >= window, latched, aggressive, thr)
            if first_collab != first_collab and not aggressive:
                first_collab = t
            broken = br0 or br1 or br2 or br3
            l1_decel, f_aggr = worst_case_core(SCALAR, uses_chain, unsafe, bounds[1], a_o, trusted, uses_assess,
                                               aggressive, broken)  # fmt: skip
            a_yh = hesitate_core(SCALAR, evy, dt, a_ym)
            active = not completed
            # --- proceed / hesitate / abort (decide.check_candidate with the commit guard) ---
            behaviour = COMPLETED
            completing = False
            if active:
                behaviour = ABORT
                for code in range(2):
                    if code == 0 and invalid:
                        continue
                    lateral = a_y if code == 0 else a_yh
                    state, period_ok, crossing, parts, bits = _candidate(
                        ex, ey, evx, evy, a_x, lateral, x[1], v[1], l1_decel, x[0], v[0], f_aggr, a_a, a_d, a_ym,
                        y_safe, p_m, dt, y_bound, lat_tol, tol,
                    )  # fmt: skip
                    if crossing:  # decide.commit_guard on the predicted states
                        pex, pevx, plx, plv, pfx, pfv = state[0], state[2], state[4], state[5], state[6], state[7]
                        keep = period_ok and commit_guard_core(SCALAR, pex, pevx, plx, plv, l1_decel, pfx, pfv, p_m,
                                                               a_d, tol)  # fmt: skip
                    else:
                        keep = period_ok and bits[0]
                    if keep:
                        behaviour = PROCEED if code == 0 else HESITATE
                        completing = crossing
                        # plan_from_core: the plan from the predicted state
                        plan[0], plan[1], plan[2], plan[3] = state[0], state[1], state[2], state[3]
                        plan[4], plan[5], plan[6] = state[4], state[5], l1_decel
                        plan[7], plan[8], plan[9] = parts[5], parts[6], parts[7]
                        for j in range(5):
                            plan[10 + j] = parts[j]
                        follows = bits[4]
                        plan_f_aggr = f_aggr
                        break
            ax_cmd = a_x
            ay_cmd = a_yh if behaviour == HESITATE else a_y
            if completed:  # after completion: centre in the target lane, follow L1 responsibly
                bound = _responsible_bound(x[1] - ex - p_m, evx, v[1], l1_decel, a_d, dt)
                ax_cmd = responsible_accel_core(SCALAR, a_x, bound, a_d)
                if l1_decel > a_d:  # L1 may brake harder than the ego: the closed form confirmed (stages.command)
                    if not responsible_ok_core(SCALAR, ax_cmd, x[1] - ex - p_m, evx, v[1], l1_decel, a_d, dt, tol):
                        ax_cmd = -a_d
                ay_cmd = lane_keep_accel(SCALAR, ey, evy, lane_w, a_ym)
            on_plan = behaviour == ABORT
            if on_plan:  # the aborting rows follow their held plan, exactly
                age = _max(t + 0.0 - plan_t0, 0.0)
                _plan_motion(plan, follows, age, dt, a_a, a_d, kt, kx, kv, ky, kvy, kax, kay)
                first = 0
                for j in range(7):
                    if kt[j + 1] - kt[j] > 0.0:
                        first = j
                        break
                span = kt[first + 1] - kt[first]
                ax_cmd = (kv[first + 1] - kv[first]) / span
                ay_cmd = (kvy[first + 1] - kvy[first]) / span
            if behaviour == PROCEED or behaviour == HESITATE:
                plan_t0 = t + 0.0 + dt
            # For the monitor at the next period: what a responsible follower of the ego could do this period.
            limit = _INF
            if active and not plan_f_aggr and ex - x[0] > 0.0:
                limit = _max(_responsible_bound(ex - x[0] - p_m, v[0], evx, a_d, a_o, dt), -a_o)
            for i in range(m):
                snap_x[i], snap_v[i], snap_bounds[i] = x[i + 1], v[i + 1], bounds[i + 1]
            snap_fx, snap_fv, snap_limit, snap_l1d, snap_active = x[0], v[0], limit, plan[6], active
            has_last = True
            # --- traffic (behaviours: worst-case leaders, F) on the running minimum of the chain bounds ---
            for i in range(k):
                cap[i] = _min(cap[i], bounds[i])
            a_last = last_accel(SCALAR, t, brake_start, decel_last[b])
            for i in range(k):
                a_i = 0.0
                if 1 <= i < k - 1 and acts[b, i]:
                    task = task_core(SCALAR, hold_speed(SCALAR, v[i], v_desired[b, i]), promise_decel[b, i],
                                     promise_accel[b, i])  # fmt: skip
                    a_i = _leader_row(x[i + 1] - x[i] - margin[b, i], v[i], v[i + 1], cap[i + 1], cap[i], task,
                                      False, 0.0, decel_last[b], a_o, dt)  # fmt: skip
                if is_last[b, i]:
                    a_i = a_last
                acc[i] = a_i
            acc[0] = _follower_row(x[0], v[0], x[1], v[1], ex, evx, f_aggressive[b], completed, gap0[b], False, 0.0,
                                   False, p_m, a_a, a_o, open_decel, open_gap, dt)  # fmt: skip
            row_acc = 0.0
            for i in range(k):
                f_acc[i], f_ts[i], f_xe[i], f_ve[i] = constant_segment(SCALAR, x[i], v[i], acc[i], dt)
                row_acc = _max(row_acc, abs(f_acc[i]))
            # --- the ego's motion: a constant command, or the held plan ---
            l_acc, l_ts, l_xe, l_ve = constant_segment(SCALAR, ex, evx, ax_cmd, dt)
            ey1 = ey + evy * dt + 0.5 * ay_cmd * dt * dt
            evy1 = evy + ay_cmd * dt
            # --- the checks (checks.ego_checks, lane_checks) ---
            p_ymax = _motion_max(kt, ky, kvy) if on_plan else 0.0
            p_xend = kx[7] if on_plan else 0.0
            p_yend = ky[7] if on_plan else 0.0
            hit, close, gap_f, gap_l1 = _ego_row(
                valid, b, x2, v2, 0, (ex, evx), (ex, evx, l_acc, l_ts, l_xe), (ey, evy, ay_cmd, ey1),
                (on_plan, p_ymax, p_xend, p_yend), fleet, row_acc, consts, (gap_f, gap_l1),
                general2,
            )  # fmt: skip
            for c in range(k):
                if not general[c]:
                    continue
                general[c] = False  # (for the next period)
                o_t[0], o_t[1], o_t[2] = 0.0, f_ts[c], dt
                o_x[0], o_x[1], o_x[2] = x[c], f_xe[c], f_xe[c]
                o_v[0], o_v[1], o_v[2] = v[c], f_ve[c], f_ve[c]
                o_a[0], o_a[1] = f_acc[c], 0.0
                for n_level in range(2):
                    level = conflict if n_level == 0 else overlap
                    if on_plan:
                        lo[n_level], hi[n_level] = _general_pair(kt, kx, kv, kax[:7], o_t, o_x, o_v, o_a, kt, ky, kvy,
                                                                 kay[:7], level, scratch)  # fmt: skip
                    else:
                        lon_t[0], lon_t[1], lon_t[2] = 0.0, l_ts, dt
                        lon_x[0], lon_x[1], lon_x[2] = ex, l_xe, l_xe
                        lon_v[0], lon_v[1], lon_v[2] = evx, l_ve, l_ve
                        lon_a[0], lon_a[1] = l_acc, 0.0
                        lat_t[0], lat_t[1] = 0.0, dt
                        lat_x[0], lat_x[1] = ey, ey1
                        lat_v[0], lat_v[1] = evy, evy1
                        lat_a[0] = ay_cmd
                        lo[n_level], hi[n_level] = _general_pair(lon_t, lon_x, lon_v, lon_a, o_t, o_x, o_v, o_a, lat_t,
                                                                 lat_x, lat_v, lat_a, level, scratch)  # fmt: skip
                hit = hit or (lo[1] < length and hi[1] > -length)
                close = close or (lo[0] < p_m - DIST_TOL_M and hi[0] > -p_m + DIST_TOL_M)
                if c == 0:
                    gap_f = _min(gap_f, -hi[0])
                elif c == 1:
                    gap_l1 = _min(gap_l1, lo[0])
            l_hit, l_close, ratio = _lane_row(lane_valid, lane_margin, b, x2, v2, f_acc2, f_ts2, f_xe2, f_ve2, 0,
                                              row_acc, dt, length)  # fmt: skip
            # --- advance (ClosedLoop.check_and_advance) ---
            if on_plan:
                ex, evx, ey, evy = kx[7], kv[7], ky[7], kvy[7]
            else:
                ex, evx, ey, evy = l_xe, l_ve, ey1, evy1
            for i in range(k):
                x[i], v[i] = f_xe[i], f_ve[i]
            completing = completing and active
            if completing and not completed:
                t_complete = t + dt
            completed = completed or completing
            collided, violated = collided or hit, violated or close
            l_collided, l_violated = l_collided or l_hit, l_violated or l_close
            lane_ratio = _min(lane_ratio, ratio)
            if behaviour == PROCEED:
                n_pro += 1
            elif behaviour == HESITATE:
                n_hes += 1
            elif behaviour == ABORT:
                n_abo += 1
            if invalid and active:
                n_inv += 1
            t = t + dt
            finite = abs(ex) < _INF and abs(ey) < _INF and abs(evx) < _INF and abs(evy) < _INF
            for i in range(k):
                finite = finite and abs(x[i]) < _INF and abs(v[i]) < _INF
            if not finite:
                bad = step
                break
        out_f[b, 0], out_f[b, 1], out_f[b, 2], out_f[b, 3] = t_complete, gap_f, gap_l1, lane_ratio
        out_f[b, 4], out_f[b, 5] = first_collab, first_s
        out_b[b, 0], out_b[b, 1], out_b[b, 2] = completed, collided, violated
        out_b[b, 3], out_b[b, 4], out_b[b, 5] = l_collided, l_violated, aggressive
        counts[b, 0], counts[b, 1], counts[b, 2] = n_pro, n_hes, n_abo
        n_invalid[b] = n_inv
        breach_flags[b, 0], breach_flags[b, 1], breach_flags[b, 2], breach_flags[b, 3] = br0, br1, br2, br3
        breach_flags[b, 4] = False
        bad_step[b] = bad

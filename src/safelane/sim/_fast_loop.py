"""Optional compiled closed loop (numba, extra ``fast``): every period of every scenario in one compiled loop.

:func:`loop_kernel` runs a whole batch, scenario by scenario, period by period, with the state held in scalars and
small per-scenario arrays — no per-period NumPy arrays, no Python between the parts. One period is
:meth:`~.step.ClosedLoop.step` for the settings it covers (:func:`._fused.covers` says which): observe, the expert
planner, the chain analysis, **the shield** (:func:`safelane.shield.core.step`: the observed assessment, the
assumption monitor, proceed / hesitate / abort with the commit guard, the held plan, the responsible follow after
completion), the paper's traffic with the worst-case leader rule, the exact motion and the continuous-time checks
— and the realistic world's side (``_fast_world.py``: the own lane, ``L0`` and any vehicles ahead of it, their
motion, the ego's checks against ``L0`` and their pairs'; the measurement noise of sensing error, the situation the
shield sees).
The shield's period is :func:`safelane.shield._fast_period.period_row` itself — the one glue of a period, the one
``Shield.step`` runs compiled — on one row whose situation, state and outputs are ``(1, .)`` arrays; the rest is
built from the row functions of the part kernels (``_leader_row``, ``_follower_row``, ``_ego_row``,
``_general_pair``, ``_lane_row``), each tested bit for bit against its NumPy function: the results table is the
NumPy path's, bit for bit (``tests/test_fast_loop.py``, several variants, sizes and settings).

:func:`loop_kernel` allocates the scratch arrays; the rows run in :func:`_loop_rows`, compiled without numba's
reference counting: with it, each period's call of ``period_row`` (34 array arguments) cost atomic increments and
decrements that made the loop 1.39x slower than the glue it replaces; without, it runs in the same time (4,000
scenarios at N = 3: 0.295 s CPU against 0.296 s for the loop with its own glue, three interleaved runs).

:mod:`._fused` is the Python side (where it runs, the arrays in, the results out). Everything else runs period by
period (:mod:`.step`); ``SAFELANE_NO_NUMBA=1`` gives the NumPy path, the reference, and ``SAFELANE_NO_FUSED=1`` the
period-by-period path with its part kernels (what ``benchmarks/bench_core.py`` compares).
"""

from __future__ import annotations

import collections

import numba
import numpy as np
from numba.core import types
from numba.extending import overload

from .._splitmix import counter_uniform4
from ..planners._fast_adversary import adversary_row
from ..planners.base import ExpertGains, expert_accel
from ..safety import _compile
from ..safety._backend import SCALAR, Limits
from ..safety._fast_base import _max, _min, announce_compiles, row_function
from ..shield._fast_period import _PRM_DELAY, _SF_CARRIED, carried_ego, observe_row, period_row, push_row
from ..shield.decide import ABORT, HESITATE, PROCEED
from ..tolerances import DIST_TOL_M
from ._fast_checks import _ego_row, _lane_row, _switch_pair
from ._fast_general import _general_pair
from ._fast_held import _motion_max
from ._fast_rows import _load, _scratch, _store, _window
from ._fast_traffic import (
    _chain_row,
    _follower_row,
    _leader_row,
    _profile_row,
    _sample_lanes,
    _wave_follower,
    _wave_task,
)
from ._fast_world import _switched, executed_plan, measure_row, own_advance, own_checks, own_lane_motion, own_pairs
from .behaviours import hold_speed, last_accel, link_decel, reactive_core, task_core, violation_accel
from .checks import far_gap, lateral_extent, near_pair, near_threshold
from .kinematics import constant_segment, piece_acc

_compile.register_rows()
announce_compiles()

_INF = np.inf
#: Scalars of :func:`loop_kernel`'s ``prm`` vector, in order.
PRM = (
    "dt", "a_x_a", "a_x_d", "a_y_m", "y_safe", "p_m", "lane_width", "vehicle_length", "conflict", "overlap",
    "monitor_tol", "brake_start_s", "open_decel", "open_gap_m", "k_p", "k_v", "gap_fraction", "brake_comfort",
    "omega2", "two_omega", "a_o_d", "reactive", "ignores_ego", "own_width", "shield_own", "sensing", "edge_share",
    "shield_sensing", "own_analysed",
)  # fmt: skip
#: ``PRM``'s entries of the shield's sensing: its box on (``ShieldConfig.sensing`` with sensing error: the stages'
#: ``observe`` takes the measurements' bounds), and the own lane analysed in it (``ShieldConfig.own_lane`` and some
#: row with an own-lane leader: ``stages.own_leader``, the box's third mode).
_SHIELD_SENSING, _OWN_ANALYSED = PRM.index("shield_sensing"), PRM.index("own_analysed")
#: The batch's inputs of :func:`loop_kernel`, per scenario (:class:`~.step.ClosedLoop`'s arrays; ``promise``,
#: ``chain_margin``: ``(N, B)``; ``uses``: ``(B, 3)`` the variant's flags).
LoopBatch = collections.namedtuple("LoopBatch", (
    "x", "v", "ego", "valid", "n_connected", "f_connected", "f_aggressive", "uses", "promise", "chain_margin", "margin",
    "is_last", "acts", "v_desired", "promise_decel", "promise_accel", "decel_last", "gap0", "lane_valid", "lane_margin",
    "p_v", "scenario_id", "key", "rule",
    "profile_t", "profile_a", "task_wave", "task_period", "f_wave", "wave_lane_valid", "wave_lane_margin",
    "lane_sample", "l0_profile_t", "l0_profile_a", "world_key", "err_f", "err_chain", "err_own", "own_nc",
    "own_promise", "own_brake_t", "own_v_desired", "planner_kind", "planner_q",
))  # fmt: skip
#: ``LoopBatch``'s last fields: ``L(N+1)``'s profile ``profile_t``, ``profile_a`` ``(B, P)`` (``P = 0``: none, the
#: sudden braking); :class:`~.traffic.WaveHooks` by scenario id (none: no rows) — ``task_wave`` ``(S, K, 5)`` (low,
#: span, high, low level, phase), ``task_period`` ``(S,)``, ``f_wave`` ``(S, 4)`` (period, phase, high, low level),
#: the lane-gap sample's pairs and margins ``(S, K−1)`` and its running minimum ``lane_sample`` ``(S,)`` (written;
#: none: no rows); the own lane's leader ``L0``'s profile ``l0_profile_t``, ``l0_profile_a`` ``(B, P0)`` (``P0 = 0``:
#: no own lane); the key of the world's draws ``world_key`` ``(B,)`` (``ScenarioBatch.world_key``, else the scenario
#: id) and the sensing-error bounds (``Situation.err_f`` ``(B, 2)``, ``err_chain`` ``(B, N + 1, 2)``, ``err_own``
#: ``(B, K0, 2)``: position, speed; zeros where ``prm``'s ``sensing`` is off); the own lane's chain
#: (:class:`~.own_chain.OwnLane`: ``own_nc`` ``(B,)`` its connected vehicles from ``L0`` on, ``own_promise``,
#: ``own_brake_t`` ``(B, K0 − 1)`` their promises and the instants they brake at them, ``own_v_desired`` ``(B, K0)``
#: every slot's initial speed; ``K0 = 1``: ``L0`` alone or no own lane); the nominal planner as data,
#: ``planner_kind`` ``(B,)`` and ``planner_q`` ``(B, 7)`` (:func:`~safelane.planners.adversarial.adversary_table`; no
#: rows: the expert planner).
#: What :func:`loop_kernel` writes: :data:`OUT_F`, :data:`OUT_B` per scenario, ``counts (B, 3)``, ``n_invalid``,
#: ``breach_flags (B, 5)``, ``bad_step`` (the first period whose state is not finite, ``-1`` if none) and the own
#: lane's final state ``own_x``, ``own_v`` ``(B, K0)``.
LoopOut = collections.namedtuple("LoopOut", ("f", "b", "counts", "n_invalid", "breach_flags", "bad_step", "own_x",
                                             "own_v"))  # fmt: skip
#: Float outputs per scenario.
OUT_F = ("t_complete", "min_gap_f", "min_gap_l1", "min_lane_ratio", "first_collaborative_s", "breach_first_s",
         "slow_delay_s", "min_gap_l0")  # fmt: skip
#: Bool outputs per scenario.
OUT_B = ("completed", "collided", "violated", "leader_collided", "leader_violated", "aggressive", "slow_missed",
         "slow_aggressive", "l0_collided", "l0_violated", "own_pair_collided")  # fmt: skip


@numba.njit(cache=True, nogil=True, error_model="numpy")
def loop_kernel(n_steps, prm, period_prm, batch, start, out, sense):
    """Run every scenario of ``batch`` (:class:`LoopBatch`) from its row of ``start`` (:data:`~._fast_rows.Rows`)
    through ``n_steps`` periods of its nominal planner (the expert, or ``batch``'s adversaries) and the final
    observation (see the module docstring), into ``out`` (:class:`LoopOut`); ``prm``: :data:`PRM`'s values,
    ``period_prm``: the shield's (``shield/_fast_period.PRM``); ``sense``: the scratch of the shield's sensing box
    (``_fused.sense_scratch``), ``None`` where it is off (compiled without it)."""
    _loop_rows(n_steps, prm, batch, start, out, _scratch(start, period_prm, sense))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def step_kernel(prm, period_prm, batch, rows, proposal, behaviour, finite, sense):
    """One period of every row of ``rows`` (:data:`~._fast_rows.Rows`, updated in place) with the nominal proposals
    ``proposal`` ``(B, 2)`` (the envs' actions) instead of the expert planner: each row's behaviour code into
    ``behaviour``, and ``finite[b]`` false where the row's state stopped being finite; ``sense``: as
    :func:`loop_kernel`'s."""
    _step_rows(prm, batch, rows, proposal, behaviour, finite, _scratch(rows, period_prm, sense))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def finish_kernel(prm, period_prm, batch, rows, sense):
    """The monitor's view of the last period of every row of ``rows`` (in place): what :func:`loop_kernel` does after
    a row's last period (``core.observe`` after the run: ``ClosedLoop.finish``); ``sense``: as
    :func:`loop_kernel`'s."""
    _finish_rows(prm, batch, rows, _scratch(rows, period_prm, sense))


@numba.njit(nogil=True, error_model="numpy", _nrt=False)
def _finish_rows(prm, batch, rows, w):
    """:func:`finish_kernel`'s rows, on its scratch arrays ``w``."""
    for b in range(rows.x.shape[0]):
        _load(rows, b, batch, w)
        _seen(prm, batch, b, w)
        _store(rows, b, w)


@row_function
def _own_seen(prm, batch, b, w):
    """The own lane of row ``b`` where the shield keeps ``p_m`` to it (``ShieldConfig.own_lane``) into the period's
    ``own_x``, ``own_v`` (its true states; ``+inf``: none, and everywhere where the shield ignores the lane), with
    its chain's promises and connected count (``Situation.own_promise``, ``own_n_connected``)."""
    o = w.own
    on = prm[24] > 0.0
    for i in range(w.own_x.shape[1]):
        w.own_x[0, i], w.own_v[0, i] = (o.x[0, i], o.v[0, i]) if on else (_INF, 0.0)
    if on:
        for i in range(w.own_promise.shape[1]):
            w.own_promise[0, i] = batch.own_promise[b, i]
        w.own_nc[0] = batch.own_nc[b]


@row_function
def _seen(prm, batch, b, w):
    """The monitor's view of the last period of row ``b`` (loaded into the scratch ``w``), where there is one:
    ``core.observe`` after the run (``ClosedLoop.finish``) — the target lane as the ego sees it now (the true
    states, or measured: ``prm``'s ``sensing``, ``realworld.measure``), at the sensing box's observed corner with the
    anchor's comparison where the shield's sensing is on (``_fast_period.observe_row``)."""
    if not w.rb[0, 4]:
        return
    x, v, chain_x, chain_v = w.x2[0], w.v2[0], w.chain_x, w.chain_v
    _own_seen(prm, batch, b, w)
    fx, fv = x[0], v[0]
    if prm[25] > 0.0:
        fx, fv = measure_row(batch, b, w.ri[0, 4], prm[26], x, v, chain_x, chain_v, w.own_x, w.own_v)
    else:
        for i in range(chain_x.shape[1]):
            chain_x[0, i], chain_v[0, i] = x[i + 1], v[i + 1]
    observe_row(0, w.rf[0, 4], prm[0], prm[10], chain_x, chain_v, w.own_x, w.own_v, fx, fv, w.px2, w.snap_x,
                w.snap_v, w.snap_b, w.snap_nc, w.st, w.sk, _sense(prm, batch, b, w.sense, True))  # fmt: skip


def _sense(prm, batch, b, a, has_last):
    """``period_row``'s ``sense`` tuple (``_fast_period.SENSE``) for row ``b`` on the scratch ``a``
    (``_fast_rows.Sense``), as ``shield/fast_step.sense_arrays`` builds it: with the shield's sensing on, the row's
    bounds (the own lane's where the shield keeps ``p_m`` to ``L0``, zeros else), every mode on but the own lane's
    where none is analysed, the held anchor where the monitor has a last period (``has_last``), and a new one made;
    off (``a`` is ``None``), ``None``: ``period_row`` compiled without them (an overload: a branch on ``a is None``
    would type the result as optional, which ``period_row`` cannot index)."""
    raise NotImplementedError("compiled only (numba)")


@overload(_sense, inline="always", jit_options=dict(_nrt=False, error_model="numpy", nogil=True))
def _sense_typed(prm, batch, b, a, has_last):
    if isinstance(a, types.NoneType):
        return lambda prm, batch, b, a, has_last: None
    return _sense_row


def _sense_row(prm, batch, b, a, has_last):
    """:func:`_sense` with the box's scratch ``a``."""
    boxed = prm[_SHIELD_SENSING] > 0.0
    a.modes[0], a.modes[1], a.modes[2] = boxed, boxed, prm[_OWN_ANALYSED] > 0.0
    err_own = a.err_own0[0:1]
    if prm[24] > 0.0 and batch.err_own.shape[1] > 0:
        err_own = batch.err_own[b : b + 1]
    held = 1 if boxed and has_last else 0
    made = 1 if boxed else 0
    return (batch.err_f[b : b + 1], batch.err_chain[b : b + 1], err_own, a.modes, a.corner_x, a.corner_v,
            a.anc_f[:held], a.anc_x[:held], a.anc_v[:held], a.anc_b[:held], a.anc_nc[:held], a.new_f[:made],
            a.new_x[:made], a.new_v[:made], a.new_b[:made], a.new_nc[:made])  # fmt: skip


@row_function
def _held(a, chain_x, chain_v):
    """After ``period_row``, with the shield's sensing on (the scratch ``a``; ``None``: off): the anchor made becomes
    the held one, and the snapshot is the chain at the analysis' corner (``fast_step.step``'s ``out.snapshot``);
    returns the snapshot's chain (``chain_x``, ``chain_v`` as seen, off)."""
    if a is None:
        return chain_x, chain_v
    if not a.modes[0]:
        return chain_x, chain_v
    for j in range(a.anc_f.shape[1]):
        a.anc_f[0, j] = a.new_f[0, j]
    for i in range(a.anc_x.shape[1]):
        a.anc_x[0, i], a.anc_v[0, i], a.anc_b[0, i] = a.new_x[0, i], a.new_v[0, i], a.new_b[0, i]
    a.anc_nc[0] = a.new_nc[0]
    return a.corner_x, a.corner_v


@numba.njit(nogil=True, error_model="numpy", _nrt=False)
def _loop_rows(n_steps, prm, batch, start, out, w):
    """:func:`loop_kernel`'s rows, on its scratch arrays ``w`` (no allocation, no reference counting)."""
    dt, lane_w = prm[0], prm[6]
    a_a, a_d, a_ym, y_safe = prm[1], prm[2], prm[3], prm[4]
    gains = ExpertGains(prm[14], prm[15], prm[16], prm[17], prm[18], prm[19])
    lim = Limits(a_a, a_d, a_ym, y_safe)
    out_f, out_b, counts, n_invalid, breach_flags, bad_step, own_x, own_v = out
    x2, v2, st, sk, rf, rb, ri = w.x2, w.v2, w.st, w.sk, w.rf, w.rb, w.ri
    x, v = x2[0], v2[0]
    den = _window(w.times, dt)
    adversaries = batch.planner_kind.shape[0] > 0
    for b in range(start.x.shape[0]):
        _load(start, b, batch, w)
        bad = -1
        for step in range(n_steps + 1):
            if step == n_steps:  # the monitor's view of the last period (core.observe after the run: finish)
                _seen(prm, batch, b, w)
                break
            # --- observe, the nominal planner: the expert (planners.base.ExpertPlanner) or an adversary as data ---
            if adversaries:
                ax_n, ay_n = adversary_row(batch.planner_kind[b], batch.planner_q, b, rf[0, 4], rf[0, 0], rf[0, 1],
                                           rf[0, 2], rf[0, 3], x[1], v[1], x[0], v[0], prm[5], lane_w, lim)  # fmt: skip
            else:
                ax_n, ay_n = expert_accel(SCALAR, x[0], x[1], v[1], rf[0, 0], rf[0, 1], rf[0, 2], rf[0, 3], gains,
                                          lane_w, lim)  # fmt: skip
            _, finite = _period(prm, batch, b, w, den, ax_n, ay_n)
            if not finite:
                bad = step
                break
        out_f[b, 0], out_f[b, 1], out_f[b, 2], out_f[b, 3] = rf[0, 5], rf[0, 6], rf[0, 7], rf[0, 8]
        out_f[b, 4], out_f[b, 5], out_f[b, 6] = st[0, 1], st[0, 2], st[0, 7]
        out_f[b, 7] = rf[0, 9]
        out_b[b, 0], out_b[b, 1], out_b[b, 2] = rb[0, 7], rb[0, 0], rb[0, 1]
        out_b[b, 3], out_b[b, 4], out_b[b, 5] = rb[0, 2], rb[0, 3], sk[0, 2]
        out_b[b, 6], out_b[b, 7] = sk[0, 10], sk[0, 11]
        out_b[b, 8], out_b[b, 9], out_b[b, 10] = rb[0, 5], rb[0, 6], rb[0, 8]
        for i in range(own_x.shape[1]):
            own_x[b, i], own_v[b, i] = w.own.x[0, i], w.own.v[0, i]
        counts[b, 0], counts[b, 1], counts[b, 2] = ri[0, 0], ri[0, 1], ri[0, 2]
        n_invalid[b] = ri[0, 3]
        for j in range(breach_flags.shape[1]):
            breach_flags[b, j] = sk[0, 5 + j]
        bad_step[b] = bad


@numba.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _step_rows(prm, batch, rows, proposal, behaviour, finite, w):
    """:func:`step_kernel`'s rows, on its scratch arrays ``w``: one period of every row. The envs' step
    (``envs/_fast.py``) calls it too, so the period is compiled once for both (cached on its own: a kernel that
    calls it loads it from the cache rather than compiling the period again)."""
    den = _window(w.times, prm[0])
    for b in range(rows.x.shape[0]):
        _load(rows, b, batch, w)
        behaviour[b], finite[b] = _period(prm, batch, b, w, den, proposal[b, 0], proposal[b, 1])
        _store(rows, b, w)


@row_function
def _ego_pieces(lon_t, lon_x, lon_v, lon_a, lat_t, lat_x, lat_v, lat_a, dt, ex, evx, l_ts, l_xe, l_ve, l_acc, ey, ey1,
                evy, evy1, ay_cmd):  # fmt: skip
    """The ego's motion over the period off its held plan, as the checks take it: longitudinal ``(t, x, v, a)`` knots
    ``0, l_ts, dt`` (constant ``l_acc`` until ``l_ts``, at rest after: ``kinematics.constant_segment``), lateral one
    free segment ``0, dt`` at ``ay_cmd`` — into the pieces' arrays (what the target lane's pairs and ``L0``'s read)."""
    lon_t[0], lon_t[1], lon_t[2] = 0.0, l_ts, dt
    lon_x[0], lon_x[1], lon_x[2] = ex, l_xe, l_xe
    lon_v[0], lon_v[1], lon_v[2] = evx, l_ve, l_ve
    lon_a[0], lon_a[1] = l_acc, 0.0
    lat_t[0], lat_t[1] = 0.0, dt
    lat_x[0], lat_x[1] = ey, ey1
    lat_v[0], lat_v[1] = evy, evy1
    lat_a[0] = ay_cmd


@row_function
def _draw(batch, b, step, slot, salt):
    """The closed loop's counter-based draw of row ``b`` (``rng.counter_uniform(seed, scenario id, step, slot, salt)``:
    promise violations, salts 7 and 8)."""
    return counter_uniform4(batch.key[0], batch.scenario_id[b], step, slot, salt)


@row_function
def _without(out, flags, b, i):
    """Row ``b`` of ``flags`` with entry ``i`` off, into ``out`` ``(1, .)``; returns ``out``."""
    for j in range(flags.shape[1]):
        out[0, j] = flags[b, j]
    if i >= 0:
        out[0, i] = False
    return out


@row_function
def _period(prm, batch, b, w, den, ax_n, ay_n):
    """One control period of row ``b`` on the scratch ``w`` (its state loaded by :func:`_load`) with the nominal
    proposal ``(ax_n, ay_n)``: the shield (``period_row``), the traffic, the motion, the checks, the running values.
    Returns the behaviour code and whether the row's state is still finite."""
    dt, a_a, a_d, p_m, length, conflict, overlap = prm[0], prm[1], prm[2], prm[5], prm[7], prm[8], prm[9]
    brake_start, open_decel, open_gap = prm[11:14]
    a_o = prm[20]  # the others' maximum braking (a_x_d: the ego's committed braking, its own limits only)
    a_lim = _max(a_a, a_d)
    max_level = _max(conflict, overlap)
    valid, n_connected, f_aggressive, margin = batch.valid, batch.n_connected, batch.f_aggressive, batch.margin
    is_last, acts, v_desired, gap0 = batch.is_last, batch.acts, batch.v_desired, batch.gap0
    promise_decel, promise_accel, decel_last = batch.promise_decel, batch.promise_accel, batch.decel_last
    k = valid.shape[1]
    m = k - 1
    (x2, v2, f_acc2, f_ts2, f_xe2, f_ve2, acc, cap, general2, pp, sf, sb, chain_x, chain_v, own_x, own_v, own_promise,
     own_nc, history, count, st, sk, plan, snap_x, snap_v, snap_b, snap_nc, bounds_out, no_chain, of, ob, knots, px2,
     pv2, pb2, kn, kax, kay, scratch, lon_t, lon_x, lon_v, lon_a, lat_t, lat_x, lat_v, lat_a, o_t, o_x, o_v, o_a, lo,
     hi, times, rf, rb, ri, sw, own, q_knots, q_seg, q_acc, q_flag, segs, sn) = w  # fmt: skip
    x, v, f_acc, f_ts, f_xe, f_ve = x2[0], v2[0], f_acc2[0], f_ts2[0], f_xe2[0], f_ve2[0]
    general = general2[0]
    consts = (dt, p_m, a_lim, conflict, overlap, length, max_level)
    fleet = (x2, v2, f_acc2, f_ts2, f_xe2)
    bounds = pb2[0]  # the chain's bounds with F's slot (a_o), as period_row leaves them
    kt, kx, kv, ky, kvy = kn[0], kn[1], kn[2], kn[3], kn[4]
    link_promise, link_margin = batch.promise[:, b : b + 1], batch.chain_margin[:, b : b + 1]
    nc = n_connected[b]
    ex, ey, evx, evy, t = rf[0, 0], rf[0, 1], rf[0, 2], rf[0, 3], rf[0, 4]
    gap_f, gap_l1 = rf[0, 6], rf[0, 7]
    # --- the shield (core.step): one period of shield/_fast_period.period_row ---
    # the situation: the true states, or as measured (sensing error: realworld.measure); F's observed speed is its
    # true one (ClosedLoop.step); the own lane where the shield keeps p_m to it (+inf: none)
    sensing = prm[25] > 0.0
    _own_seen(prm, batch, b, w)
    fx_seen, fv_seen = x[0], v[0]
    if sensing:
        fx_seen, fv_seen = measure_row(batch, b, ri[0, 4], prm[26], x, v, chain_x, chain_v, own_x, own_v)
    else:
        for i in range(m):
            chain_x[0, i], chain_v[0, i] = x[i + 1], v[i + 1]
    sf[0, 0], sf[0, 1], sf[0, 2], sf[0, 3], sf[0, 4], sf[0, 5] = ex, ey, evx, evy, fx_seen, fv_seen
    sf[0, 6], sf[0, 7], sf[0, 8], sf[0, 9] = v[0], ax_n, ay_n, nc
    pp[0] = t
    if pp[_PRM_DELAY] > 0.0:  # the shield's delay is the world's (_fused): the world's commands in flight are its own
        for j in range(segs.shape[0]):  # an aborting command over its segments, another over one (Command.piece's
            segs[j] = q_seg.shape[3] if q_flag[0, j, 1] else 1  # segments of length 0 leave the bits as they are)
        c = _SF_CARRIED
        sf[0, c], sf[0, c + 1], sf[0, c + 2], sf[0, c + 3] = carried_ego(0, dt, segs, q_knots, q_seg, q_acc, q_flag,
                                                                         ex, ey, evx, evy)  # fmt: skip
    completed = rb[0, 7]  # the world's (with an actuation delay the command acting completes it, not the one issued)
    active = not completed
    # F's acceleration (behaviours.follower_accel) reads the period's start only, not the shield's decision: computed
    # before the shield, so that its arithmetic can overlap the shield's in the processor (stored in acc after the
    # leaders, as before)
    sid = batch.scenario_id[b]
    waves = batch.task_period.shape[0] > 0  # the leaders' and F's wishes from WaveHooks
    f_wish = _wave_follower(batch, sid, t, a_a, a_d) if waves else 0.0
    a_f = _follower_row(x[0], v[0], x[1], v[1], ex, evx, f_aggressive[b], completed, gap0[b], waves, f_wish,
                        prm[22] > 0.0, p_m, a_a, a_o, open_decel, open_gap, dt)  # fmt: skip
    behaviour = period_row(0, pp, times, den, sf, sb, batch.rule[b : b + 1], chain_x, chain_v, link_promise,
                           link_margin, own_x, own_v, own_promise, own_nc, history, count, st, sk, plan, rb[0, 4],
                           snap_x, snap_v, snap_b, snap_nc, bounds_out, no_chain, of, ob, knots, px2, pv2, pb2,
                           kn, _sense(prm, batch, b, sn, rb[0, 4]))  # fmt: skip
    ax_cmd, ay_cmd = of[0, 0], of[0, 1]
    completing, invalid_active = ob[0, 0], ob[0, 1]
    # The snapshot the next period's monitor compares with (the caller keeps it: fast_step.step): the chain as seen,
    # at the analysis' corner with the shield's sensing on; the anchor made becomes the held one.
    seen_x, seen_v = _held(sn, chain_x, chain_v)
    for i in range(m):
        snap_x[0, i], snap_v[0, i], snap_b[0, i] = seen_x[0, i], seen_v[0, i], bounds[i + 1]
    snap_nc[0] = nc
    rb[0, 4] = True
    on_plan = ob[0, 4]  # the held plan's motion (an abort under the paper's rule; an RSS response is constant)
    if q_knots.shape[1] > 0:  # the actuation delay: the oldest command in flight acts, executed from the ego's state
        on_plan, ax_cmd, ay_cmd, completing = q_flag[0, 0, 1], q_acc[0, 0, 0], q_acc[0, 0, 1], q_flag[0, 0, 0]
        if on_plan:  # (into kn: the command issued, which push_row queues, is in knots)
            executed_plan(q_knots[0, 0], q_seg[0, 0, 0], q_seg[0, 0, 1], ex, ey, evx, evy, kt, kx, kv, ky, kvy)
        push_row(0, of, ob, knots, q_knots, q_seg, q_acc, q_flag)  # the oldest leaves, this period's joins
    if on_plan:  # the plan's period (the held plan's knots and samples from period_row, or executed): its segments'
        for j in range(7):  # accelerations
            span = kt[j + 1] - kt[j]
            kax[j] = piece_acc(SCALAR, kv[j], kv[j + 1], span)
            kay[j] = piece_acc(SCALAR, kvy[j], kvy[j + 1], span)
    # --- traffic (behaviours: the leaders by their rule, F) ---
    true_bounds = bounds  # the traffic's chain analysis is on the true states (ClosedLoop.chain)
    if sensing:  # the shield's was on the measured ones
        _chain_row(x2, v2, 0, link_promise, link_margin, 0, a_o, pv2)
        true_bounds = pv2[0]
    for i in range(k):
        cap[i] = _min(cap[i], true_bounds[i])
    sw_t, sw_a = dt, 0.0  # L(N+1)'s profile: a switch inside the period at sw_t to sw_a (dt: none)
    if batch.profile_t.shape[1] > 0:
        a_last, sw_t, sw_a = _profile_row(batch.profile_t, batch.profile_a, b, t, dt)
    else:
        a_last = last_accel(SCALAR, t, brake_start, decel_last[b])
    if batch.lane_sample.shape[0] > 0:  # (WaveHooks' sample of the lane gaps, before the leaders' wishes)
        _sample_lanes(batch, sid, x)
    p_v, step = batch.p_v[b], ri[0, 4]
    if prm[21] > 0.0:  # SimConfig.leader_rule "reactive" (behaviours.reactive_leader_accels): front to back
        for i in range(k - 1, 0, -1):
            a_i = 0.0
            if is_last[b, i]:
                a_i = a_last
            elif acts[b, i]:
                z = 0.0
                if i + 1 < k:
                    z = link_decel(SCALAR, x[i + 1] - x[i] - margin[b, i], v[i], v[i + 1], _max(-acc[i + 1], 0.0),
                                   a_o)  # fmt: skip
                if p_v > 0.0 and _draw(batch, b, step, i, 7) < p_v:  # an unexpected violation replaces the rule
                    a_i = violation_accel(SCALAR, z, decel_last[b], _draw(batch, b, step, i, 8))
                else:
                    wish = _wave_task(batch, sid, i, t) if waves else hold_speed(SCALAR, v[i], v_desired[b, i])
                    task = task_core(SCALAR, wish, promise_decel[b, i], promise_accel[b, i])
                    a_i = reactive_core(SCALAR, task, z)
            acc[i] = a_i
    else:  # "worst_case" (behaviours.leader_accels), on the running minimum of the chain bounds
        for i in range(k):
            a_i = 0.0
            if 1 <= i < k - 1 and acts[b, i]:
                wish = _wave_task(batch, sid, i, t) if waves else hold_speed(SCALAR, v[i], v_desired[b, i])
                task = task_core(SCALAR, wish, promise_decel[b, i], promise_accel[b, i])
                breaks = p_v > 0.0 and _draw(batch, b, step, i, 7) < p_v  # an unexpected violation
                pick = _draw(batch, b, step, i, 8) if breaks else 0.0
                a_i = _leader_row(x[i + 1] - x[i] - margin[b, i], v[i], v[i + 1], cap[i + 1], cap[i], task,
                                  breaks, pick, decel_last[b], a_o, dt)  # fmt: skip
            if is_last[b, i]:
                a_i = a_last
            acc[i] = a_i
    acc[0] = a_f
    row_acc = 0.0
    for i in range(k):
        f_acc[i], f_ts[i], f_xe[i], f_ve[i] = constant_segment(SCALAR, x[i], v[i], acc[i], dt)
        row_acc = _max(row_acc, abs(f_acc[i]))
    last = nc + 1
    switching = sw_t < dt
    if switching:  # L(N+1) switches inside the period: two segments (kinematics.Fleet.switched), its knots in sw
        row_acc = _max(row_acc, _switched(x[last], v[last], f_acc, f_ts, f_xe, f_ve, last, sw_t, sw_a, dt, sw))
    # --- the ego's motion: a constant command, or the held plan ---
    l_acc, l_ts, l_xe, l_ve = constant_segment(SCALAR, ex, evx, ax_cmd, dt)
    ey1 = ey + evy * dt + 0.5 * ay_cmd * dt * dt
    evy1 = evy + ay_cmd * dt
    # --- the checks (checks.ego_checks, lane_checks) ---
    p_ymax = _motion_max(kt, ky, kvy) if on_plan else 0.0
    p_xend = kx[7] if on_plan else 0.0
    p_yend = ky[7] if on_plan else 0.0
    ego_valid, vb = valid, b
    if switching:  # the switching vehicle's pair is checked below, on its two segments
        ego_valid, vb = _without(sw.valid, valid, b, last), 0
    hit, close, gap_f, gap_l1 = _ego_row(
        ego_valid, vb, x2, v2, 0, (ex, evx), (ex, evx, l_acc, l_ts, l_xe), (ey, evy, ay_cmd, ey1),
        (on_plan, p_ymax, p_xend, p_yend), fleet, row_acc, consts, (gap_f, gap_l1),
        general2,
    )  # fmt: skip
    if switching:  # its pair with the ego as ego_checks takes a switching vehicle's: near, the general path
        y_max, xe_, ye_ = lateral_extent(SCALAR, ey, evy, ay_cmd, dt)[1], l_xe, ey1
        if on_plan:
            y_max, xe_, ye_ = p_ymax, p_xend, p_yend
        d0 = x[last] - ex
        if near_pair(SCALAR, valid[b, last], d0, v[last] - evx, near_threshold(SCALAR, p_m, a_lim + row_acc, dt),
                     y_max, conflict, dt):  # fmt: skip
            general[last] = True
        elif last == 1:
            gap_l1 = far_gap(SCALAR, gap_l1, valid[b, last], 1.0, d0, ey, f_xe[last] - xe_, ye_, conflict)
    for c in range(k):
        if not general[c]:
            continue
        general[c] = False  # (for the next period)
        o_t[0], o_t[1], o_t[2] = 0.0, f_ts[c], dt
        o_x[0], o_x[1], o_x[2] = x[c], f_xe[c], f_xe[c]
        o_v[0], o_v[1], o_v[2] = v[c], f_ve[c], f_ve[c]
        o_a[0], o_a[1] = f_acc[c], 0.0
        m_t, m_x, m_v, m_a = o_t, o_x, o_v, o_a
        if switching and c == last:
            m_t, m_x, m_v, m_a = sw.t, sw.x, sw.v, sw.a
        for n_level in range(2):
            level = conflict if n_level == 0 else overlap
            if on_plan:
                lo[n_level], hi[n_level] = _general_pair(kt, kx, kv, kax[:7], m_t, m_x, m_v, m_a, kt, ky, kvy,
                                                         kay[:7], level, scratch)  # fmt: skip
            else:
                _ego_pieces(lon_t, lon_x, lon_v, lon_a, lat_t, lat_x, lat_v, lat_a, dt, ex, evx, l_ts, l_xe, l_ve,
                            l_acc, ey, ey1, evy, evy1, ay_cmd)  # fmt: skip
                lo[n_level], hi[n_level] = _general_pair(lon_t, lon_x, lon_v, lon_a, m_t, m_x, m_v, m_a, lat_t,
                                                         lat_x, lat_v, lat_a, level, scratch)  # fmt: skip
        hit = hit or (lo[1] < length and hi[1] > -length)
        close = close or (lo[0] < p_m - DIST_TOL_M and hi[0] > -p_m + DIST_TOL_M)
        if c == 0:
            gap_f = _min(gap_f, -hi[0])
        elif c == 1:
            gap_l1 = _min(gap_l1, lo[0])
    lane_valid, lane_margin, pb = batch.lane_valid, batch.lane_margin, b
    if switching:  # the pair behind the switching vehicle is checked below, on its two segments
        lane_valid, lane_margin, pb = _without(sw.lane_valid, batch.lane_valid, b, last - 1), sw.lane_margin, 0
        for c in range(k - 1):
            lane_margin[0, c] = batch.lane_margin[b, c]
    l_hit, l_close, ratio = _lane_row(lane_valid, lane_margin, pb, x2, v2, f_acc2, f_ts2, f_xe2, f_ve2, 0,
                                      row_acc, dt, length)  # fmt: skip
    c = last - 1
    if switching and batch.lane_valid[b, c]:  # as lane_checks takes a switching pair (near: its exact minimum)
        pair_hit, pair_close, pair_ratio = _switch_pair(x, v, f_acc, f_ts, f_xe, f_ve, c, sw, o_t, o_x, o_v, o_a,
                                                        batch.lane_margin[b, c], row_acc, dt, length, scratch)
        l_hit, l_close, ratio = l_hit or pair_hit, l_close or pair_close, _min(ratio, pair_ratio)
    # --- the own lane (ClosedLoop._own_lane): its motion (own_chain.OwnLane.period), its vehicles' pairs, the ego's
    # checks against L0 (an own lane without L0 has no vehicle: own_chain.check_chain) ---
    ox = own.x[0]
    if ox[0] < _INF:
        o_switch, o_acc = own_lane_motion(batch, b, own, t, dt, a_a, a_o, p_m)
        head = batch.own_nc[b]
        if ox.shape[0] > 1:
            rb[0, 8] = own_pairs(own, head, o_switch, o_acc, p_m, dt, length, o_t, o_x, o_v, o_a, scratch) or rb[0, 8]
        m_t, m_x, m_v, m_a = own.sw.t, own.sw.x, own.sw.v, own.sw.a  # L0's motion: the head's, switching
        if not (o_switch and head == 0):
            m_t, m_x, m_v, m_a = o_t, o_x, o_v, o_a
            o_t[0], o_t[1], o_t[2] = 0.0, own.ts[0, 0], dt
            o_x[0], o_x[1], o_x[2] = own.fx[0, 0], own.xe[0, 0], own.xe[0, 0]
            o_v[0], o_v[1], o_v[2] = own.fv[0, 0], own.ve[0, 0], own.ve[0, 0]
            o_a[0], o_a[1] = own.acc[0, 0], 0.0
        if on_plan:
            o_hit, o_close, o_low = own_checks(m_t, m_x, m_v, m_a, (kt, kx, kv, kax[:7]), (kt, ky, kvy, kay[:7]),
                                               prm[23], length, p_m, own, scratch)  # fmt: skip
        else:
            _ego_pieces(lon_t, lon_x, lon_v, lon_a, lat_t, lat_x, lat_v, lat_a, dt, ex, evx, l_ts, l_xe, l_ve, l_acc,
                        ey, ey1, evy, evy1, ay_cmd)  # fmt: skip
            o_hit, o_close, o_low = own_checks(m_t, m_x, m_v, m_a, (lon_t, lon_x, lon_v, lon_a),
                                               (lat_t, lat_x, lat_v, lat_a), prm[23], length, p_m, own,
                                               scratch)  # fmt: skip
        o_close = o_close and not completed
        hit, close = hit or o_hit, close or o_close
        rb[0, 5], rb[0, 6] = rb[0, 5] or o_hit, rb[0, 6] or o_close
        rf[0, 9] = _min(rf[0, 9], o_low)
        own_advance(own)
    # --- advance (ClosedLoop.check_and_advance) ---
    if on_plan:
        ex, evx, ey, evy = kx[7], kv[7], ky[7], kvy[7]
    else:
        ex, evx, ey, evy = l_xe, l_ve, ey1, evy1
    for i in range(k):
        x[i], v[i] = f_xe[i], f_ve[i]
    completing = completing and active
    if completing and not completed:
        rf[0, 5] = t + dt
    rb[0, 7] = completed or completing
    rb[0, 0], rb[0, 1] = rb[0, 0] or hit, rb[0, 1] or close
    rb[0, 2], rb[0, 3] = rb[0, 2] or l_hit, rb[0, 3] or l_close
    rf[0, 6], rf[0, 7], rf[0, 8] = gap_f, gap_l1, _min(rf[0, 8], ratio)
    if behaviour == PROCEED:
        ri[0, 0] += 1
    elif behaviour == HESITATE:
        ri[0, 1] += 1
    elif behaviour == ABORT:
        ri[0, 2] += 1
    if invalid_active:
        ri[0, 3] += 1
    ri[0, 4] += 1
    rf[0, 0], rf[0, 1], rf[0, 2], rf[0, 3], rf[0, 4] = ex, ey, evx, evy, t + dt
    finite = abs(ex) < _INF and abs(ey) < _INF and abs(evx) < _INF and abs(evy) < _INF
    for i in range(k):
        finite = finite and abs(x[i]) < _INF and abs(v[i]) < _INF
    return behaviour, finite

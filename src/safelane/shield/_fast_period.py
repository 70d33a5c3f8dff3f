"""Optional compiled control period of the shield (numba, extra ``fast``): :func:`safelane.shield.core.step`'s stages
for every row in one compiled call, for the settings :func:`.fast_step.refusals` accepts.

No rule lives here: :func:`period_kernel` is the stages' glue, row by row, calling the one source of each rule — the
assessment's :func:`~.assessment.belief_core`, the chain scan's link (``_chain_row`` →
:func:`~safelane.safety.chain.chain_link`), the monitor's comparisons (``_breach_row`` →
:func:`~.monitor.braked_harder`, :func:`~.monitor.pushed_harder`), :func:`~.stages.worst_case_core`,
:func:`~.proposals.proposal_core`, the candidate check (``_candidate`` → :func:`~.decide.candidate_row`), the
completion guard :func:`~.decide.commit_guard_core`, :func:`~.decide.hesitate_core`, the sensing box's corners
(:func:`~.realworld.behind_corner`, :func:`~.realworld.ahead_corner`; each chain link at its own corner,
:func:`~.realworld.link_at_corner`) and the monitor's cumulative comparison (``_fast_monitor.anchor_row``,
:func:`~.monitor.anchor_renewal`, :func:`~.monitor.anchor_carry`), the own-lane leader ``L0`` (its
chain's bound through :func:`~.realworld.link_at_corner`, the period with it
:func:`~safelane.safety.own_lane.own_period`, its evasion check ``_fast_own._own_lane``), the frame of a delayed
decision (the ego carried over the commands in flight, :func:`carried_ego` → :func:`~.command.segment_core`; the
others along their worst cases, :func:`~.realworld.carried_others`, :func:`~.realworld.carry_worst_core`; the new
command queued, :func:`push_row`), the responsible follow
(:mod:`safelane.safety.responsible`), :func:`~.stages.lane_keep_accel`, the held plan's motion
(:func:`~safelane.safety.plan.plan_state`, :func:`~.decide.plan_switches`) and
:func:`~safelane.safety.plan.plan_reason`.
It writes what the NumPy stages compute, in their order of evaluation, so a row's decision and state are the stages'
bits (``tests/test_fast_period.py`` compares them field by field over many periods). :mod:`.fast_step` is the Python
side (the state packed into arrays between periods, the :class:`~.decision.Decision` built from them).

**One glue.** The compiled closed loop (``sim/_fast_loop.py``) calls :func:`period_row` for its shield's period:
there is no second copy of a period's glue. :func:`period_row` and :func:`monitor_row` are row functions (inlined,
compiled without numba's reference counting: their 34 array arguments would cost 68 atomic reference-count
operations per row), and the loop runs its rows without reference counting too (docs/architecture.md, "One glue of
a period"). The held plan's knots come from :func:`plan_knots`.
"""

from __future__ import annotations

import numba
import numpy as np

from ..safety import _compile
from ..safety._backend import SCALAR, Limits, _clip
from ..safety._fast_base import announce_compiles, float_bits, row_function, sort_short
from ..safety._fast_responsible import _responsible_bound
from ..safety.own_lane import own_period
from ..safety.plan import PlanRecord, plan_reason, plan_state
from ..safety.responsible import responsible_accel_core, responsible_ok_core
from ..sim._fast_traffic import _chain_row
from ..sim.kinematics import piece_acc
from ._fast_decide import _candidate
from ._fast_monitor import _breach_row, anchor_row
from ._fast_own import _own_lane
from ._fast_rules import rule_row
from .assessment import belief_core
from .command import segment_core
from .decide import (
    ABORT,
    COMPLETED,
    HESITATE,
    PROCEED,
    candidate_period,
    commit_guard_core,
    hesitate_core,
    plan_switches,
)
from .monitor import anchor_carry, anchor_renewal
from .policies import slow_belief, slow_draws
from .proposals import proposal_core
from .realworld import ahead_corner, behind_corner, carried_others, carry_worst_core, link_at_corner
from .stages import lane_keep_accel, worst_case_core

_compile.register_rows()
announce_compiles()

_INF = np.inf
#: Scalars of :func:`period_kernel`'s ``prm`` vector, in order.
PRM = (
    "t", "dt", "a_x_a", "a_x_d", "a_y_m", "y_safe", "p_m", "p_m_human", "y_boundary", "lane_width", "a_o_d",
    "lat_tol", "tol", "monitor_tol", "assess_threshold", "monitor", "own_level", "own_margin", "truth",
    "paper_evasion", "slow", "assess_delay_s", "assess_miss", "time_tol", "vehicle_length", "vehicle_width",
    "delay_s",
)  # fmt: skip
_PRM_DELAY = PRM.index("delay_s")  # the actuation delay [s] (whole periods; 0: none)
#: Columns of the situation's per-row floats ``sf``.
SIT_F = ("ego_x", "ego_y", "ego_vx", "ego_vy", "f_x", "f_v", "f_observed", "a_x", "a_y", "n_connected",
         "carried_x", "carried_y", "carried_vx", "carried_vy")  # fmt: skip
#: The first of the ego's columns carried over the commands in flight (:func:`carried_ego`; read under a delay).
_SF_CARRIED = SIT_F.index("carried_x")
#: Columns of the situation's per-row flags ``sb``: F trusted over V2X (connected and collaborative), a stale V2X
#: sender, the variant's flags (uses the chain, F's V2X, the assessment), F's true type (the ``truth`` assessment).
SIT_B = ("f_trusted", "stale", "uses_chain", "uses_f_v2x", "uses_assessment", "f_aggressive_truth")
#: The held plan's columns (:class:`~safelane.safety.plan.EvasionPlan`'s fields, booleans and the reason as floats).
PLAN = (
    "feasible", "reason", "t_y_f", "t_y_switch", "t_x1", "t_x2", "min_gap_leader", "min_gap_follower", "ego_px",
    "ego_py", "ego_vx", "ego_vy", "l1_p", "l1_v", "l1_decel", "v_switch", "t_brake_end", "follows_leader", "y_acc_1",
    "y_acc_2", "t_y_end", "own_p", "own_v", "own_decel", "follows_own", "continues", "min_gap_own",
)  # fmt: skip
#: Per-row float state ``st``: the held plan's start, the assessment's first collaborative verdict, the breach's
#: first instant, the monitor's snapshot of F and the plan (F's position and speed, a responsible F's limit,
#: the plan's L1 deceleration), and the slow assessment's extra delay.
STATE_F = (
    "plan_t0", "first_collaborative_s", "first_breach_s", "snap_f_x", "snap_f_v", "snap_f_limit", "snap_l1_decel",
    "slow_delay_s",
)  # fmt: skip
#: Per-row flag state ``sk``: the plan's F type, the assessment's latch and belief, the lane change completed, the
#: snapshot's activity, the breach flags (``monitor.BREACH_KINDS``), then the slow assessment's miss and belief.
STATE_B = ("plan_f_aggr", "latched", "aggressive", "completed", "snap_active", "l1_decel", "leader_bound", "last_decel",
           "follower", "stale_v2x", "slow_missed", "slow_aggressive")  # fmt: skip
#: Per-row outputs ``of``: the commands, the proposal as checked, L1's worst case.
OUT_F = ("a_x", "a_y", "nominal_x", "nominal_y", "l1_decel")
#: Per-row output flags ``ob``: completing, invalid, F assumed aggressive, the chain unsafe, the command is the held
#: plan's motion (an abort under the paper's rule; an RSS response is a constant command).
OUT_B = ("completing", "invalid", "f_aggressive", "unsafe", "on_plan")

_PF = {name: j for j, name in enumerate(PLAN)}
_P_FEAS, _P_REASON, _P_TX2, _P_GAPL, _P_GAPF, _P_FOLLOWS = (
    _PF[n] for n in ("feasible", "reason", "t_x2", "min_gap_leader", "min_gap_follower", "follows_leader")
)
_P_OWN = _PF["own_p"]
#: EvasionPlan's values without an own-lane leader: own_p, own_v, own_decel, follows_own, continues, min_gap_own.
_OWN_DEFAULTS = np.array([np.inf, 0.0, 0.0, 0.0, 0.0, np.inf])
assert PLAN[_P_OWN:] == ("own_p", "own_v", "own_decel", "follows_own", "continues", "min_gap_own")
_PF_EGO_PX, _PF_EGO_PY, _PF_EGO_VX, _PF_EGO_VY, _PF_L1P, _PF_L1V, _PF_L1D = (
    _PF[n] for n in ("ego_px", "ego_py", "ego_vx", "ego_vy", "l1_p", "l1_v", "l1_decel")
)
_PF_TX1, _PF_VSW, _PF_TBE, _PF_TYF, _PF_TYS, _PF_YA1, _PF_YA2, _PF_TYE = (
    _PF[n] for n in ("t_x1", "v_switch", "t_brake_end", "t_y_f", "t_y_switch", "y_acc_1", "y_acc_2", "t_y_end")
)
_P_FOLLOWS_OWN, _P_CONT, _P_GAP_OWN = _PF["follows_own"], _PF["continues"], _PF["min_gap_own"]
#: The plan columns of the predicted state and L1 (``ego_px`` … ``l1_decel``), then the rest of the profile.
_HELD = np.array([_PF[n] for n in ("ego_px", "ego_py", "ego_vx", "ego_vy", "l1_p", "l1_v", "l1_decel", "t_x1",
                                   "v_switch", "t_brake_end", "t_y_f", "t_y_switch", "y_acc_1", "y_acc_2",
                                   "t_y_end")])  # fmt: skip
#: The evasion's float parts (``_fast.FLOAT_PARTS``, as :func:`._fast_decide._candidate` returns them) into the plan.
_PARTS = np.array([_PF[n] for n in ("t_y_f", "t_y_switch", "y_acc_1", "y_acc_2", "t_y_end", "t_x1", "v_switch",
                                    "t_brake_end")])  # fmt: skip


@numba.njit(inline="always")
def _own_decel(own_x, own_v, own_promise, nc, r, p_m, a_o, sense):
    """``realworld.chain_bounds`` of row ``r``'s own-lane chain (``L0`` first; no human margins), each link at its
    own corner of the sensing box (``sense``'s ``err_own``; exact states without one): ``(L0's bound, unsafe)``; an
    empty slot pair (``+inf`` positions) leaves the link free."""
    a_ahead = a_o
    unsafe = False
    for i in range(own_x.shape[1] - 2, -1, -1):
        promise = own_promise[r, i] if i < nc else a_o
        a_ahead, broken = link_at_corner(SCALAR, own_x[r, i], own_v[r, i], _own_err(sense, r, i, 0),
                                         _own_err(sense, r, i, 1), own_x[r, i + 1], own_v[r, i + 1],
                                         _own_err(sense, r, i + 1, 0), _own_err(sense, r, i + 1, 1), p_m, a_ahead,
                                         promise, a_o)  # fmt: skip
        unsafe = unsafe or broken
    return a_ahead, unsafe


@numba.njit(inline="always")
def _held_motion(plan, r, age, dt, a_a, a_d, kt, kx, kv, ky, kvy):
    """``decide.plan_motion`` of row ``r`` of the held plan (:data:`PLAN` columns; with an own-lane leader too: the
    profile follows ``L0`` where ``follows_own`` and goes on after ``t_y_f`` where it ``continues``): the 8 knots into
    ``kt``, the samples into ``kx, kv, ky, kvy``."""
    held = PlanRecord(plan[r, _PF_EGO_PX], plan[r, _PF_EGO_PY], plan[r, _PF_EGO_VX], plan[r, _PF_EGO_VY],
                      plan[r, _PF_TX1], plan[r, _PF_VSW], plan[r, _PF_TBE], plan[r, _P_FOLLOWS] > 0.0,
                      plan[r, _PF_TYF], plan[r, _PF_TYS], plan[r, _PF_YA1], plan[r, _PF_YA2], plan[r, _PF_TYE],
                      plan[r, _P_CONT] > 0.0)  # fmt: skip
    if plan[r, _P_FOLLOWS_OWN] > 0.0:
        lead_p, lead_v, lead_decel = plan[r, _P_OWN], plan[r, _P_OWN + 1], plan[r, _P_OWN + 2]
    else:
        lead_p, lead_v, lead_decel = plan[r, _PF_L1P], plan[r, _PF_L1V], plan[r, _PF_L1D]
    plan_knots(held, lead_p, lead_v, lead_decel, age, dt, a_a, a_d, kt, kx, kv, ky, kvy)


@numba.njit(inline="always")
def plan_knots(held, lead_p, lead_v, lead_decel, age, dt, a_a, a_d, kt, kx, kv, ky, kvy):
    """``decide.plan_motion`` of one held plan (a :class:`~safelane.safety.plan.PlanRecord`, the profile following
    ``(lead_p, lead_v, lead_decel)``) on ``[age, age + dt]``: the period's ends and the plan's switches inside it
    (:func:`~.decide.plan_switches`), sorted, into ``kt``, the plan's state at each
    (:func:`~safelane.safety.plan.plan_state`) into ``kx, kv, ky, kvy``. The shield's period and the closed loop's
    held plan (``sim/_fast_held.py``) both call it."""
    switches = plan_switches(SCALAR, held, lead_v, lead_decel, age, dt)
    kt[0] = 0.0
    for j in range(6):
        kt[j + 1] = switches[j]
    kt[7] = dt
    sort_short(kt)
    lim = Limits(a_a, a_d, 0.0, 0.0)
    for j in range(8):
        kx[j], ky[j], kv[j], kvy[j] = plan_state(SCALAR, held, age + kt[j], lead_p, lead_v, lead_decel, lim)


@row_function
def monitor_row(b, t, dt, mon_tol, now, snap_x, snap_v, snap_bounds, snap_nc, st, sk):
    """The monitor's comparison of the last period for row ``b`` (:func:`~.monitor.observe_breaches`): ``now``
    ``(., M + 1)`` the chain as seen now with F in slot 0 (row 0), the snapshot's chain ``snap_*`` (row ``b``); the
    breach flags and first instant into ``sk``, ``st``."""
    same = snap_x.shape[1] == now.shape[1] - 1
    f0, f1, f2, f3 = _breach_row(snap_x, snap_v, snap_bounds, b, now, 0, 1, snap_nc[b], st[b, 6], st[b, 3], st[b, 4],
                                 st[b, 5], sk[b, 4], now[0, 0], same, dt, mon_tol)  # fmt: skip
    new = (f0 and not sk[b, 5]) or (f1 and not sk[b, 6]) or (f2 and not sk[b, 7]) or (f3 and not sk[b, 8])
    if st[b, 2] != st[b, 2] and new:
        st[b, 2] = t
    sk[b, 5], sk[b, 6], sk[b, 7], sk[b, 8] = sk[b, 5] or f0, sk[b, 6] or f1, sk[b, 7] or f2, sk[b, 8] or f3


#: The held anchor's per-row floats (:class:`~.monitor.Anchor`'s fields; :class:`.fast_step.Packed` packs them).
ANCHOR_F = ("t", "f_t", "own_t", "l1_decel", "f_x", "f_v", "f_accel", "own_x", "own_v", "own_decel")
#: The entries of :func:`period_row`'s ``sense`` tuple (:func:`.fast_step.sense_arrays` builds it): the sensing box
#: (``err_f (B, 2)``, ``err_chain (B, M, 2)``, ``err_own (B, K, 2)``, zeros where the situation bounds nothing;
#: no rows: no box), its modes (a box, the chain's errors bounded, the own lane analysed), the chain at the
#: analysis' corner (written: the snapshot), the held anchor (:data:`ANCHOR_F`, chain, bounds, number connected; no
#: rows: none) and the new one (written; no rows: none made).
SENSE = ("err_f", "err_chain", "err_own", "modes", "corner_x", "corner_v", "anchor_f", "anchor_x", "anchor_v",
         "anchor_b", "anchor_nc", "new_f", "new_x", "new_v", "new_b", "new_nc")  # fmt: skip


@row_function
def _own_boxed(sense):
    """A sensing box and an own lane analysed (``stages.own_leader`` is not ``None``)."""
    if sense is None:
        return False
    return sense[3][0] and sense[3][2]


@row_function
def _own_err(sense, r, i, j):
    """The own lane's sensing bound ``err_own[r, i, j]`` (0 without a box)."""
    if sense is None:
        return 0.0
    if not sense[3][0]:
        return 0.0
    return sense[2][r, i, j]


@row_function
def _chain_box(sense, chain_x, chain_v, link_promise, link_margin, b, a_o, b2):
    """``(done, unsafe)``: row ``b``'s chain analysis with each link at its own corner of the sensing box
    (:func:`~.realworld.chain_bounds`, what :func:`~.stages.chain_analysis` runs where the chain's errors are
    bounded), its bounds into ``b2`` as ``_chain_row`` writes them; ``done`` false where the chain's states are
    exact (the caller's ``_chain_row``)."""
    if sense is None:
        return False, False
    if not (sense[3][0] and sense[3][1]):
        return False, False
    err = sense[1]
    m = chain_x.shape[1]
    a_ahead = a_o
    unsafe = False
    b2[0, 0] = a_o
    b2[0, m] = a_o
    for i in range(m - 2, -1, -1):
        a_ahead, broken = link_at_corner(SCALAR, chain_x[b, i], chain_v[b, i], err[b, i, 0], err[b, i, 1],
                                         chain_x[b, i + 1], chain_v[b, i + 1], err[b, i + 1, 0], err[b, i + 1, 1],
                                         link_margin[i, b], a_ahead, link_promise[i, b], a_o)  # fmt: skip
        unsafe = unsafe or broken
        b2[0, i + 1] = a_ahead
    return True, unsafe


@row_function
def _corners(sense, b, chain_x, chain_v, own_x, own_v, fx, fv, x2):
    """Row ``b`` at the sensing box's corners (:func:`~.realworld.worst_corners`): ``(fx, fv, fx_o, fv_o, l1x, l1v,
    l0x, l0v, l0x_o)`` — F, L1 and L0 at the analysis' corner (leaders behind and slower, F ahead and faster), then
    F and L0 at the observed one (the opposite, what the monitor compares with). The chain at the analysis' corner
    into ``sense``'s snapshot arrays, its observed positions into ``x2``'s slots from 1 and F's into slot 0. Without
    a box: the states as measured, ``x2`` untouched."""
    if sense is None:
        return fx, fv, fx, fv, chain_x[b, 0], chain_v[b, 0], own_x[b, 0], own_v[b, 0], own_x[b, 0]
    if not sense[3][0]:
        return fx, fv, fx, fv, chain_x[b, 0], chain_v[b, 0], own_x[b, 0], own_v[b, 0], own_x[b, 0]
    ef, ec, eo, cx, cv = sense[0], sense[1], sense[2], sense[4], sense[5]
    for i in range(chain_x.shape[1]):
        cx[b, i], cv[b, i] = behind_corner(SCALAR, chain_x[b, i], chain_v[b, i], ec[b, i, 0], ec[b, i, 1])
        x2[0, i + 1] = ahead_corner(SCALAR, chain_x[b, i], chain_v[b, i], ec[b, i, 0], ec[b, i, 1])[0]
    fxa, fva = ahead_corner(SCALAR, fx, fv, ef[b, 0], ef[b, 1])
    fxo, fvo = behind_corner(SCALAR, fx, fv, ef[b, 0], ef[b, 1])
    x2[0, 0] = fxo
    l0x, l0v = behind_corner(SCALAR, own_x[b, 0], own_v[b, 0], eo[b, 0, 0], eo[b, 0, 1])
    l0x_o = ahead_corner(SCALAR, own_x[b, 0], own_v[b, 0], eo[b, 0, 0], eo[b, 0, 1])[0]
    return fxa, fva, fxo, fvo, cx[b, 0], cv[b, 0], l0x, l0v, l0x_o


@row_function
def _anchor_check(sense, b, t, tol, now, now_own_x, st, sk):
    """The monitor's cumulative comparison of row ``b`` (:func:`~.monitor.anchor_flags`, recorded as
    ``observe_breaches`` records it, before the period's own comparison) with the held anchor, where there is one:
    ``now`` ``(1, M + 1)`` the observation (F in slot 0), ``now_own_x`` L0's (``+inf``: none)."""
    if sense is None:
        return
    af, ax, av, ab, anc = sense[6], sense[7], sense[8], sense[9], sense[10]
    if af.shape[0] == 0 or not sk[b, 4]:
        return
    same = ax.shape[1] == now.shape[1] - 1
    f0, f1, f2, f3 = anchor_row(ax, av, ab, b, now, 0, 1, af[b, 3], anc[b], af[b, 4], af[b, 5], af[b, 6], now[0, 0],
                                af[b, 7], af[b, 8], af[b, 9], now_own_x, SCALAR.maximum(t - af[b, 0], 0.0),
                                SCALAR.maximum(t - af[b, 1], 0.0), SCALAR.maximum(t - af[b, 2], 0.0), same,
                                tol)  # fmt: skip
    new = (f0 and not sk[b, 5]) or (f1 and not sk[b, 6]) or (f2 and not sk[b, 7]) or (f3 and not sk[b, 8])
    if st[b, 2] != st[b, 2] and new:
        st[b, 2] = t
    sk[b, 5], sk[b, 6], sk[b, 7], sk[b, 8] = sk[b, 5] or f0, sk[b, 6] or f1, sk[b, 7] or f2, sk[b, 8] or f3


@row_function
def _anchor_remember(sense, b, t, a_a, nc, bounds, fx, fv, l0x, l0v, l0_decel, st, sk):
    """Row ``b``'s anchor for the next period (``stages.remember``: this period's worst case at the analysis' corner,
    carried from the held anchor by :meth:`~.monitor.Anchor.carried`'s rule) into ``sense``'s new anchor, where
    one is made; ``st``, ``sk`` after the period (the plan's L1 deceleration and F type)."""
    if sense is None:
        return
    nf, nx, nv, nb, nnc = sense[11], sense[12], sense[13], sense[14], sense[15]
    if nf.shape[0] == 0:
        return
    cx, cv = sense[4], sense[5]
    hf, hx, hv, hb, hnc = sense[6], sense[7], sense[8], sense[9], sense[10]
    f_accel = a_a if sk[b, 0] else _INF
    if not sense[3][2]:  # no own lane analysed (stages.worst_case's own is None)
        l0x, l0v, l0_decel = _INF, 0.0, 0.0
    nnc[b] = nc
    if hf.shape[0] > 0 and hx.shape[1] == cx.shape[1]:
        renew, renew_f, renew_own = anchor_renewal(SCALAR, hnc[b], nc, hf[b, 6], f_accel, hf[b, 7])
        nf[b, 0] = anchor_carry(SCALAR, renew, hf[b, 0], t, False)
        nf[b, 1] = anchor_carry(SCALAR, renew_f, hf[b, 1], t, False)
        nf[b, 2] = anchor_carry(SCALAR, renew_own, hf[b, 2], t, False)
        nf[b, 3] = anchor_carry(SCALAR, renew, hf[b, 3], st[b, 6], True)
        nf[b, 4] = anchor_carry(SCALAR, renew_f, hf[b, 4], fx, False)
        nf[b, 5] = anchor_carry(SCALAR, renew_f, hf[b, 5], fv, False)
        nf[b, 7] = anchor_carry(SCALAR, renew_own, hf[b, 7], l0x, False)
        nf[b, 8] = anchor_carry(SCALAR, renew_own, hf[b, 8], l0v, False)
        nf[b, 9] = anchor_carry(SCALAR, renew_own, hf[b, 9], l0_decel, True)
        for i in range(cx.shape[1]):
            nx[b, i] = anchor_carry(SCALAR, renew, hx[b, i], cx[b, i], False)
            nv[b, i] = anchor_carry(SCALAR, renew, hv[b, i], cv[b, i], False)
            nb[b, i] = anchor_carry(SCALAR, renew, hb[b, i], bounds[b, i], True)
    else:
        nf[b, 0], nf[b, 1], nf[b, 2], nf[b, 3], nf[b, 4], nf[b, 5] = t, t, t, st[b, 6], fx, fv
        nf[b, 7], nf[b, 8], nf[b, 9] = l0x, l0v, l0_decel
        for i in range(cx.shape[1]):
            nx[b, i], nv[b, i], nb[b, i] = cx[b, i], cv[b, i], bounds[b, i]
    nf[b, 6] = f_accel


@row_function
def observe_row(b, t, dt, mon_tol, chain_x, chain_v, own_x, own_v, fx, fv, x2, snap_x, snap_v, snap_bounds, snap_nc,
                st, sk, sense=None):  # fmt: skip
    """:func:`~.core.observe` of row ``b``: the monitor's view of the last period without deciding (after a run's
    last period) — the observation (the chain ``chain_x``, ``chain_v``, F's ``(fx, fv)``, L0 in ``own_x``,
    ``own_v``) at the sensing box's observed corner into ``x2`` (F in slot 0; as seen without a box), the
    comparison with the held anchor, then the period's (:func:`monitor_row`), as :func:`period_row` compares."""
    x2[0, 0] = fx
    for i in range(chain_x.shape[1]):
        x2[0, i + 1] = chain_x[b, i]
    l0x_o = _corners(sense, b, chain_x, chain_v, own_x, own_v, fx, fv, x2)[8]
    _anchor_check(sense, b, t, mon_tol, x2, l0x_o, st, sk)
    monitor_row(b, t, dt, mon_tol, x2, snap_x, snap_v, snap_bounds, snap_nc, st, sk)


@row_function
def period_row(b, prm, times, den, sf, sb, rule, chain_x, chain_v, link_promise, link_margin, own_x, own_v,
               own_promise, own_nc, history, count, st, sk, plan, has_last, snap_x, snap_v, snap_bounds, snap_nc,
               bounds, given_unsafe, of, ob, knots, x2, v2, b2, kn, sense=None):  # fmt: skip
    """One period of row ``b`` (the module docstring): the stages of :func:`~.core.step` in their order. Reads the
    situation (``sf``, ``sb``, the chain; ``rule``: the row's decision rule, :data:`._fast_rules.RULE` — one column
    of zeros for a batch under the paper's rule alone; ``link_promise``, ``link_margin`` ``(M − 1, .)``: each link's
    promise and margin, resolved as :func:`~.stages.chain_analysis` resolves them), updates the state in place
    (``history``, ``count``, ``st``, ``sk``, ``plan``; the snapshot ``snap_*`` of the last period is read, the
    caller keeps this one), writes ``bounds`` (or reads them, with ``given_unsafe``, where the caller's chain
    analysis is given: a non-empty ``given_unsafe``), ``of``, ``ob`` and, for an abort, the held plan's knots
    ``knots[b] (5, 8)`` (``t, px, vx, py, vy``; also left in the scratch ``kn``); returns the behaviour. Under an
    actuation delay (``prm``'s ``delay_s`` > 0) it decides from the frame of :func:`~.stages.frame`: the ego of
    ``sf``'s ``carried_*`` columns (the caller's :func:`carried_ego`), the others carried along their worst cases.
    ``times``,
    ``den``: the assessment's window; ``x2, v2, b2, kn``: scratch (``b2`` holds the chain's bounds with F's slot
    after the call); ``sense``: the sensing box and the monitor's anchors (:data:`SENSE`; ``None``: neither)."""
    t, dt, a_a, a_d, a_ym, y_safe, p_m, _, y_bound, lane_w, a_o, lat_tol, tol, mon_tol, thr, mon = prm[:16]
    own_level, own_margin = prm[16], prm[17]
    paper = prm[19] > 0.0  # ShieldConfig.completion == "paper_evasion" (else "commit_guard")
    lim = Limits(a_a, a_d, a_ym, y_safe)
    window = times.shape[0]
    kt, kx, kv, ky, kvy = kn[0], kn[1], kn[2], kn[3], kn[4]
    ex, ey, evx, evy, fx, fv = sf[b, 0], sf[b, 1], sf[b, 2], sf[b, 3], sf[b, 4], sf[b, 5]
    # --- observe: the assessment's observation (assessment.update) ---
    for j in range(window - 1):
        history[b, j] = history[b, j + 1]
    history[b, window - 1] = sf[b, 6]
    count[b] += 1
    num = history[b, 0] * times[0]
    for j in range(1, window):
        num = num + history[b, j] * times[j]
    sk[b, 1], sk[b, 2] = belief_core(SCALAR, num / den, count[b] >= window, sk[b, 1], sk[b, 2], thr)
    if st[b, 1] != st[b, 1] and not sk[b, 2]:
        st[b, 1] = t
    if prm[20] > 0.0:  # the 'slow' assessment (policies.SlowAssessment): its draws at F's first observation
        if count[b] == 1:
            key_x, key_v = fx - ex, sf[b, 6]
            st[b, 7], sk[b, 10] = slow_draws(SCALAR, key_x, key_v, prm[21], prm[22], float_bits(key_x),
                                             float_bits(key_v))  # fmt: skip
        sk[b, 11] = slow_belief(SCALAR, t, st[b, 1], st[b, 7], prm[23], sk[b, 2], sk[b, 10])
    # --- the chain analysis (stages.chain_analysis), F in slot 0 ---
    m = chain_x.shape[1]
    x2[0, 0], v2[0, 0] = fx, fv
    for i in range(m):
        x2[0, i + 1], v2[0, i + 1] = chain_x[b, i], chain_v[b, i]
    if given_unsafe.shape[0] > 0:  # the caller's analysis of this very situation, taken as given (core.step's chain)
        unsafe = given_unsafe[b]
        b2[0, 0] = a_o
        for i in range(m):
            b2[0, i + 1] = bounds[b, i]
    else:
        done, unsafe = _chain_box(sense, chain_x, chain_v, link_promise, link_margin, b, a_o, b2)
        if not done:
            unsafe = _chain_row(x2, v2, 0, link_promise, link_margin, b, a_o, b2)
        for i in range(m):
            bounds[b, i] = b2[0, i + 1]
    # --- the sensing box's corners (realworld.worst_corners): x2 becomes the observation the monitor compares ---
    fx, fv, fx_o, fv_o, l1x, l1v, l0x_a, l0v_a, l0x_o = _corners(sense, b, chain_x, chain_v, own_x, own_v, fx, fv, x2)
    # --- the monitor's comparison of the last period (monitor.observe_breaches) ---
    if has_last:
        _anchor_check(sense, b, t, mon_tol, x2, l0x_o, st, sk)
        monitor_row(b, t, dt, mon_tol, x2, snap_x, snap_v, snap_bounds, snap_nc, st, sk)
    # --- worst case (stages.worst_case) ---
    broken = sk[b, 5] or sk[b, 6] or sk[b, 7] or sk[b, 8] or sk[b, 9]
    broken = broken and mon > 0.0  # ShieldConfig.monitor
    trusted = sb[b, 3] and sb[b, 0]
    # the observed belief, the slow one's, or (the 'truth' assessment) F's type
    assessed = sk[b, 11] if prm[20] > 0.0 else (sk[b, 2] if prm[18] == 0.0 else sb[b, 5])
    l1_decel, f_aggr = worst_case_core(SCALAR, sb[b, 2], unsafe, b2[0, 1], a_o, trusted, sb[b, 4], assessed,
                                       broken)  # fmt: skip
    l0x, l0v, l0_decel = own_x[b, 0], own_v[b, 0], a_o  # (stages.own_leader; +inf: no L0)
    has_l0 = l0x < _INF
    if has_l0 or _own_boxed(sense):  # (with a box, the anchor holds every row's L0 bound)
        bound0, unsafe0 = _own_decel(own_x, own_v, own_promise, own_nc[b], b, p_m, a_o, sense)
        if sb[b, 2] and not unsafe0 and not broken:
            l0_decel = bound0
    l0x, l0v = l0x_a, l0v_a  # (the analysis' corner)
    # --- frame (stages.frame): with an actuation delay, the states once the commands in flight have acted ---
    delay = prm[_PRM_DELAY]
    ex0, evx0, fx0, fv0 = ex, evx, fx, fv  # (the period's start: what stages.remember keeps)
    if delay > 0.0:
        c = _SF_CARRIED
        ex, ey, evx, evy = sf[b, c], sf[b, c + 1], sf[b, c + 2], sf[b, c + 3]
        l1x, l1v, fx, fv = carried_others(SCALAR, l1x, l1v, l1_decel, fx, fv, f_aggr, a_a, a_d, delay)
        if has_l0:
            l0x, l0v = carry_worst_core(SCALAR, l0x, l0v, l0_decel, delay)
    # --- the proposal (stages.proposal) ---
    ok, ax_ok, ay_ok = proposal_core(SCALAR, sf[b, 7], sf[b, 8], lim)
    invalid = not ok
    a_x, a_y = _clip(ax_ok, -a_d, a_a), _clip(ay_ok, -a_ym, a_ym)
    # --- decide: proceed / hesitate / abort with the commit guard (stages.decide, decide.verdict_of) ---
    a_yh = hesitate_core(SCALAR, evy, dt, a_ym)
    active = not sk[b, 3]
    code_b = COMPLETED
    completing = False
    ruled = rule.shape[1] > 1 and rule[b, 0] > 0.0  # RSS decides this row (stages.decide's other rules)
    ax_rule = ay_rule = 0.0
    if ruled:
        code_b, ax_rule, ay_rule, completing = rule_row(
            rule, b, (ex, ey, evx, evy), chain_x, chain_v, (fx, fv), bounds, sf[b, 9], (a_x, a_y, a_yh,
            lane_keep_accel(SCALAR, ey, evy, lane_w, a_ym)), invalid, l1_decel, sb[b, 2] and not unsafe, sk[b, 3],
            (l0x, l0v), (dt, lane_w, prm[24], prm[25], a_d, a_ym, y_bound),
        )  # fmt: skip
        if code_b == PROCEED or code_b == HESITATE:  # (stages.remember: the plan's start moves, the plan stays)
            st[b, 0] = t + delay + dt
    elif active:
        code_b = ABORT
        for code in range(2):
            if code == 0 and invalid:
                continue
            lateral = a_y if code == 0 else a_yh
            if has_l0:  # decide._with_own: the candidate with L0 (_fast_own.check_kernel's row)
                state, period_ok, crossing = candidate_period(
                    SCALAR, ex, ey, evx, evy, a_x, lateral, l1x, l1v, l1_decel, fx, fv,
                    f_aggr, lim, p_m, dt, own_level, lat_tol, tol,
                )  # fmt: skip
                period_ok, crossing, ox, ov = own_period(SCALAR, ex, evx, a_x, l0x, l0v, l0_decel, period_ok,
                                                         crossing, state[3], p_m, dt, tol)  # fmt: skip
                of_, bits = _own_lane(state[0], state[1], state[2], state[3], state[4], state[5], l1_decel,
                                      state[6], state[7], f_aggr, ox, ov, l0_decel, p_m, p_m, own_margin, lim,
                                      tol)  # fmt: skip
                # as _candidate's: the plan's float parts (FLOAT_PARTS), then (exists, lead_ok, follow_ok,
                # nothing, follows_leader)
                parts = (of_[6], of_[7], of_[8], of_[9], of_[10], of_[0], of_[1], of_[2], of_[3], of_[4])
                bits = (bits[0], bits[1], bits[2], bits[4], bits[3], bits[5])
                own_gap = of_[5]
            else:
                state, period_ok, crossing, parts, bits5 = _candidate(
                    ex, ey, evx, evy, a_x, lateral, l1x, l1v, l1_decel, fx, fv, f_aggr, a_a,
                    a_d, a_ym, y_safe, p_m, dt, y_bound, lat_tol, tol,
                )  # fmt: skip
                bits = (bits5[0], bits5[1], bits5[2], bits5[3], bits5[4], False)
                ox = ov = own_gap = 0.0
            if crossing and paper:  # the completion rule paper_evasion: the evasion check decides this step too
                keep = period_ok and bits[0]
            elif crossing:  # commit_guard
                keep = period_ok and commit_guard_core(SCALAR, state[0], state[2], state[4], state[5], l1_decel,
                                                       state[6], state[7], p_m, a_d, tol)  # fmt: skip
            else:
                keep = period_ok and bits[0]
            if keep:  # the plan from the predicted state (safety.plan.plan_from_core)
                code_b = PROCEED if code == 0 else HESITATE
                completing = crossing
                plan[b, _P_FEAS] = 1.0 if bits[0] else 0.0
                plan[b, _P_REASON] = plan_reason(SCALAR, bits[1], bits[2], bits[3])
                for j in range(8):
                    plan[b, _PARTS[j]] = parts[j]
                plan[b, _P_TX2] = SCALAR.minimum(parts[7], parts[0])
                plan[b, _P_GAPL] = parts[8] + p_m
                plan[b, _P_GAPF] = parts[9] + p_m
                for j in range(6):
                    plan[b, _HELD[j]] = state[j]
                plan[b, _HELD[6]] = l1_decel
                plan[b, _P_FOLLOWS] = 1.0 if bits[4] else 0.0
                if has_l0:  # (plan_from_core's own-lane fields)
                    plan[b, _P_OWN], plan[b, _P_OWN + 1], plan[b, _P_OWN + 2] = ox, ov, l0_decel
                    plan[b, _P_FOLLOWS_OWN] = 1.0 if bits[5] else 0.0
                    plan[b, _P_CONT] = 1.0
                    plan[b, _P_GAP_OWN] = own_gap + own_margin
                else:
                    for j in range(6):  # no own-lane leader: EvasionPlan's defaults
                        plan[b, _P_OWN + j] = _OWN_DEFAULTS[j]
                sk[b, 0] = f_aggr
                st[b, 0] = t + delay + dt
                break
    # --- command (stages.command) ---
    ax_cmd = a_x
    ay_cmd = a_yh if code_b == HESITATE else a_y
    on_plan = code_b == ABORT and not ruled
    if ruled:
        ax_cmd, ay_cmd = ax_rule, ay_rule
    elif not active:  # after completion: centre in the target lane, follow L1 responsibly
        slack = l1x - ex - p_m
        ax_cmd = responsible_accel_core(SCALAR, a_x, _responsible_bound(slack, evx, l1v, l1_decel, a_d,
                                                                        dt), a_d)  # fmt: skip
        if l1_decel > a_d:
            if not responsible_ok_core(SCALAR, ax_cmd, slack, evx, l1v, l1_decel, a_d, dt, tol):
                ax_cmd = -a_d
        ay_cmd = lane_keep_accel(SCALAR, ey, evy, lane_w, a_ym)
    if on_plan:  # the held plan's exact motion over the period
        age = SCALAR.maximum(t + delay - st[b, 0], 0.0)
        _held_motion(plan, b, age, dt, a_a, a_d, kt, kx, kv, ky, kvy)
        for j in range(8):
            knots[b, 0, j], knots[b, 1, j], knots[b, 2, j] = kt[j], kx[j], kv[j]
            knots[b, 3, j], knots[b, 4, j] = ky[j], kvy[j]
        first = 0
        for j in range(7):
            if kt[j + 1] - kt[j] > 0.0:
                first = j
                break
        span = kt[first + 1] - kt[first]
        ax_cmd = (kv[first + 1] - kv[first]) / span
        ay_cmd = (kvy[first + 1] - kvy[first]) / span
    # --- remember: what a responsible F may do this period, for the monitor (stages.remember) ---
    limit = _INF
    if active and not sk[b, 0] and ex0 - fx0 > 0.0:
        limit = SCALAR.maximum(_responsible_bound(ex0 - fx_o - p_m, fv_o, evx0, a_d, a_o, dt), -a_o)
    st[b, 3], st[b, 4], st[b, 5], st[b, 6] = fx0, fv0, limit, plan[b, _HELD[6]]
    sk[b, 4] = active
    if active and sb[b, 1] and not sk[b, 9]:  # stages.with_stale
        sk[b, 9] = True
        if st[b, 2] != st[b, 2]:
            st[b, 2] = t
    _anchor_remember(sense, b, t, a_a, int(sf[b, 9]), bounds, fx0, fv0, l0x_a, l0v_a, l0_decel, st, sk)
    completing = completing and active
    sk[b, 3] = sk[b, 3] or completing
    of[b, 0], of[b, 1], of[b, 2], of[b, 3], of[b, 4] = ax_cmd, ay_cmd, ax_ok, ay_ok, l1_decel
    ob[b, 0], ob[b, 1], ob[b, 2], ob[b, 3], ob[b, 4] = completing, invalid and active, f_aggr, unsafe, on_plan
    return code_b


@row_function
def carried_ego(b, dt, segs, q_knots, q_seg, q_acc, q_flag, ex, ey, evx, evy):
    """:meth:`~.command.InFlight.carry` of row ``b``: the ego ``(x, y, vx, vy)`` once the commands in flight have
    acted (the queue ``q_*``, oldest first, as :class:`.fast_step.Packed` holds it), segment by segment
    (:func:`~.command.segment_core`) as :meth:`~.command.Command.piece` lays a command out: ``segs[c]`` segments for
    command ``c`` (its knots less one where some row aborts, else 1), each by :func:`carried_command`."""
    for c in range(q_knots.shape[1]):
        ex, ey, evx, evy = carried_command(dt, segs[c], q_flag[b, c, 1], q_knots[b, c], q_seg[b, c, 0],
                                           q_seg[b, c, 1], q_acc[b, c, 0], q_acc[b, c, 1], ex, ey, evx,
                                           evy)  # fmt: skip
    return ex, ey, evx, evy


@row_function
def carried_command(dt, segs, aborts, knots, ax_seg, ay_seg, a_x, a_y, ex, ey, evx, evy):
    """:meth:`~.command.Command.carry` of one row's command: the ego ``(x, y, vx, vy)`` after ``segs`` segments
    (:func:`~.command.segment_core`) — an aborting row (``aborts``) follows its ``knots`` with their segments'
    accelerations ``ax_seg``, ``ay_seg``, another row its constant command ``(a_x, a_y)`` for ``dt``, then segments
    of length 0 (which leave the state's bits as they are). :func:`carried_ego` (the queue as :class:`.fast_step.Packed`
    holds it) calls it, for :func:`period_kernel` and the compiled closed loop (``sim/_fast_loop._period``: the
    world's commands in flight, kept in the same layout and pushed by :func:`push_row`)."""
    for k in range(segs):
        if aborts:
            h, ax, ay = knots[k + 1] - knots[k], ax_seg[k], ay_seg[k]
        else:
            h, ax, ay = dt if k == 0 else 0.0, a_x, a_y
        ex, ey, evx, evy = segment_core(SCALAR, ex, ey, evx, evy, h, ax, ay)
    return ex, ey, evx, evy


@row_function
def push_row(b, of, ob, knots, q_knots, q_seg, q_acc, q_flag):
    """:meth:`~.command.InFlight.push` of row ``b``'s command of this period (:meth:`~.command.Command.issued`: the
    accelerations ``of[b, :2]``, completing ``ob[b, 0]``, following the held plan ``ob[b, 4]`` over the knots
    ``knots[b]`` with their segments' accelerations, :func:`~safelane.sim.kinematics.piece_acc`): the oldest
    command, which acts now, leaves the queue ``q_*``; a row that does not abort has zero knots and segments.
    :func:`period_kernel` and the compiled closed loop (``sim/_fast_loop._period``, the world's queue) push with it."""
    d, s = q_knots.shape[1], q_seg.shape[3]
    if d == 0:
        return
    for c in range(d - 1):
        for j in range(s + 1):
            q_knots[b, c, j] = q_knots[b, c + 1, j]
        for j in range(s):
            q_seg[b, c, 0, j], q_seg[b, c, 1, j] = q_seg[b, c + 1, 0, j], q_seg[b, c + 1, 1, j]
        q_acc[b, c, 0], q_acc[b, c, 1] = q_acc[b, c + 1, 0], q_acc[b, c + 1, 1]
        q_flag[b, c, 0], q_flag[b, c, 1] = q_flag[b, c + 1, 0], q_flag[b, c + 1, 1]
    c = d - 1
    aborts = ob[b, 4]
    q_acc[b, c, 0], q_acc[b, c, 1] = of[b, 0], of[b, 1]
    q_flag[b, c, 0], q_flag[b, c, 1] = ob[b, 0], aborts
    for j in range(s + 1):
        q_knots[b, c, j] = knots[b, 0, j] if aborts else 0.0
    for j in range(s):
        if aborts:
            span = knots[b, 0, j + 1] - knots[b, 0, j]
            q_seg[b, c, 0, j] = piece_acc(SCALAR, knots[b, 2, j], knots[b, 2, j + 1], span)
            q_seg[b, c, 1, j] = piece_acc(SCALAR, knots[b, 4, j], knots[b, 4, j + 1], span)
        else:
            q_seg[b, c, 0, j], q_seg[b, c, 1, j] = 0.0, 0.0


@numba.njit(cache=True, nogil=True, error_model="numpy")
def period_kernel(prm, sf, sb, rule, chain_x, chain_v, chain_promise, chain_human, n_connected, own_x, own_v,
                  own_promise, own_nc, history, count, st, sk, plan, has_last, snap_x, snap_v, snap_bounds, snap_nc,
                  bounds, given_unsafe, behaviour, of, ob, knots, segs, q_knots, q_seg, q_acc, q_flag,
                  sense=None):  # fmt: skip
    """One period of every row: :func:`period_row` after resolving each link's promise and margin as
    :func:`~.stages.chain_analysis` does (the promise of a connected leader, else ``a_o_d``; ``p_m_human`` for a
    connected human-driven one, else ``p_m``). With commands in flight (``q_*``: ``(B, d, .)``, oldest first;
    ``segs (d,)`` each command's segments), the ego carried over them first (:func:`carried_ego`, into ``sf``'s
    ``carried_*`` columns) and this period's command pushed after (:func:`push_row`); ``sense``: :data:`SENSE`
    (omitted where there is neither a sensing box nor an anchor: a compiled version of its own, which pays nothing
    for them)."""
    dt, p_m, p_m_h, a_o = prm[1], prm[6], prm[7], prm[10]
    bsz, m = chain_x.shape
    window = history.shape[1]
    times = np.empty(window)
    for j in range(window):
        times[j] = (j - (window - 1) / 2.0) * dt
    den = times[0] * times[0]
    for j in range(1, window):
        den = den + times[j] * times[j]
    x2, v2, b2 = np.empty((1, m + 1)), np.empty((1, m + 1)), np.empty((1, m + 1))
    kn = np.empty((5, 8))
    link_promise, link_margin = np.empty((max(m - 1, 1), bsz)), np.empty((max(m - 1, 1), bsz))
    for b in range(bsz):
        for i in range(m - 1):
            connected = i < n_connected[b]
            link_promise[i, b] = chain_promise[b, i] if connected else a_o
            link_margin[i, b] = p_m_h if (chain_human[b, i] and connected) else p_m
    c = _SF_CARRIED
    for b in range(bsz):
        carried = carried_ego(b, dt, segs, q_knots, q_seg, q_acc, q_flag, sf[b, 0], sf[b, 1], sf[b, 2], sf[b, 3])
        sf[b, c], sf[b, c + 1], sf[b, c + 2], sf[b, c + 3] = carried
        behaviour[b] = period_row(b, prm, times, den, sf, sb, rule, chain_x, chain_v, link_promise, link_margin, own_x,
                                  own_v, own_promise, own_nc, history, count, st, sk, plan, has_last, snap_x, snap_v,
                                  snap_bounds, snap_nc, bounds, given_unsafe, of, ob, knots, x2, v2, b2,
                                  kn, sense)  # fmt: skip
        push_row(b, of, ob, knots, q_knots, q_seg, q_acc, q_flag)

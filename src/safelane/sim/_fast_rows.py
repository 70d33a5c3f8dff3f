"""The compiled closed loop's row layout (numba, extra ``fast``): a row's whole state between periods (:data:`Rows`)
and the scratch arrays of one row's period (:data:`Scratch`), with the moves between them — :func:`_load` a row into
the scratch, :func:`_store` it back — and the assessment's window (:func:`_window`). ``sim/_fast_loop.py``'s kernels
(the episode loop, one period, ``envs/_fast.py``'s step) run ``_fast_loop._period`` on this layout; nothing here
computes a rule."""

from __future__ import annotations

import collections

import numba
import numpy as np

from ..safety._fast_base import announce_compiles, row_function
from ..shield._fast_period import OUT_B, SIT_F

announce_compiles()

_INF = np.inf
#: A row's whole state between periods, one array per part with the batch first (the compiled loop's only state):
#: the target lane ``x``, ``v``, the last period's accelerations ``acc`` and the running minimum of the chain bounds
#: ``cap`` ``(B, K)``; the running values ``rf`` (:data:`RF`), ``rb`` (:data:`RB`), ``ri`` (:data:`RI`); the
#: shield's state as :func:`~safelane.shield._fast_period.period_row` holds it (``shield/fast_step.Packed``:
#: ``plan``, ``history``, ``count``, ``st``, ``sk``), the monitor's snapshot of the last period (``snap_*``) and the
#: actuation delay's commands in flight, oldest first, in the shield's layout (``shield/fast_step.Packed.queue``:
#: ``q_knots`` ``(B, D, 8)``, ``q_seg`` ``(B, D, 2, 7)``, ``q_acc`` ``(B, D, 2)``, ``q_flag`` ``(B, D, 2)``
#: completing, aborting; ``D = 0``: none; pushed by ``_fast_period.push_row``) — the shield's own where its delay is
#: the world's — and the monitor's cumulative anchor held with the shield's sensing on (``anc_f``
#: ``(B, len(ANCHOR_F))``, ``anc_x``, ``anc_v``, ``anc_b`` ``(B, M)``, ``anc_nc`` ``(B,)``: ``Packed.anchor``; held
#: where ``has_last``, made anew every period) — and the own lane (``sim/own_chain.py``, ``L0`` first: ``own_x``,
#: ``own_v`` and the running minimum of its chain bounds ``own_cap`` ``(B, K0)``, ``own_x = +inf``: no vehicle in that
#: slot; ``K0 = 1`` with ``L0`` alone or no own lane).
Rows = collections.namedtuple("Rows", (
    "x", "v", "acc", "cap", "rf", "rb", "ri", "plan", "history", "count", "st", "sk", "snap_x", "snap_v", "snap_b",
    "snap_nc", "q_knots", "q_seg", "q_acc", "q_flag", "anc_f", "anc_x", "anc_v", "anc_b", "anc_nc", "own_x", "own_v",
    "own_cap",
))  # fmt: skip
#: A row's running floats: the ego's state, the row's clock, the results' times and smallest gaps.
RF = ("ego_x", "ego_y", "ego_vx", "ego_vy", "t", "t_complete", "min_gap_f", "min_gap_l1", "min_lane_ratio",
      "min_gap_l0")  # fmt: skip
#: A row's running flags (``has_last``: the monitor has a snapshot of a last period; the ego's collisions and
#: ``p_m`` violations against ``L0``, also counted in ``collided``, ``violated``; the world's completion: the shield's
#: but under an actuation delay, where the command acting completes the lane change; the own lane's vehicles ran into
#: each other: ``SimState.own_pair_collided``, the traffic's own soundness).
RB = ("collided", "violated", "leader_collided", "leader_violated", "has_last", "l0_collided", "l0_violated",
      "completed", "own_pair_collided")  # fmt: skip
#: A row's counts: periods that proceeded, hesitated, aborted; invalid proposals; periods run (the draws' counter).
RI = ("proceed", "hesitate", "abort", "invalid", "step")
#: The scratch arrays of one row's period (:func:`_scratch`), by name (the row's commands in flight ``q_*`` as
#: :data:`Rows` holds them, ``(1, D, .)``, and ``segs`` ``(D,)`` each command's segments as the carry takes them).
Scratch = collections.namedtuple("Scratch", (
    "x2", "v2", "f_acc2", "f_ts2", "f_xe2", "f_ve2", "acc", "cap", "general2", "pp", "sf", "sb", "chain_x", "chain_v",
    "own_x", "own_v", "own_promise", "own_nc", "history", "count", "st", "sk", "plan", "snap_x", "snap_v", "snap_b",
    "snap_nc", "bounds_out", "no_chain", "of", "ob", "knots", "px2", "pv2", "pb2", "kn", "kax", "kay", "scratch",
    "lon_t", "lon_x", "lon_v", "lon_a", "lat_t", "lat_x", "lat_v", "lat_a", "o_t", "o_x", "o_v", "o_a", "lo", "hi",
    "times", "rf", "rb", "ri", "sw", "own", "q_knots", "q_seg", "q_acc", "q_flag", "segs", "sense",
))  # fmt: skip
#: The scratch of the shield's sensing box in a period (``Scratch.sense``, ``None`` with its sensing off;
#: ``_fast_loop._sense`` builds
#: ``period_row``'s ``sense`` tuple from it, :data:`~safelane.shield._fast_period.SENSE`): its modes, zero bounds for
#: an own lane not analysed (``err_own0`` ``(1, 1, 2)``), the chain at the analysis' corner (``corner_x``,
#: ``corner_v``), the held anchor (``anc_*``, the row's) and the new one (``new_*``), each ``(1, .)``.
Sense = collections.namedtuple("Sense", (
    "modes", "err_own0", "corner_x", "corner_v", "anc_f", "anc_x", "anc_v", "anc_b", "anc_nc", "new_f", "new_x",
    "new_v", "new_b", "new_nc",
))  # fmt: skip
#: The scratch of a period in which ``L(N+1)``'s profile switches (``Scratch.sw``): the row's ``valid`` and lane
#: pairs without that vehicle (the checks' rows skip it; ``_fast_loop._period`` checks its pairs on its two segments),
#: its motion's knots (``t``, ``x``, ``v``, ``a``: 5, 5, 5, 4) and a lateral motion above the level all period (for the
#: general path's gap over two motions, unwindowed).
Switched = collections.namedtuple("Switched", (
    "valid", "lane_valid", "lane_margin", "t", "x", "v", "a", "lat_t", "lat_x", "lat_v", "lat_a",
))  # fmt: skip
#: The scratch of the own lane in a period (``Scratch.own``; ``sim/_fast_world.py``), ``K0`` slots, ``L0`` first: the
#: row's state (``x``, ``v``, ``cap``: :data:`Rows`' ``own_*``, ``(1, K0)``), each slot's acceleration this period
#: (``want`` ``(K0,)``), its motion as :class:`~.kinematics.Fleet` holds it (``fx``, ``fv``: the start, an empty slot
#: at 0; ``acc``, ``ts``, ``xe``, ``ve``: the first segment as ``constant_segment`` gives it; ``(1, K0)``), the chain
#: scan's lane laid out as the target lane (``lane_x``, ``lane_v``, its bounds ``lane_b`` ``(1, K0 + 1)``; its links'
#: ``promise`` and ``margin`` ``(K0 − 1, 1)``), the head's switch (``sw``: :data:`Switched`, its knots and, in
#: ``lane_valid``/``lane_margin``, the pairs the lane checks take) and the ego's lateral motion mirrored (``lat_*``:
#: up to the held plan's 8 knots).
Own = collections.namedtuple("Own", (
    "x", "v", "cap", "want", "fx", "fv", "acc", "ts", "xe", "ve", "lane_x", "lane_v", "lane_b", "promise", "margin",
    "sw", "lat_t", "lat_x", "lat_v", "lat_a",
))  # fmt: skip


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _scratch(rows, period_prm, sense):
    """The scratch arrays of one row's period, allocated once per call of a kernel: the rows then run without
    reference counting (every array a period touches would otherwise cost atomic increments and decrements).
    ``sense``: the sensing box's scratch (:data:`Sense`, ``_fused.sense_scratch``), or ``None`` where the shield's
    sensing is off (the kernel is then compiled without the box, ``period_row``'s ``sense=None``: nothing to pay)."""
    k = rows.x.shape[1]
    m = k - 1
    k0 = rows.own_x.shape[1]  # own-lane slots
    window = rows.history.shape[1]
    d = rows.q_knots.shape[1]  # commands in flight
    return Scratch(
        np.empty((1, k)), np.empty((1, k)), np.empty((1, k)), np.empty((1, k)), np.empty((1, k)), np.empty((1, k)),
        np.empty(k), np.empty(k), np.zeros((1, k), np.bool_), period_prm.copy(), np.empty((1, len(SIT_F))),
        np.zeros((1, 6), np.bool_), np.empty((1, m)), np.empty((1, m)), np.full((1, k0), _INF), np.zeros((1, k0)),
        np.zeros((1, k0 - 1)), np.zeros(1, np.int64), np.empty((1, window)), np.empty(1, np.int64),
        np.empty((1, rows.st.shape[1])), np.empty((1, rows.sk.shape[1]), np.bool_),
        np.empty((1, rows.plan.shape[1])), np.empty((1, m)), np.empty((1, m)), np.empty((1, m)), np.empty(1, np.int64),
        np.empty((1, m)), np.zeros(0, np.bool_), np.empty((1, 5)), np.empty((1, len(OUT_B)), np.bool_),
        np.empty((1, 5, 8)),
        np.empty((1, m + 1)), np.empty((1, m + 1)), np.empty((1, m + 1)), np.empty((5, 8)), np.empty(7), np.empty(7),
        np.empty(64), np.empty(3), np.empty(3), np.empty(3), np.empty(2), np.empty(2), np.empty(2), np.empty(2),
        np.empty(1), np.empty(3), np.empty(3), np.empty(3), np.empty(2), np.empty(2), np.empty(2), np.empty(window),
        np.empty((1, len(RF))), np.empty((1, len(RB)), np.bool_), np.empty((1, len(RI)), np.int64),
        Switched(np.empty((1, k), np.bool_), np.empty((1, m), np.bool_), np.empty((1, m)), np.empty(5), np.empty(5),
                 np.empty(5), np.empty(4), np.zeros(2), np.ones(2), np.zeros(2), np.zeros(1)),
        Own(np.full((1, k0), _INF), np.zeros((1, k0)), np.full((1, k0), _INF), np.zeros(k0), np.empty((1, k0)),
            np.empty((1, k0)), np.empty((1, k0)), np.empty((1, k0)), np.empty((1, k0)), np.empty((1, k0)),
            np.empty((1, k0 + 1)), np.empty((1, k0 + 1)), np.empty((1, k0 + 1)), np.empty((k0 - 1, 1)),
            np.empty((k0 - 1, 1)),
            Switched(np.empty((1, k0), np.bool_), np.empty((1, k0 - 1), np.bool_), np.empty((1, k0 - 1)),
                     np.empty(5), np.empty(5), np.empty(5), np.empty(4), np.zeros(2), np.ones(2), np.zeros(2),
                     np.zeros(1)),
            np.empty(8), np.empty(8), np.empty(8), np.empty(7)),
        np.empty((1, d, rows.q_knots.shape[2])), np.empty((1, d, 2, rows.q_seg.shape[3])), np.empty((1, d, 2)),
        np.empty((1, d, 2), np.bool_), np.empty(d, np.int64),
        sense,
    )  # fmt: skip


@row_function
def _load(rows, b, batch, w):
    """Row ``b`` of ``rows`` into the scratch ``w`` (and the row's situation flags from ``batch``)."""
    x2, v2, acc, cap, sb, rf, rb, ri = w.x2, w.v2, w.acc, w.cap, w.sb, w.rf, w.rb, w.ri
    history, count, st, sk, plan = w.history, w.count, w.st, w.sk, w.plan
    snap_x, snap_v, snap_b, snap_nc = w.snap_x, w.snap_v, w.snap_b, w.snap_nc
    for i in range(x2.shape[1]):
        x2[0, i], v2[0, i], acc[i], cap[i] = rows.x[b, i], rows.v[b, i], rows.acc[b, i], rows.cap[b, i]
    for j in range(rf.shape[1]):
        rf[0, j] = rows.rf[b, j]
    for j in range(rb.shape[1]):
        rb[0, j] = rows.rb[b, j]
    for j in range(ri.shape[1]):
        ri[0, j] = rows.ri[b, j]
    for j in range(plan.shape[1]):
        plan[0, j] = rows.plan[b, j]
    for j in range(history.shape[1]):
        history[0, j] = rows.history[b, j]
    count[0] = rows.count[b]
    for j in range(st.shape[1]):
        st[0, j] = rows.st[b, j]
    for j in range(sk.shape[1]):
        sk[0, j] = rows.sk[b, j]
    for j in range(snap_x.shape[1]):
        snap_x[0, j], snap_v[0, j], snap_b[0, j] = rows.snap_x[b, j], rows.snap_v[b, j], rows.snap_b[b, j]
    snap_nc[0] = rows.snap_nc[b]
    _move_queue(rows.q_knots, rows.q_seg, rows.q_acc, rows.q_flag, b, w.q_knots, w.q_seg, w.q_acc, w.q_flag, 0)
    _load_anchor(rows, b, w.sense)
    o = w.own
    for i in range(o.x.shape[1]):
        o.x[0, i], o.v[0, i], o.cap[0, i] = rows.own_x[b, i], rows.own_v[b, i], rows.own_cap[b, i]
    sb[0, 0] = batch.f_connected[b]  # F trusted where the variant listens: connected (it declares itself collaborative)
    sb[0, 2], sb[0, 3], sb[0, 4] = batch.uses[b, 0], batch.uses[b, 1], batch.uses[b, 2]
    sb[0, 5] = batch.f_aggressive[b]  # F's true type (read by the 'truth' assessment only)


@row_function
def _store(rows, b, w):
    """The scratch ``w`` back into row ``b`` of ``rows`` (:func:`_load`'s inverse)."""
    x2, v2, acc, cap, rf, rb, ri = w.x2, w.v2, w.acc, w.cap, w.rf, w.rb, w.ri
    history, count, st, sk, plan = w.history, w.count, w.st, w.sk, w.plan
    snap_x, snap_v, snap_b, snap_nc = w.snap_x, w.snap_v, w.snap_b, w.snap_nc
    for i in range(x2.shape[1]):
        rows.x[b, i], rows.v[b, i], rows.acc[b, i], rows.cap[b, i] = x2[0, i], v2[0, i], acc[i], cap[i]
    for j in range(rf.shape[1]):
        rows.rf[b, j] = rf[0, j]
    for j in range(rb.shape[1]):
        rows.rb[b, j] = rb[0, j]
    for j in range(ri.shape[1]):
        rows.ri[b, j] = ri[0, j]
    for j in range(plan.shape[1]):
        rows.plan[b, j] = plan[0, j]
    for j in range(history.shape[1]):
        rows.history[b, j] = history[0, j]
    rows.count[b] = count[0]
    for j in range(st.shape[1]):
        rows.st[b, j] = st[0, j]
    for j in range(sk.shape[1]):
        rows.sk[b, j] = sk[0, j]
    for j in range(snap_x.shape[1]):
        rows.snap_x[b, j], rows.snap_v[b, j], rows.snap_b[b, j] = snap_x[0, j], snap_v[0, j], snap_b[0, j]
    rows.snap_nc[b] = snap_nc[0]
    _move_queue(w.q_knots, w.q_seg, w.q_acc, w.q_flag, 0, rows.q_knots, rows.q_seg, rows.q_acc, rows.q_flag, b)
    _store_anchor(rows, b, w.sense)
    o = w.own
    for i in range(o.x.shape[1]):
        rows.own_x[b, i], rows.own_v[b, i], rows.own_cap[b, i] = o.x[0, i], o.v[0, i], o.cap[0, i]


@row_function
def _move_queue(knots, seg, acc, flag, b, to_knots, to_seg, to_acc, to_flag, to_b):
    """Row ``b``'s commands in flight (``Packed.queue``'s layout) into row ``to_b`` of the ``to_*`` arrays."""
    for c in range(knots.shape[1]):
        for j in range(knots.shape[2]):
            to_knots[to_b, c, j] = knots[b, c, j]
        for j in range(seg.shape[3]):
            to_seg[to_b, c, 0, j], to_seg[to_b, c, 1, j] = seg[b, c, 0, j], seg[b, c, 1, j]
        to_acc[to_b, c, 0], to_acc[to_b, c, 1] = acc[b, c, 0], acc[b, c, 1]
        to_flag[to_b, c, 0], to_flag[to_b, c, 1] = flag[b, c, 0], flag[b, c, 1]


@row_function
def _load_anchor(rows, b, a):
    """Row ``b``'s held anchor into the scratch ``a`` (:data:`Sense`; ``None``: nothing to load)."""
    if a is None:
        return
    for j in range(a.anc_f.shape[1]):
        a.anc_f[0, j] = rows.anc_f[b, j]
    for j in range(a.anc_x.shape[1]):
        a.anc_x[0, j], a.anc_v[0, j], a.anc_b[0, j] = rows.anc_x[b, j], rows.anc_v[b, j], rows.anc_b[b, j]
    a.anc_nc[0] = rows.anc_nc[b]


@row_function
def _store_anchor(rows, b, a):
    """:func:`_load_anchor`'s inverse."""
    if a is None:
        return
    for j in range(a.anc_f.shape[1]):
        rows.anc_f[b, j] = a.anc_f[0, j]
    for j in range(a.anc_x.shape[1]):
        rows.anc_x[b, j], rows.anc_v[b, j], rows.anc_b[b, j] = a.anc_x[0, j], a.anc_v[0, j], a.anc_b[0, j]
    rows.anc_nc[b] = a.anc_nc[0]


@row_function
def _window(times, dt):
    """The assessment's window of sample times centred on 0 (``times``, filled) and the sum of their squares."""
    window = times.shape[0]
    for j in range(window):
        times[j] = (j - (window - 1) / 2.0) * dt
    den = times[0] * times[0]
    for j in range(1, window):
        den = den + times[j] * times[j]
    return den

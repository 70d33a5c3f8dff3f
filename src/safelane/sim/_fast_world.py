"""The compiled closed loop's world beyond the paper (numba, extra ``fast``; used by ``_fast_loop._period``), row by
row: the own lane (``L0`` and any vehicles ahead of it, :mod:`.own_chain`: their motion, the ego's exact checks
against ``L0``: :mod:`.realworld`'s :func:`~.realworld.own_lane_checks`, and their pairs' checks,
``ClosedLoop._own_lane``) and the measurement noise of sensing error
(:func:`~.realworld.measure`), and under the actuation delay the command acting (``InFlight``'s oldest, executed
from the ego's actual state: :func:`~.realworld.executed_motion`). The commands in flight themselves are the shield's
queue (``shield/fast_step.Packed.queue``'s layout, pushed by ``_fast_period.push_row``, carried by
``_fast_period.carried_ego``). Loops and indexing only.

No rule lives here. The own lane's motion is :meth:`~.own_chain.OwnLane.period`'s: the head's profile
(:func:`~.traffic.profile_segment`, ``_profile_row``), the connected ones' task (:func:`~.own_chain.own_task`) capped
by the worst-case leader rule (``_fast_traffic._leader_row``) on the running minimum of the chain bounds
(``_fast_traffic._chain_row``), and :meth:`~.kinematics.Fleet.switched`'s numbers
(:func:`~.kinematics.constant_segment`, :func:`_switched`); its pairs are the lane checks' (``_fast_checks._lane_row``,
``_fast_checks._switch_pair``); the ego's checks against ``L0`` are the general path's windowed extrema
(``_fast_general._general_pair``, :func:`~.kinematics.windowed_gap_extrema` over the ego's lateral motion mirrored, as
``own_lane_checks`` takes it) and the target lane's verdict
(:func:`~.checks.ego_verdict`). The draws are :func:`~.rng.counter_uniform`'s hash itself (``_splitmix.absorb``,
``unit_of``, on uint64), the measurement :func:`~.realworld.edge_draw` and :func:`~.realworld.measured`. The tables
are the NumPy path's, bit for bit (``tests/test_fast_realworld_loop.py``).
"""

from __future__ import annotations

import numpy as np

from .._motion import advance_core
from .._splitmix import absorb, unit_of
from ..safety import _compile
from ..safety import responsible as _responsible  # noqa: F401  (marks advance_core: registered below)
from ..safety._backend import INF, SCALAR
from ..safety._fast_base import _max, _min, announce_compiles, row_function
from ._fast_checks import _lane_row, _switch_pair
from ._fast_general import _general_pair
from ._fast_traffic import _chain_row, _leader_row, _profile_row
from .checks import ego_verdict
from .kinematics import constant_segment, state_at
from .own_chain import _EMPTY_AHEAD_M, own_task
from .realworld import CHAIN_SLOTS, EDGE_COUNTER, SLOT_CHAIN, SLOT_F, SLOT_OWN, edge_draw, measured

_compile.register_rows()
announce_compiles()


@row_function
def _switched(x, v, f_acc, f_ts, f_xe, f_ve, i, t_sw, a2, dt, sw):
    """Vehicle ``i`` (its first segment in ``f_*`` from ``constant_segment``) changing to ``a2`` at ``t_sw`` inside
    the period: :meth:`~.kinematics.Fleet.switched`'s numbers (its stop time, end state) into ``f_ts``, ``f_xe``,
    ``f_ve``, its knots (:meth:`~.kinematics.Fleet.motion`) into ``sw``; returns the second segment's ``|a|``."""
    a1, t_stop = f_acc[i], f_ts[i]
    ts1 = _min(t_stop, t_sw)
    x_sw, v_run = state_at(SCALAR, x, v, a1, ts1)
    v_sw = 0.0 if t_stop <= t_sw else _max(v_run, 0.0)  # stopped before the switch: exactly 0
    acc2, ts2, x_end, v_end = constant_segment(SCALAR, x_sw, v_sw, a2, _max(dt - t_sw, 0.0))
    f_ts[i], f_xe[i], f_ve[i] = ts1, x_end, v_end
    sw.t[0], sw.t[1], sw.t[2], sw.t[3], sw.t[4] = 0.0, ts1, t_sw, t_sw + ts2, dt
    sw.x[0], sw.x[1], sw.x[2], sw.x[3], sw.x[4] = x, x_sw, x_sw, x_end, x_end
    sw.v[0], sw.v[1], sw.v[2], sw.v[3], sw.v[4] = v, v_sw, v_sw, v_end, v_end
    sw.a[0], sw.a[1], sw.a[2], sw.a[3] = a1, 0.0, acc2, 0.0
    return abs(acc2)


@row_function
def own_lane_motion(batch, b, o, t, dt, a_x_a, a_o, p_m):
    """The own lane of row ``b`` over the period ``[t, t + dt]`` from its state in ``o`` (``_fast_rows.Own``: ``x``,
    ``v``, ``cap``), :meth:`~.own_chain.OwnLane.period`: each slot's acceleration into ``o.want`` (the head's profile,
    the connected ones' rule: :func:`_own_accels`), its motion into ``o``'s fleet arrays (an empty slot at 0:
    ``constant_segment``; the head's switch inside the period, :meth:`~.kinematics.Fleet.switched`'s numbers, its knots
    into ``o.sw``). Returns ``(switching, row_acc)``: whether the head switches inside the period, and the lane's
    largest ``|acceleration|`` in any segment (``Fleet.row_max_abs_acc``)."""
    x, v, want = o.x[0], o.v[0], o.want
    k = x.shape[0]
    head = batch.own_nc[b]  # (0 with L0 alone)
    a1, t_sw, a2 = _profile_row(batch.l0_profile_t, batch.l0_profile_a, b, t, dt)
    for i in range(k):
        want[i] = 0.0
    want[head] = a1
    if head > 0:
        _own_accels(batch, b, o, t, dt, a_x_a, a_o, p_m)
    row_acc = 0.0
    for i in range(k):
        x0 = x[i] if x[i] < INF else 0.0
        o.fx[0, i], o.fv[0, i] = x0, v[i]
        o.acc[0, i], o.ts[0, i], o.xe[0, i], o.ve[0, i] = constant_segment(SCALAR, x0, v[i], want[i], dt)
        row_acc = _max(row_acc, abs(o.acc[0, i]))
    switching = t_sw < dt
    if switching:
        row_acc = _max(row_acc, _switched(o.fx[0, head], v[head], o.acc[0], o.ts[0], o.xe[0], o.ve[0], head, t_sw, a2,
                                          dt, o.sw))  # fmt: skip
    return switching, row_acc


@row_function
def _own_accels(batch, b, o, t, dt, a_x_a, a_o, p_m):
    """The connected own-lane vehicles' accelerations (``OwnLane._connected``) of row ``b``, which has some: the chain
    scan on the lane laid out as the target lane (an empty slot 0, at rest at 0; the empty slots ahead of the head
    ``_EMPTY_AHEAD_M`` apart beyond it, at rest), the running minimum of its bounds into ``o.cap``, and each connected
    one's task (:func:`~.own_chain.own_task`) under the worst-case leader rule (``_leader_row``) into ``o.want``.
    Where nothing is connected the array path's scan is read by no one: not run here (the caller's branch)."""
    x, v, cap, want = o.x[0], o.v[0], o.cap[0], o.want
    k = x.shape[0]
    nc = batch.own_nc[b]
    lx, lv = o.lane_x, o.lane_v
    lx[0, 0], lv[0, 0] = 0.0, 0.0
    for i in range(k):
        if x[i] < INF:
            lx[0, i + 1], lv[0, i + 1] = x[i], v[i]
        else:
            lx[0, i + 1], lv[0, i + 1] = x[nc] + _EMPTY_AHEAD_M * (i + 1), 0.0
    for i in range(k - 1):
        o.promise[i, 0] = batch.own_promise[b, i] if i < nc else a_o
        o.margin[i, 0] = p_m
    _chain_row(lx, lv, 0, o.promise, o.margin, 0, a_o, o.lane_b)
    for i in range(k):
        cap[i] = _min(cap[i], o.lane_b[0, i + 1])
    for j in range(nc):
        task = own_task(SCALAR, t, batch.own_brake_t[b, j], v[j], batch.own_v_desired[b, j], batch.own_promise[b, j],
                        a_x_a)  # fmt: skip
        want[j] = _leader_row(lx[0, j + 2] - lx[0, j + 1] - p_m, lv[0, j + 1], lv[0, j + 2], cap[j + 1], cap[j], task,
                              False, 0.0, a_o, a_o, dt)  # fmt: skip


@row_function
def own_pairs(o, head, switching, row_acc, p_m, dt, length, o_t, o_x, o_v, o_a, scratch):
    """``OwnLane.pair_collisions`` of a row whose own lane moved (:func:`own_lane_motion`): whether consecutive
    own-lane vehicles ran into each other this period (``lane_checks`` on the lane's fleet, margin ``p_m``; the pair
    behind a switching head on its two segments, ``_switch_pair``)."""
    x = o.x[0]
    k = x.shape[0]
    pairs, margin = o.sw.lane_valid, o.sw.lane_margin
    for c in range(k - 1):
        pairs[0, c] = x[c] < INF and x[c + 1] < INF and not (switching and c + 1 == head)
        margin[0, c] = p_m
    hit = _lane_row(pairs, margin, 0, o.fx, o.fv, o.acc, o.ts, o.xe, o.ve, 0, row_acc, dt, length)[0]
    if switching and head > 0 and x[head] < INF:
        hit = _switch_pair(o.fx[0], o.fv[0], o.acc[0], o.ts[0], o.xe[0], o.ve[0], head - 1, o.sw, o_t, o_x, o_v, o_a,
                           p_m, row_acc, dt, length, scratch)[0] or hit  # fmt: skip
    return hit


@row_function
def own_advance(o):
    """The own lane's state at the period's end (:func:`own_lane_motion`'s), into ``o.x``, ``o.v`` (its empty slots
    stay empty: ``OwnLane.period``'s caller keeps them at ``+inf``)."""
    x, v, xe, ve = o.x[0], o.v[0], o.xe[0], o.ve[0]
    for i in range(x.shape[0]):
        if x[i] < INF:
            x[i] = xe[i]
        v[i] = ve[i]


@row_function
def own_checks(m_t, m_x, m_v, m_a, lon, lat, width, length, p_m, o, scratch):
    """``own_lane_checks`` of one row whose ``L0`` is present, its motion's knots in ``m_*``: the exact ``(min, max)``
    of ``x_0 − x`` over the instants the ego's lateral position is below ``width`` (its lateral motion mirrored above
    ``−width``, into ``o``'s ``lat_*``), and the verdict. ``lon``, ``lat``: the ego's motions' ``(t, x, v, acc)``
    knots. Returns ``(hit, close, low)`` (``close`` before the completion's mask)."""
    lon_t, lon_x, lon_v, lon_a = lon
    lat_t, lat_x, lat_v, lat_a = lat
    nl = lat_t.shape[0]
    for j in range(nl):
        o.lat_t[j], o.lat_x[j], o.lat_v[j] = lat_t[j], -lat_x[j], -lat_v[j]
    for j in range(nl - 1):
        o.lat_a[j] = -lat_a[j]
    low, high = _general_pair(lon_t, lon_x, lon_v, lon_a, m_t, m_x, m_v, m_a, o.lat_t[:nl], o.lat_x[:nl],
                              o.lat_v[:nl], o.lat_a[: nl - 1], -width, scratch)  # fmt: skip
    hit, close = ego_verdict(SCALAR, low, high, low, high, length, p_m)
    return hit, close, low


@row_function
def _draw(batch, b, step, slot, far, share):
    """One measurement draw of row ``b`` (``measure``'s ``draw``): ``counter_uniform(seed, key, step, slot)`` (with
    one more counter, 1, for a chain vehicle beyond :data:`~.realworld.CHAIN_SLOTS`), put at the bound's end by the
    edge share's second draw (the counter :data:`~.realworld.EDGE_COUNTER` after them)."""
    h = absorb(batch.key[0], np.uint64(batch.world_key[b]))
    h = absorb(h, np.uint64(step))
    h = absorb(h, np.uint64(slot))
    if far:
        h = absorb(h, np.uint64(1))
    u = unit_of(h)
    if share <= 0.0:
        return u
    return edge_draw(SCALAR, u, unit_of(absorb(h, np.uint64(EDGE_COUNTER))), share)


@row_function
def measure_row(batch, b, step, share, x, v, chain_x, chain_v, own_x, own_v):
    """``measure`` of row ``b`` at period ``step``: the target lane's true ``x``, ``v`` (F in slot 0) measured — the
    chain into ``chain_x``, ``chain_v`` (row 0) — and the own lane in place (``own_x``, ``own_v``, row 0: the true
    states the shield would see, ``+inf``: none) where the batch has its bounds; returns F's ``(x, v)``."""
    e_f, e_c = batch.err_f, batch.err_chain
    f_x, f_v = measured(SCALAR, x[0], v[0], e_f[b, 0], e_f[b, 1], _draw(batch, b, step, SLOT_F, False, share),
                        _draw(batch, b, step, SLOT_F + 1, False, share))  # fmt: skip
    for k in range(chain_x.shape[1]):
        far = k >= CHAIN_SLOTS
        ux = _draw(batch, b, step, SLOT_CHAIN + 2 * k, far, share)
        uv = _draw(batch, b, step, SLOT_CHAIN + 2 * k + 1, far, share)
        chain_x[0, k], chain_v[0, k] = measured(SCALAR, x[k + 1], v[k + 1], e_c[b, k, 0], e_c[b, k, 1], ux, uv)
    if batch.err_own.shape[1] > 0:
        e_o = batch.err_own
        for k in range(own_x.shape[1]):
            if own_x[0, k] < INF:
                own_x[0, k], own_v[0, k] = measured(SCALAR, own_x[0, k], own_v[0, k], e_o[b, k, 0], e_o[b, k, 1],
                                                    _draw(batch, b, step, SLOT_OWN + 2 * k, False, share),
                                                    _draw(batch, b, step, SLOT_OWN + 2 * k + 1, False, share))
            else:
                own_x[0, k], own_v[0, k] = INF, 0.0
    return f_x, f_v


@row_function
def executed_plan(knots, ax_seg, ay_seg, ex, ey, evx, evy, kt, kx, kv, ky, kvy):
    """An aborting command's plan executed from the ego's actual state (``executed_motion``:
    ``Command.plan_samples``, ``segment_states``): the command acting, the oldest in flight as
    ``shield/fast_step.Packed.queue`` holds it (its 8 ``knots`` and its 7 segments' accelerations ``ax_seg``,
    ``ay_seg``); its knots into ``kt``, the states there into ``kx, kv, ky, kvy``."""
    kt[0], kx[0], kv[0], ky[0], kvy[0] = knots[0], ex, evx, ey, evy
    for j in range(7):
        kt[j + 1] = knots[1 + j]
        h = knots[1 + j] - knots[j]
        kx[j + 1], kv[j + 1] = advance_core(SCALAR, kx[j], kv[j], ax_seg[j], h)
        ay = ay_seg[j]
        ky[j + 1], kvy[j + 1] = ky[j] + kvy[j] * h + 0.5 * ay * h * h, kvy[j] + ay * h

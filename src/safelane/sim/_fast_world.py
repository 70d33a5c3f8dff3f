"""The compiled closed loop's world beyond the paper (numba, extra ``fast``; used by ``_fast_loop._period``), row by
row: the own lane's leader ``L0`` (its profile motion, the ego's exact checks against it: :mod:`.realworld`'s
:func:`~.realworld.own_lane_checks`, ``ClosedLoop._own_lane``) and the measurement noise of sensing error
(:func:`~.realworld.measure`), and under the actuation delay the command acting (``InFlight``'s oldest, executed
from the ego's actual state: :func:`~.realworld.executed_motion`). The commands in flight themselves are the shield's
queue (``shield/fast_step.Packed.queue``'s layout, pushed by ``_fast_period.push_row``, carried by
``_fast_period.carried_ego``). Loops and indexing only.

No rule lives here. ``L0``'s motion is :func:`~.traffic.profile_segment` (``_profile_row``) and
:meth:`~.kinematics.Fleet.switched`'s numbers (:func:`~.kinematics.constant_segment`, :func:`_switched`); its checks
are the general path's windowed extrema (``_fast_general._general_pair``, :func:`~.kinematics.windowed_gap_extrema`
over the ego's lateral motion mirrored, as ``own_lane_checks`` takes it) and the target lane's verdict
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
from ._fast_general import _general_pair
from ._fast_traffic import _profile_row
from .checks import ego_verdict
from .kinematics import constant_segment, state_at
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
def own_motion(batch, b, o, t, dt, x, v):
    """``L0``'s motion over the period ``[t, t + dt]`` from ``(x, v)`` (``OwnLane.period`` of one slot: the head's
    profile, ``Fleet.switched`` where it switches inside the period): its knots into ``o`` (``_fast_rows.Own``), its
    end state into ``o.xe[0]``, ``o.ve[0]``; returns the number of knots (3, or 5 where it switches)."""
    a1, t_sw, a2 = _profile_row(batch.l0_profile_t, batch.l0_profile_a, b, t, dt)
    o.acc[0], o.ts[0], o.xe[0], o.ve[0] = constant_segment(SCALAR, x, v, a1, dt)
    if t_sw < dt:
        _switched(x, v, o.acc, o.ts, o.xe, o.ve, 0, t_sw, a2, dt, o)
        return 5
    o.t[0], o.t[1], o.t[2] = 0.0, o.ts[0], dt
    o.x[0], o.x[1], o.x[2] = x, o.xe[0], o.xe[0]
    o.v[0], o.v[1], o.v[2] = v, o.ve[0], o.ve[0]
    o.a[0], o.a[1] = o.acc[0], 0.0
    return 3


@row_function
def own_checks(o, n_o, lon, lat, width, length, p_m, scratch):
    """``own_lane_checks`` of one row whose ``L0`` is present, its motion's ``n_o`` knots in ``o``: the exact
    ``(min, max)`` of ``x_0 − x`` over the instants the ego's lateral position is below ``width`` (its lateral motion
    mirrored above ``−width``), and the verdict. ``lon``, ``lat``: the ego's motions' ``(t, x, v, acc)`` knots.
    Returns ``(hit, close, low)`` (``close`` before the completion's mask)."""
    lon_t, lon_x, lon_v, lon_a = lon
    lat_t, lat_x, lat_v, lat_a = lat
    nl = lat_t.shape[0]
    for j in range(nl):
        o.lat_t[j], o.lat_x[j], o.lat_v[j] = lat_t[j], -lat_x[j], -lat_v[j]
    for j in range(nl - 1):
        o.lat_a[j] = -lat_a[j]
    low, high = _general_pair(lon_t, lon_x, lon_v, lon_a, o.t[:n_o], o.x[:n_o], o.v[:n_o], o.a[: n_o - 1],
                              o.lat_t[:nl], o.lat_x[:nl], o.lat_v[:nl], o.lat_a[: nl - 1], -width,
                              scratch)  # fmt: skip
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
def measure_row(batch, b, step, share, x, v, chain_x, chain_v, l0x, l0v, own_x, own_v):
    """``measure`` of row ``b`` at period ``step``: the target lane's true ``x``, ``v`` (F in slot 0) measured — the
    chain into ``chain_x``, ``chain_v`` (row 0), ``L0`` (``l0x``, ``l0v``; ``+inf``: none) into ``own_x``,
    ``own_v`` (row 0) where they have a column; returns F's ``(x, v)``."""
    e_f, e_c = batch.err_f, batch.err_chain
    f_x, f_v = measured(SCALAR, x[0], v[0], e_f[b, 0], e_f[b, 1], _draw(batch, b, step, SLOT_F, False, share),
                        _draw(batch, b, step, SLOT_F + 1, False, share))  # fmt: skip
    for k in range(chain_x.shape[1]):
        far = k >= CHAIN_SLOTS
        ux = _draw(batch, b, step, SLOT_CHAIN + 2 * k, far, share)
        uv = _draw(batch, b, step, SLOT_CHAIN + 2 * k + 1, far, share)
        chain_x[0, k], chain_v[0, k] = measured(SCALAR, x[k + 1], v[k + 1], e_c[b, k, 0], e_c[b, k, 1], ux, uv)
    if own_x.shape[1] > 0 and batch.err_own.shape[1] > 0:
        ox, ov = measured(SCALAR, l0x, l0v, batch.err_own[b, 0, 0], batch.err_own[b, 0, 1],
                          _draw(batch, b, step, SLOT_OWN, False, share),
                          _draw(batch, b, step, SLOT_OWN + 1, False, share))  # fmt: skip
        if l0x < INF:
            own_x[0, 0], own_v[0, 0] = ox, ov
        else:
            own_x[0, 0], own_v[0, 0] = INF, 0.0
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

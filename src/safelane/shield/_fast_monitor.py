"""Optional compiled kernel of the assumption monitor's period check (:func:`~.monitor.observe_breaches`; numba,
extra ``fast``): loops and indexing only. Per scenario it calls the monitor's own comparisons, compiled as they are
(:func:`~.monitor.braked_harder` for every chain vehicle at its bound and for L1 at the held plan's deceleration,
:func:`~.monitor.pushed_harder` for F at its responsible limit), compiled on the float backend ``SCALAR``, so the
flags and times are the NumPy path's (``tests/test_fast_monitor.py``)."""

from __future__ import annotations

import numpy as np
from numba import types

from ..safety import _compile
from ..safety._backend import SCALAR
from ..safety._fast_base import announce_compiles, kernel, row_function
from .monitor import BREACH_KINDS, TOL_M, Breach, braked_harder, pushed_harder

_compile.register_rows()
announce_compiles()

_M = types.Array(types.float64, 2, "A", readonly=True)
_V = types.Array(types.float64, 1, "A", readonly=True)
_VB = types.Array(types.bool_, 1, "A", readonly=True)
_SIGNATURE = types.void(
    _M, _M, _M, _M, types.Array(types.int64, 1, "A", readonly=True), _V, _V, _V, _V, _VB, _V, types.boolean,
    types.float64, types.float64, types.Array(types.bool_, 2, "A"),
)  # fmt: skip


@row_function
def _breach_row(chain_x, chain_v, bounds, r, now_x, nr, off, n_connected, plan_l1_decel, f_x, f_v, f_limit, active,
                now_f_x, same_chain, dt, tol):  # fmt: skip
    """One scenario of :func:`breach_kernel`: row ``r`` of the snapshot's chain (``(., M)``), the chain now at row
    ``nr``, columns from ``off`` of ``now_x``; the four flags."""
    l1 = leader = last = False
    if same_chain:
        for i in range(chain_x.shape[1]):
            behind = braked_harder(SCALAR, now_x[nr, i + off], chain_x[r, i], chain_v[r, i], bounds[r, i], dt, tol)
            if i < n_connected:
                leader = leader or behind
            elif i == n_connected:
                last = last or behind
        l1 = active and braked_harder(SCALAR, now_x[nr, off], chain_x[r, 0], chain_v[r, 0], plan_l1_decel, dt, tol)
    return l1, leader, last, pushed_harder(SCALAR, now_f_x, f_x, f_v, f_limit, dt, tol)


@kernel(_SIGNATURE)
def breach_kernel(
    chain_x, chain_v, bounds, now_x, n_connected, plan_l1_decel, f_x, f_v, f_limit, active, now_f_x, same_chain, dt,
    tol, flags,
):  # fmt: skip
    """Write the period's breach flags (``(B, 4)`` of the first four :data:`~.monitor.BREACH_KINDS`) into ``flags``:
    ``chain_x``/``chain_v``/``bounds`` the snapshot's chain, ``now_x`` the chain now (read only where
    ``same_chain``: the chain kept its length)."""
    for b in range(chain_x.shape[0]):
        flags[b, 0], flags[b, 1], flags[b, 2], flags[b, 3] = _breach_row(
            chain_x, chain_v, bounds, b, now_x, b if same_chain else 0, 0, n_connected[b], plan_l1_decel[b], f_x[b],
            f_v[b], f_limit[b], active[b], now_f_x[b], same_chain, dt, tol,
        )  # fmt: skip


def observe_breaches(prev: Breach, last, situation, prm, t_now: float) -> Breach:
    """:func:`~.monitor.observe_breaches` through :func:`breach_kernel`."""
    bsz = len(prev.first_s)
    same = situation.chain_x.shape == last.chain_x.shape
    f64 = lambda a, shape: np.broadcast_to(np.asarray(a, dtype=np.float64), shape)  # noqa: E731
    m = last.chain_x.shape[1]
    flags = np.zeros((bsz, len(BREACH_KINDS)), dtype=np.bool_)
    breach_kernel(
        f64(last.chain_x, (bsz, m)), f64(last.chain_v, (bsz, m)), f64(last.bounds, (bsz, m)),
        f64(situation.chain_x, (bsz, m)) if same else np.zeros((1, 1)),
        np.broadcast_to(np.asarray(last.n_connected, dtype=np.int64), (bsz,)), f64(last.plan_l1_decel, (bsz,)),
        f64(last.f_x, (bsz,)), f64(last.f_v, (bsz,)), f64(last.f_limit, (bsz,)),
        np.broadcast_to(np.asarray(last.active, dtype=np.bool_), (bsz,)), f64(situation.f_x, (bsz,)), same, prm.dt,
        TOL_M, flags[:, :4],
    )  # fmt: skip
    new = flags & ~prev.flags
    first = np.where(np.isnan(prev.first_s) & new.any(1), t_now, prev.first_s)
    return Breach(flags=prev.flags | flags, first_s=first)


_ANCHOR_SIGNATURE = types.void(
    _M, _M, _M, _M, _V, types.Array(types.int64, 1, "A", readonly=True), _V, _V, _V, _V, _V, _V, _V, _V, _V, _V, _V,
    _VB, types.boolean, types.float64, types.Array(types.bool_, 2, "A"),
)  # fmt: skip


@row_function
def anchor_row(chain_x, chain_v, bounds, r, now_x, nr, off, l1_decel, n_connected, f_x, f_v, f_accel, now_f_x, own_x,
               own_v, own_decel, now_own_x, age, age_f, age_own, same_chain, tol):  # fmt: skip
    """One active row of :func:`anchor_kernel` (and of the compiled period): row ``r`` of the anchor's chain
    (``(., M)``), the chain now at row ``nr``, columns from ``off`` of ``now_x``; the four flags."""
    l1 = leader = last = False
    if same_chain:
        for i in range(chain_x.shape[1]):
            behind = braked_harder(SCALAR, now_x[nr, i + off], chain_x[r, i], chain_v[r, i], bounds[r, i], age, tol)
            if i < n_connected:
                leader = leader or behind
            elif i == n_connected:
                last = last or behind
        l1 = braked_harder(SCALAR, now_x[nr, off], chain_x[r, 0], chain_v[r, 0], l1_decel, age, tol)
    if own_x < np.inf and now_own_x < np.inf:
        last = last or braked_harder(SCALAR, now_own_x, own_x, own_v, own_decel, age_own, tol)
    return l1, leader, last, pushed_harder(SCALAR, now_f_x, f_x, f_v, f_accel, age_f, tol)


@kernel(_ANCHOR_SIGNATURE)
def anchor_kernel(
    chain_x, chain_v, bounds, now_x, l1_decel, n_connected, f_x, f_v, f_accel, now_f_x, own_x, own_v, own_decel,
    now_own_x, age, age_f, age_own, active, same_chain, tol, flags,
):  # fmt: skip
    """The cumulative comparison (:func:`~.monitor.anchor_flags`) per scenario into ``flags`` (``(B, 4)``): the
    monitor's own comparisons over each row's time since its anchors (``age``: the chain's, ``age_f``: F's,
    ``age_own``: L0's); ``now_x`` read only where ``same_chain``."""
    for b in range(chain_x.shape[0]):
        if not active[b]:
            continue
        flags[b, 0], flags[b, 1], flags[b, 2], flags[b, 3] = anchor_row(
            chain_x, chain_v, bounds, b, now_x, b, 0, l1_decel[b], n_connected[b], f_x[b], f_v[b], f_accel[b],
            now_f_x[b], own_x[b], own_v[b], own_decel[b], now_own_x[b], age[b], age_f[b], age_own[b], same_chain, tol,
        )  # fmt: skip


def anchor_flags(anchor, active, now_chain_x, now_f_x, now_own_x, age, age_f, age_own):
    """:func:`~.monitor.anchor_flags` through :func:`anchor_kernel` (``now_chain_x`` ``None``: the chain changed
    length)."""
    bsz, m = np.shape(anchor.chain_x)
    f64 = lambda a, shape: np.broadcast_to(np.asarray(a, dtype=np.float64), shape)  # noqa: E731
    flags = np.zeros((bsz, len(BREACH_KINDS)), dtype=np.bool_)
    same = now_chain_x is not None
    anchor_kernel(
        f64(anchor.chain_x, (bsz, m)), f64(anchor.chain_v, (bsz, m)), f64(anchor.bounds, (bsz, m)),
        f64(now_chain_x, (bsz, m)) if same else np.zeros((1, 1)), f64(anchor.l1_decel, (bsz,)),
        np.broadcast_to(np.asarray(anchor.n_connected, dtype=np.int64), (bsz,)), f64(anchor.f_x, (bsz,)),
        f64(anchor.f_v, (bsz,)), f64(anchor.f_accel, (bsz,)), f64(now_f_x, (bsz,)), f64(anchor.own_x, (bsz,)),
        f64(anchor.own_v, (bsz,)), f64(anchor.own_decel, (bsz,)), f64(now_own_x, (bsz,)), f64(age, (bsz,)),
        f64(age_f, (bsz,)), f64(age_own, (bsz,)), np.broadcast_to(np.asarray(active, dtype=np.bool_), (bsz,)), same,
        TOL_M, flags[:, :4],
    )  # fmt: skip
    return flags

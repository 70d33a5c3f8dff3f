"""Worst-case deceleration propagated down the connected leader chain (paper Eqs. 1–4).

Symbols: ``L_i`` is the i-th leader ahead of the ego in the target lane (``L1`` nearest); ``L1..LN`` are
connected and promise to brake no harder than ``a_m_d`` unless their own safety requires more (never beyond the
others' maximum ``a_o_d``, ``Params.others_decel``); ``L(N+1)`` is not connected and is assumed to brake at
``a_o_d`` (``a_x_d`` in the paper's world, where ``a_o_d`` is not set).

Correction to the paper (see ``docs/safety.md``): the first case of Eq. 2 reads
``z = 3 (v_{i-1} − v_i)² / (2 (p_i − p_{i-1} − p_m)) + a_{x,i,d}``. Setting the gap at the equal-speed instant
to ``p_m`` gives ``z = (v_{i-1} − v_i)² / (2 D) + a_{x,i,d}`` with ``D = p_i − p_{i-1} − p_m``; the factor 3
comes from a sign error in the ``z t²/2`` term of Eq. 1 at ``t = (v_{i-1} − v_i)/(z − a_{x,i,d})``. The case is
also chosen here by where the minimum gap really occurs (a condition on known quantities), not by the
paper's condition, which involves the unknown ``z``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..params import Params
from ._backend import ARRAY, FEASIBILITY_TOL_M, INF, SCALAR, jitable
from ._checks import bool_array, check_params, finish, float_array, prepare


def min_follow_decel(xp, slack, v_f, v_l, a_l, tol=FEASIBILITY_TOL_M):
    """Smallest constant deceleration ``z`` keeping a follower ``slack`` metres clear of its margin.

    ``slack = p_l − p_f − p_m`` (> 0), follower speed ``v_f``, leader speed ``v_l``, leader braking at ``a_l``
    until it stops; both vehicles stop rather than reverse. The gap is smallest either when the speeds
    become equal while both still move (only possible if ``v_f > v_l``) or when both have stopped:

    * equal speeds while moving: ``z_A = a_l + (v_f − v_l)² / (2 slack)``, which applies exactly when at
      ``z_A`` the equal-speed time ``2 slack / (v_f − v_l)`` comes before the leader stops, i.e.
      ``2 slack a_l <= v_l (v_f − v_l)``;
    * both stopped: ``z_B = v_f² / (2 slack + v_l² / a_l)``.

    **The boundary** ``slack = 0`` (the pair exactly at its margin — where a chain's own worst-case trajectory
    ends, and what a speed match on a period boundary produces, with speeds equal up to round-off): gaps within
    ``FEASIBILITY_TOL_M`` (1 nm) of the margin count as kept, as everywhere in the analysis. A slack of at most
    half of it is taken as ``slack + FEASIBILITY_TOL_M / 2`` (clamped at 0 down to ``−FEASIBILITY_TOL_M``): ``z``
    then keeps the gap above ``margin − 0.5 nm``, leaving the other half of the tolerance to round-off, so a pair
    that settles at the margin never drifts out of the tolerance. A pair at the margin that is not closing needs
    ``z_B ≈ a_l·(v_f/v_l)²`` (``a_l`` at equal speeds; 0 when both are at rest), the limit of the formula as
    ``slack → 0+``; one closing at round-off speed (``1e-15`` m/s) needs ``a_l`` plus a negligible term; one really
    closing needs far beyond ``a_x_d`` (unsafe). So ``z`` is continuous as ``slack → 0`` (up to the tolerance)
    wherever the true bound is; it is ``inf`` only for pairs inside the margin beyond the tolerance.

    ``tol``: that tolerance (the compiled rows pass it on; every caller uses ``FEASIBILITY_TOL_M``).

    Backend-generic and compiled as it is (marked ``jitable``): one formula for NumPy arrays, floats and the kernels.
    Every division is guarded (``xp.div``, or a divisor that cannot be zero where the quotient is used); a NumPy
    caller that feeds extreme magnitudes (products overflowing) sets its own ``errstate``.

    Returns ``z`` (``inf`` when ``slack < −tol``).
    """
    half = 0.5 * tol
    slack = xp.where(slack > half, slack, xp.where(slack >= -tol, xp.maximum(slack + half, 0.0), slack))
    # 2·(v_l²/(2 a_l)) = v_l²/a_l and 2·slack: the exact rescalings of the stopping distances.
    lead_stop2 = xp.where(a_l > 0.0, xp.div(v_l * v_l, a_l, 0.0), xp.where(v_l > 0.0, INF, 0.0))
    two_slack = 2.0 * slack
    # The denominator is > 0 wherever slack > 0; at slack = 0 it is 0 only with the leader at rest (or v_l²
    # underflowing), where a pair that is not closing needs 0 (a closing one takes z_A); NaN gives 0 (not > 0).
    den = two_slack + lead_stop2
    z_b = xp.where(den > 0.0, xp.div(v_f * v_f, den, 0.0), 0.0)
    dv = v_f - v_l
    # A zero divisor (slack taken as 0) with a closing pair: z_A is infinite.
    z_a = a_l + xp.div(dv * dv, two_slack, INF)
    interior = (dv > 0.0) & (two_slack * a_l <= v_l * dv)
    return xp.where(slack >= 0.0, xp.where(interior, z_a, z_b), INF)


@dataclass(frozen=True)
class ChainResult:
    """Worst-case decelerations of a leader chain.

    Attributes:
        decel: ``(..., N+1)`` worst-case deceleration of ``L1..L(N+1)`` (the last is ``a_o_d``).
        required: ``(..., N)`` minimum deceleration ``z`` that ``L1..LN`` need to stay clear of the vehicle
            ahead (``inf`` where the gap is already at or below the margin).
        unsafe: ``(...)`` True where some ``L_i`` cannot be shown to stay clear of ``L(i+1)`` (gap at or
            below its margin, or ``z > a_o_d``: beyond what any other vehicle can brake); ``l1_decel`` is then
            ``a_o_d``.
        l1_decel: ``(...)`` worst-case deceleration of ``L1`` for the ego's analysis.
    """

    decel: np.ndarray
    required: np.ndarray
    unsafe: np.ndarray
    l1_decel: np.ndarray


def leader_chain(p, v, promise_decel, params: Params, *, human_driven=None) -> ChainResult:
    """Propagate the worst case from ``L(N+1)`` up to ``L1`` (Eqs. 1–3, corrected).

    Args:
        p, v: ``(..., N+1)`` positions [m] and speeds [m/s] of ``L1..L(N+1)``, ordered front-last
            (``p[..., i+1] > p[..., i]`` in normal traffic).
        promise_decel: ``(..., N)`` promised maximum deceleration ``a_m_d`` of ``L1..LN`` (``<= a_o_d``).
        params: physical limits.
        human_driven: optional ``(..., N)`` bool; a connected human-driven ``L_i`` keeps ``p_m_human``
            (paper footnote 1) to the vehicle ahead instead of ``p_m``.

    ``L_i`` brakes at ``min(max(a_m_d_i, z_i), a_o_d)``: its promise, or the least it needs (an expected
    violation), never beyond the others' maximum ``a_o_d`` (``params.others_decel``: ``a_x_d`` unless set).
    The loop runs over the chain, not the batch: each link depends on the one ahead (a scan).
    """
    check_params(params)
    p = _as_chain("p", p)
    v = _as_chain("v", v)
    n_links = p.shape[-1] - 1
    if p.shape[-1] < 1:
        raise ValueError(f"p must have at least one vehicle (L(N+1)) on its last axis; got shape {p.shape}")
    if v.shape != p.shape:
        raise ValueError(f"v must have the same shape as p {p.shape}; got {v.shape}")
    promise = _as_chain("promise_decel", promise_decel)
    if promise.shape[-1] != n_links:
        raise ValueError(
            f"promise_decel must have N={n_links} entries on its last axis (one per connected leader); "
            f"got shape {promise.shape}"
        )
    if (v < 0).any():
        raise ValueError(f"v must be >= 0; got {v[v < 0].flat[0]!r}")
    a_o = params.others_decel
    if (promise < 0).any() or (promise > a_o).any():
        bad = promise[(promise < 0) | (promise > a_o)].flat[0]
        raise ValueError(f"promise_decel must lie in [0, a_o_d={a_o}] (Params.others_decel); got {bad!r}")
    if human_driven is None:
        human = np.zeros(promise.shape, dtype=bool)
    else:
        human = bool_array("human_driven", human_driven)
        if human.shape[-1:] != (n_links,):
            raise ValueError(f"human_driven must have N={n_links} entries on its last axis; got {human.shape}")
    try:
        batch = np.broadcast_shapes(p.shape[:-1], promise.shape[:-1], human.shape[:-1])
    except ValueError as exc:
        raise ValueError(
            f"batch shapes do not broadcast: p{p.shape}, promise_decel{promise.shape}, human_driven{human.shape}"
        ) from exc

    xp = SCALAR if batch == () else ARRAY
    margin = np.where(human, params.p_m_human, params.p_m)
    if xp is SCALAR:
        cols = (p.tolist(), v.tolist(), promise.tolist(), margin.tolist())
    else:
        cols = tuple(np.moveaxis(np.broadcast_to(a, (*batch, a.shape[-1])), -1, 0) for a in (p, v, promise, margin))
    with np.errstate(all="ignore"):
        decel, required, unsafe = propagate_chain(xp, *cols, params, n_links)
    l1 = xp.where(unsafe, params.others_decel, decel[0])
    if xp is SCALAR:
        stack = lambda xs: np.asarray(xs, dtype=np.float64)  # noqa: E731
    else:
        stack = lambda xs: np.stack([np.broadcast_to(x, batch) for x in xs], -1)  # noqa: E731
    required_arr = stack(required) if n_links else np.zeros((*batch, 0))
    return ChainResult(
        decel=stack(decel),
        required=required_arr,
        unsafe=finish(xp, batch, unsafe, np.bool_),
        l1_decel=finish(xp, batch, l1),
    )


def propagate_chain(xp, p, v, promise, margin, params: Params, n_links: int):
    """Unchecked scan of :func:`leader_chain` over per-vehicle rows ``p[i]``, ``v[i]`` (``L1`` first; ``promise``
    and ``margin`` — ``p_m``, or ``p_m_human`` for a human-driven link — for ``L1..LN``). Returns
    ``(decel, required, unsafe)``: lists front-last and a flag. Every other vehicle brakes at most
    ``params.others_decel`` (``a_o_d``; ``a_x_d`` in the paper's world)."""
    a_o = params.others_decel
    decel = [a_o]  # L(N+1), not connected: the others' maximum braking
    required = []
    unsafe = False
    a_ahead = a_o
    slacks = [p[i + 1] - p[i] - margin[i] for i in range(n_links)] if xp is not ARRAY else p[1:] - p[:-1] - margin
    for i in range(n_links - 1, -1, -1):
        z, a_ahead, broken = chain_link(xp, slacks[i], v[i], v[i + 1], a_ahead, promise[i], a_o)
        unsafe = unsafe | broken
        decel.insert(0, a_ahead)
        required.insert(0, z)
    return decel, required, unsafe


def chain_link(xp, slack, v_f, v_l, a_ahead, promise, a_o):
    """One link of :func:`propagate_chain`'s scan (Eqs. 2–3, corrected), backend-generic: a leader ``slack`` metres
    clear of its margin behind a vehicle whose worst case is ``a_ahead``. Returns ``(z, decel, broken)``: the least
    deceleration it needs (:func:`min_follow_decel`), its worst case ``min(max(promise, z), a_o)`` (its promise, or
    an expected violation, never beyond the others' maximum ``a_o``) and whether ``z`` exceeds ``a_o`` (the link
    cannot be shown safe). The compiled chain scan (``sim/_fast_traffic.py``) calls it link by link."""
    z = min_follow_decel(xp, slack, v_f, v_l, a_ahead)
    return z, xp.minimum(xp.maximum(promise, z), a_o), z > a_o


def worst_case_leader_decel(p, v, promise_decel, params: Params, *, human_driven=None):
    """Worst-case deceleration of ``L1`` (paper Eqs. 1–3, corrected). See :func:`leader_chain`.

    Returns ``(...)`` float64; the others' maximum ``a_o_d`` when ``N = 0`` or when a collision ahead cannot be ruled
    out.
    """
    return leader_chain(p, v, promise_decel, params, human_driven=human_driven).l1_decel


def leader_position(p, v, decel, t, params: Params):
    """Position of a leader braking at ``decel`` from ``(p, v)`` after ``t`` seconds, stopping at rest (Eq. 4).

    All arguments broadcast; ``decel`` in ``[0, max(a_x_d, a_o_d)]``, ``v >= 0``, ``t >= 0``.
    """
    check_params(params)
    xp, a, shape = prepare(
        {"p": p, "v": v, "decel": decel, "t": t},
        nonneg=("v", "decel", "t"),
        upper={"decel": decel_cap(params)},
    )
    with np.errstate(all="ignore"):
        out = braked_position(xp, a["p"], a["v"], a["decel"], a["t"])
    return finish(xp, shape, out)


def decel_cap(params: Params) -> float:
    """The largest worst-case deceleration an input may give a vehicle: ``max(a_x_d, a_o_d)`` (the ego's committed
    braking, or any other vehicle's maximum)."""
    return max(params.a_x_d, params.others_decel)


def braked_position(xp, p, v, decel, t, t_stop=None):
    """Unchecked core of :func:`leader_position` (backend-generic).

    ``t_stop`` is ``xp.stop_time(v, decel)``; callers that evaluate one trajectory at many times pass it once.
    """
    if t_stop is None:
        t_stop = xp.stop_time(v, decel)
    tt = xp.minimum(t, t_stop)
    return p + v * tt - 0.5 * decel * tt * tt


def _as_chain(name: str, value) -> np.ndarray:
    arr = float_array(name, value)
    if arr.ndim == 0:
        raise ValueError(f"{name} must have a vehicle axis (last axis); got a scalar")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite; got {arr[~np.isfinite(arr)].flat[0]!r}")
    return arr


# The closed forms compiled into the kernels (safety/_compile.py): the same functions, evaluated row by row.
jitable(braked_position, min_follow_decel, chain_link)

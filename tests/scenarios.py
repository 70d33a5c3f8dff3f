"""Named scenarios for the safety engine, each built for the situation its name describes.

Every builder returns a fresh ``dict`` of keyword arguments, to be used with the default :class:`safelane.Params`
(``a_x_a = 2.5``, ``a_x_d = 8``, ``a_y_m = 1.5`` m/s², ``w_l = 3.5``, ``w_v = 1.8``, ``p_m = 7``,
``p_m_human = 10`` m; so ``y_s = 0.85`` m and the lane boundary is at ``y = 1.75`` m):

* evasion scenarios (``EVASION_SCENARIOS``) → ``evasion_exists(**s, params=Params())`` /
  ``plan_evasion(**s, params=Params())``; the ego is at ``ego_px = 0``, moving at 25 m/s unless said otherwise.
* chain scenarios (``CHAIN_SCENARIOS``) → ``leader_chain(**s, params=Params())`` /
  ``worst_case_leader_decel(**s, params=Params())``; positions and speeds of ``L1..L(N+1)``.

The outcome each docstring promises is checked in ``test_safety_golden.py``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


def _evasion(**overrides) -> dict:
    """A calm lane change half-way across (centre on the lane boundary, drifting on at 0.5 m/s), ``L1`` 40 m
    ahead and a collaborative follower 30 m behind, everyone at 25 m/s, ``L1`` assumed to brake at ``a_x_d``."""
    state = dict(
        ego_px=0.0,
        ego_py=1.75,
        ego_vx=25.0,
        ego_vy=0.5,
        l1_p=40.0,
        l1_v=25.0,
        l1_decel=8.0,
        f_p=-30.0,
        f_v=25.0,
        follower_aggressive=False,
    )
    state.update(overrides)
    return state


# --- evasion scenarios ------------------------------------------------------------------------------------------


def open_gap_collaborative_follower() -> dict:
    """Wide gaps both ways and a collaborative follower: the evasion exists; the ego can accelerate throughout
    (Figure 3 case code 0)."""
    return _evasion()


def tight_gap_aggressive_follower() -> dict:
    """An aggressive follower 9 m behind closing at 5 m/s: it reaches the ego before the ego is back in its lane
    (reason ``FOLLOWER_TOO_CLOSE``)."""
    return _evasion(f_p=-9.0, f_v=30.0, follower_aggressive=True)


def leader_braking_hard_close() -> dict:
    """``L1`` 9 m ahead, 10 m/s slower, braking at ``a_x_d``: even full braking from now cannot keep ``p_m``
    (reason ``LEADER_INFEASIBLE``)."""
    return _evasion(ego_vx=30.0, l1_p=9.0, l1_v=20.0)


def already_back_in_lane() -> dict:
    """Centre at 0.3 m drifting home: the ego is wholly in its own lane, ``t_y_f = 0`` and there is nothing to
    evade (reason ``NOTHING_TO_EVADE``), even though ``L1`` is close and braking."""
    return _evasion(ego_py=0.3, ego_vy=-0.2, l1_p=9.0, l1_v=20.0)


def past_lane_boundary_returning_fast() -> dict:
    """Centre 0.15 m past the lane boundary but heading home at 2 m/s: too fast to stop at ``y_s``, so the
    lateral plan only brakes (no bang-bang switch, ``t_y_switch = 0``) — the case the paper's Eq. 5 misses."""
    return _evasion(ego_py=1.9, ego_vy=-2.0)


def ego_stops_before_horizon() -> dict:
    """Crawling queue: the ego (5 m/s, fully in the target lane) is 15 m behind a stopped ``L1``; the evasion
    brakes it to a stop before ``t_y_f`` (Figure 3 case (b), code 2)."""
    return _evasion(ego_py=3.5, ego_vy=0.0, ego_vx=5.0, l1_p=15.0, l1_v=0.0, f_p=-20.0, f_v=5.0)


def follow_l1_to_stop() -> dict:
    """``L1`` 10 m ahead at 6 m/s brakes to a stop at 3 m/s² within the horizon; the ego matches its speed and
    follows it down to rest (Figure 3 case (d), code 4)."""
    return _evasion(ego_py=3.5, ego_vy=0.0, ego_vx=6.0, l1_p=10.0, l1_v=6.0, l1_decel=3.0, f_p=-20.0, f_v=6.0)


def follow_moving_l1() -> dict:
    """``L1`` 15 m ahead, 2 m/s slower, braking gently at 3 m/s²: the ego matches its speed and follows it, and
    ``L1`` still moves at ``t_y_f`` (Figure 3 case (c), code 3)."""
    return _evasion(ego_py=3.5, ego_vy=0.0, ego_vx=27.0, l1_p=15.0, l1_v=25.0, l1_decel=3.0)


def still_braking_at_horizon() -> dict:
    """``L1`` 25 m ahead at the ego's speed, braking at ``a_x_d``: the ego accelerates, then brakes, and is
    still braking (faster than ``L1``) when the lateral evasion ends (Figure 3 case (a), code 1)."""
    return _evasion(l1_p=25.0)


def collaborative_follower_stops_behind() -> dict:
    """A slow ego (3 m/s, fully in the target lane) with a collaborative follower 9 m behind at 6 m/s: braking
    at ``a_x_d`` the follower stops within the horizon, and the closest approach is where the speeds are equal —
    an interior point, not an end of the interval."""
    return _evasion(ego_py=3.5, ego_vy=0.0, ego_vx=3.0, l1_p=60.0, l1_v=10.0, f_p=-9.0, f_v=6.0)


def human_driven_follower_needs_larger_margin() -> dict:
    """An aggressive follower whose closest approach is about 8.6 m: enough for ``p_m = 7``, not for the
    ``p_m_human = 10`` of a connected human-driven follower (pass ``follower_human=True``)."""
    return _evasion(f_p=-12.5, f_v=27.0, follower_aggressive=True)


# --- chain scenarios --------------------------------------------------------------------------------------------


def chain_gap_below_margin() -> dict:
    """``L1`` is 6 m behind ``L2`` — already inside ``p_m``: the chain is unsafe and ``L1``'s worst case is
    ``a_x_d``."""
    return dict(p=[0.0, 6.0, 60.0], v=[25.0, 25.0, 25.0], promise_decel=[2.0, 2.0])


def connected_chain_absorbs_braking() -> dict:
    """Two connected leaders 35 m apart behind an unconnected ``L3`` braking at ``a_x_d``: each link needs less
    than the one ahead (``L2`` ≈ 4.66, ``L1`` ≈ 3.29 m/s²), so ``L1``'s worst case stays well below ``a_x_d``."""
    return dict(p=[0.0, 35.0, 70.0], v=[25.0, 25.0, 25.0], promise_decel=[3.0, 3.0])


def human_driven_link_needs_larger_margin() -> dict:
    """``L1`` 8.5 m behind ``L2``: safe with ``p_m = 7`` (``L1`` needs ≈ 7.70 m/s²), unsafe when ``L1`` is a
    connected human-driven vehicle keeping ``p_m_human = 10`` (pass ``human_driven=[True]``)."""
    return dict(p=[0.0, 8.5], v=[25.0, 25.0], promise_decel=[3.0])


def closing_fast_on_braking_leader() -> dict:
    """``L1`` closes at 10 m/s on ``L2`` 15 m ahead, which brakes at ``a_x_d``: ``L1`` would need
    ``8 + 10²/(2·8) = 14.25`` m/s² > ``a_x_d`` — the chain is unsafe (Eq. 2, first case)."""
    return dict(p=[0.0, 15.0], v=[30.0, 20.0], promise_decel=[3.0])


def unconnected_leader_only() -> dict:
    """``N = 0``: only the unconnected ``L1`` is known, so its worst case is ``a_x_d``."""
    return dict(p=[40.0], v=[25.0], promise_decel=np.zeros(0))


EVASION_SCENARIOS: dict[str, Callable[[], dict]] = {
    f.__name__: f
    for f in (
        open_gap_collaborative_follower,
        tight_gap_aggressive_follower,
        leader_braking_hard_close,
        already_back_in_lane,
        past_lane_boundary_returning_fast,
        ego_stops_before_horizon,
        follow_l1_to_stop,
        follow_moving_l1,
        still_braking_at_horizon,
        collaborative_follower_stops_behind,
        human_driven_follower_needs_larger_margin,
    )
}

CHAIN_SCENARIOS: dict[str, Callable[[], dict]] = {
    f.__name__: f
    for f in (
        chain_gap_below_margin,
        connected_chain_absorbs_braking,
        human_driven_link_needs_larger_margin,
        closing_fast_on_braking_leader,
        unconnected_leader_only,
    )
}

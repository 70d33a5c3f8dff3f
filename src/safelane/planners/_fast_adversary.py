"""The adversarial planners in the compiled closed loop (numba, extra ``fast``): :func:`adversary_row`, one row's
proposal from its kind and parameters (:func:`.adversarial.adversary_table`, the planner as data), by the planners'
own closed forms (:mod:`.adversarial`); the glue of :class:`~.adversarial.Mixture` per row, where the array path
evaluates every planner and keeps each row's. The same bits as calling the planner: ``tests/test_fast_adversary.py``.
"""

from __future__ import annotations

from ..safety import _compile
from ..safety._backend import SCALAR
from ..safety._fast_base import announce_compiles, row_function
from .adversarial import ZERO, hug_follower_accel, hug_leader_accel, lateral_pd, oscillating_accel, reckless_lateral

_compile.register_rows()
announce_compiles()


@row_function
def adversary_row(kind, q, b, t, p_x, p_y, v_x, v_y, p_x_l, v_x_l, p_x_f, v_x_f, p_m, lane_w, lim):
    """``(a_x, a_y)`` of row ``b`` (kind ``kind``, parameters ``q[b]``) observing the ego at ``(p_x, p_y, v_x, v_y)``,
    L1 at ``(p_x_l, v_x_l)`` and F at ``(p_x_f, v_x_f)`` at time ``t``, clipped to ``lim`` as ``clip_actions``."""
    if kind == ZERO:
        return 0.0, 0.0
    if kind == 2:
        a_x, a_y = oscillating_accel(SCALAR, t, q[b, 0], q[b, 1], q[b, 2], q[b, 3], q[b, 4], q[b, 5], q[b, 6])
    elif kind == 3:
        a_x, a_y = q[b, 0], reckless_lateral(SCALAR, q[b, 1], lim.a_y_m, lane_w, p_y)
    else:
        if kind == 0:
            a_x = hug_leader_accel(SCALAR, p_x, v_x, p_x_l, v_x_l, p_m, q[b, 2], q[b, 0], q[b, 1])
        else:
            a_x = hug_follower_accel(SCALAR, p_x, v_x, p_x_f, v_x_f, p_m, q[b, 2], q[b, 0], q[b, 1])
        a_y = lateral_pd(SCALAR, lane_w, p_y, v_y, q[b, 3], q[b, 4])
    return SCALAR.clip(a_x, -lim.a_x_d, lim.a_x_a), SCALAR.clip(a_y, -lim.a_y_m, lim.a_y_m)

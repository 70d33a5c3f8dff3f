"""Optional compiled decision of the rows under RSS's lane-change rule (numba, extra ``fast``): what
:meth:`safelane.baselines.rss_rule.RssRule.decide` does on arrays, one row at a time, for the shield's compiled period
(:func:`._fast_period.period_row`).

No rule lives here: the row calls the rule's closed forms (:mod:`safelane.baselines.rss_rule`: ``chain_brake_core``,
``ego_after_core``, ``ahead_after_core``, ``follower_after_core``, ``verdict_core``, ``lateral_core``,
``follow_check_accel``, ``follow_core``, ``completing_core``; RSS itself in :mod:`safelane.baselines.rss`) and reduces
over the chain with a loop where :class:`~safelane.baselines.rss_rule.RssRule` reduces with ``all``. That glue is the
one twin, and it is unavoidable: ``RssRule.decide`` evaluates whole rows with NumPy's array operations, which compiled
row code cannot call without allocating; every formula it applies is the closed forms' own. A row's RSS parameters
come as a float vector (:data:`RULE`: the rule flag, then :data:`~safelane.baselines.rss.RSS_FIELDS`), so rows of
several parameter sets run in one call. ``tests/test_fast_period.py`` and ``tests/test_fast_loop.py`` hold it to the
NumPy path bit for bit.
"""

from __future__ import annotations

import numba
import numpy as np

from ..baselines.rss import RSS_FIELDS, RssRecord
from ..baselines.rss_rule import (
    ahead_after_core,
    chain_brake_core,
    completing_core,
    ego_after_core,
    follow_check_accel,
    follow_core,
    follower_after_core,
    lateral_core,
    verdict_core,
)
from ..safety import _compile
from ..safety._backend import SCALAR
from .decide import ABORT, COMPLETED, HESITATE, PROCEED

_compile.register_rows()  # (no kernel of its own: the period's kernels compile these and announce it)

_INF = np.inf
#: Columns of a row's rule vector: whether RSS decides the row (``> 0``), then its parameters.
RULE = ("rss", *RSS_FIELDS)

#: Compiled out of line (not forced inline into the loop's period as the row functions are: most rows are the
#: paper's, and each kernel that inlines the period would compile this again); no reference counting.
_rule_function = numba.njit(error_model="numpy", nogil=True, _nrt=False)


@_rule_function
def _record(rule, b):
    """Row ``b``'s :class:`~safelane.baselines.rss.RssRecord`."""
    return RssRecord(rule[b, 1], rule[b, 2], rule[b, 3], rule[b, 4], rule[b, 5], rule[b, 6], rule[b, 7], rule[b, 8],
                     rule[b, 9], rule[b, 10])  # fmt: skip


@_rule_function
def _safe_after(rss, b, ego, a_x, a_y, chain_x, chain_v, f, bounds, nc, l1_decel, uses_chain, own, geometry):
    """:meth:`~safelane.baselines.rss_rule.RssRule.safe_after` of row ``b``: ``(safe towards every vehicle ahead, safe
    towards F, longitudinally safe towards every vehicle ahead)``. ``ego``: ``(x, y, vx, vy)``; ``f``: ``(x, v)``;
    ``own``: ``(L0's x, v, counted)``; ``geometry``: ``(dt, lane width, vehicle length, vehicle width)``."""
    dt, lane_w, length, width = geometry
    ex, ey, evx, evy = ego_after_core(SCALAR, ego[0], ego[1], ego[2], ego[3], a_x, a_y, dt)
    ok_ahead, lon_ok = True, True
    for j in range(chain_x.shape[1]):
        brake = chain_brake_core(SCALAR, j, uses_chain, nc, bounds[b, j], l1_decel, rss.brake_max)
        safe, lon = ahead_after_core(SCALAR, ex, ey, evx, evy, chain_x[b, j], chain_v[b, j], lane_w, brake, rss,
                                     length, width, dt)  # fmt: skip
        ok_ahead, lon_ok = ok_ahead and safe, lon_ok and lon
    to_f = follower_after_core(SCALAR, ex, ey, evx, evy, f[0], f[1], lane_w, rss, length, width, dt)
    if own[2]:  # L0 in the own lane (y = 0), until the change completes
        safe, lon = ahead_after_core(SCALAR, ex, ey, evx, evy, own[0], own[1], 0.0, rss.brake_max, rss, length, width,
                                     dt)  # fmt: skip
        ok_ahead, lon_ok = ok_ahead and safe, lon_ok and lon
    return ok_ahead, to_f, lon_ok


@_rule_function
def rule_row(rule, b, ego, chain_x, chain_v, f, bounds, nc, proposal, invalid, l1_decel, uses_chain, completed,
             own_leader, limits):  # fmt: skip
    """RSS's decision for row ``b`` (:meth:`~safelane.baselines.rss_rule.RssRule.decide` and
    :class:`~.rules.Coded`): ``(behaviour code, a_x, a_y, completing)``. ``proposal``: ``(a_x, a_y, the hesitation's
    a_y, the lane keeping's a_y)``; ``own_leader``: ``(L0's x, v)`` (``+inf``: none); ``limits``: ``(dt, lane width,
    vehicle length, vehicle width, a_x_d, a_y_m, y_boundary)``."""
    rss = _record(rule, b)
    dt, lane_w, length, width, a_d, a_ym, y_bound = limits
    a_x, a_y, a_yh, a_y_keep = proposal
    geometry = (dt, lane_w, length, width)
    own = (own_leader[0], own_leader[1], abs(own_leader[0]) < _INF and not completed)
    ok_chain, ok_f, _ = _safe_after(rss, b, ego, a_x, a_y, chain_x, chain_v, f, bounds, nc, l1_decel, uses_chain, own,
                                    geometry)  # fmt: skip
    ok_chain_h, ok_f_h, _ = _safe_after(rss, b, ego, a_x, a_yh, chain_x, chain_v, f, bounds, nc, l1_decel, uses_chain,
                                        own, geometry)  # fmt: skip
    proceed, hesitate, respond = verdict_core(SCALAR, not completed, invalid, ok_chain, ok_f, ok_chain_h, ok_f_h)
    a_y_cmd = lateral_core(SCALAR, proceed, hesitate, respond, completed, a_y, a_yh, a_y_keep, ego[1], ego[3], a_ym,
                           rss.lat_brake_min)  # fmt: skip
    a_x_cmd = a_x
    follow = respond or completed
    if follow:
        _, _, lon_ok = _safe_after(rss, b, ego, follow_check_accel(SCALAR, respond, a_x), a_y_cmd, chain_x, chain_v,
                                   f, bounds, nc, l1_decel, uses_chain, own, geometry)  # fmt: skip
        a_x_cmd = follow_core(SCALAR, follow, lon_ok, a_x, rss.brake_min, a_d)
    completing = completing_core(SCALAR, proceed, hesitate, ego[1], ego[3], a_y_cmd, dt, y_bound)
    code = COMPLETED
    if proceed:
        code = PROCEED
    elif hesitate:
        code = HESITATE
    elif respond:
        code = ABORT
    return code, a_x_cmd, a_y_cmd, completing

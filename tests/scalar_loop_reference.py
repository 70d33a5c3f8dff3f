"""The scalar closed loop (``scalar_loop.scenario_loop``) on the independent numeric reference. Test helper.

Every request of the loop is answered by ``tests/reference.py`` — time stepping with exact substeps and bisection,
nothing imported from ``safelane.safety`` and none of its closed forms:

* ``chain`` — :func:`reference.ref_leader_chain` (L1's worst case, Eqs. 1–3 by bisection on each link);
* ``plan`` — :func:`reference.ref_evasion_exists` for the verdict (Eqs. 4–9), and :class:`RefPlan` for the motion
  an abort executes: the reference's switch time, its profile time-stepped, and the lateral return as the plan
  documents it (brake the lateral speed, or bang-bang to ``y_s``);
* ``follow`` — :func:`reference.ref_min_follow_decel` (Eq. 3 by log-space bisection);
* ``responsible`` / ``leader`` — the definition of responsible following (``safelane.safety.responsible``'s
  docstring: one period at ``a``, the exact gap over it kept, then braking at ``brake`` keeps the margin against the
  vehicle ahead braking at ``d``), checked by time stepping and :func:`reference.ref_min_follow_decel`, and solved
  by bisection on ``a`` (the safe accelerations form an interval: a smaller ``a`` leaves the follower behind at every
  instant).

The library's documented tolerances are the only conventions shared with it (they are conventions, not maths):
gaps within ``1e-9`` m of a margin count as kept (``FEASIBILITY_TOL_M``), intrusions within ``1e-9`` m of ``y_s``
as none (``LATERAL_TOL_M``), a link's slack is read ``0.5`` nm generously (as ``reference.py`` does), and a responsible
acceleration is applied ``1e-9`` m/s² on the safe side.

:func:`reference_loop` runs many scenarios in lockstep: each round collects every live scenario's pending request
and answers all requests of one kind with one batched reference call (a reference call costs about the same for one
row as for a hundred).
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from reference import (
    BISECT_ITERS,
    _Profile,
    _simulate,
    follow_gap_margin,
    gap_minimum,
    integrate,
    ref_evasion_exists,
    ref_leader_chain,
    ref_min_follow_decel,
    time_nodes,
)
from safelane import Params
from scalar_loop import scenario_loop

TOL_M = 1e-9  # FEASIBILITY_TOL_M / LATERAL_TOL_M: the library's round-off conventions
ROOT_EPS = 1e-9  # responsible accelerations applied this far on the safe side


class RefPlan:
    """The reference evasion plan of one state: ``feasible`` and the planned ego ``state(t)`` (arrays of ``t``)."""

    def __init__(self, ev, row: int, args, prm: Params):
        self.prm = prm
        self.feasible = bool(ev.exists[row])
        self.ex, self.ey, self.evx, self.evy, self.lx, self.lv, self.l1_decel = (float(a) for a in args[:7])
        lon, lat = ev.longitudinal, ev.lateral
        self.T = float(lat.t_y_f[row])
        self.prof = tuple(float(np.asarray(getattr(lon.profile, f))[row]) for f in ("u", "brake_end", "l1_stop"))
        self.match = bool(lon.profile.match[row])
        # The lateral return as the plan documents it; an intrusion within TOL_M counts as none.
        a, v = prm.a_y_m, self.evy
        if float(lat.peak[row]) <= TOL_M:
            self.T = 0.0
            self.lat = ((0.0, 0.0), (-a if v > 0.0 else a, abs(v) / a))  # brake the lateral speed to rest
        elif int(lat.case[row]) == 1:
            self.lat = ((-a, float(lat.t_switch[row])), (a, self.T))  # bang-bang to y_s at rest
        else:
            self.lat = ((0.0, 0.0), (a, abs(v) / a))  # returning fast: brake the returning speed to rest

    def state(self, t):
        t = np.asarray(t, dtype=np.float64)
        k = t.size
        tt = np.minimum(t, self.T)
        prof = _Profile(*(np.full(k, x) for x in (self.prof[0], self.prof[1])), np.full(k, self.match),
                        np.full(k, self.prof[2]))  # fmt: skip
        one = (np.full(k, x) for x in (self.ex, self.evx, self.lx, self.lv, self.l1_decel))
        _, _, (pe, ve, _), _ = _simulate(prof, *one, tt, self.prm)
        vx = ve[:, -1]
        px = pe[:, -1] + vx * (t - tt)
        y, vy = np.full(k, self.ey), np.full(k, self.evy)
        start = np.zeros(k)
        for acc, end in self.lat:
            h = np.clip(np.minimum(t, end) - start, 0.0, None)
            y, vy = y + vy * h + 0.5 * acc * h * h, vy + acc * h
            start = np.maximum(start, end)
        return px, y, vx, vy


def _follow(prm: Params, slack, v_f, v_l, a_l):
    """Least deceleration of a follower ``slack`` beyond its margin behind a leader braking at ``a_l``."""
    slack = np.asarray(slack, dtype=np.float64)
    # The reference reads a slack of at most 0.5 nm half a nanometre generously itself (the shared convention).
    return ref_min_follow_decel(np.zeros_like(slack), v_f, slack, v_l, a_l, 0.0, prm.a_x_d).z


def _period_gap(prm: Params, slack, v_f, a_f, v_l, a_l):
    """Exact minimum over one period of ``x_l − x_f − margin`` (time-stepped, both stop rather than reverse)."""
    dt = np.full(slack.shape, prm.dt)
    events = [np.where(a < 0.0, v / np.maximum(-a, 1e-300), np.inf) for v, a in ((v_f, a_f), (v_l, a_l))]
    nodes = time_nodes(dt, events, 5)
    mid = 0.5 * (nodes[:, 1:] + nodes[:, :-1])
    acc_f = np.where(mid < events[0][:, None], a_f[:, None], 0.0)
    acc_l = np.where(mid < events[1][:, None], a_l[:, None], 0.0)
    pf, vf = integrate(nodes, np.zeros_like(slack), v_f, acc_f)
    pl, vl = integrate(nodes, slack, v_l, acc_l)
    g, _ = gap_minimum(nodes, pl, vl, acc_l, pf, vf, acc_f)
    return g, pf[:, -1], vf[:, -1], pl[:, -1], vl[:, -1]


def _keeps_margin(slack, v_f, v_l, d, brake):
    """Can a follower ``slack`` beyond its margin keep it by braking at ``brake`` while the leader brakes at ``d``?
    (Braking harder only helps, so this is Eq. 3's ``z <= brake``, checked by one time-stepped run.) Slack read as
    :func:`reference.ref_min_follow_decel` reads it (the shared half-nanometre convention)."""
    slack = np.where((slack >= -TOL_M) & (slack <= 0.5 * TOL_M), np.maximum(slack + 0.5 * TOL_M, 0.0), slack)
    close = (slack < 0.0) | ((slack <= 0.0) & (v_f > v_l))
    gap, *_ = follow_gap_margin(brake, np.zeros_like(slack), v_f, slack, v_l, d, 0.0)
    return ~close & (gap >= 0.0)


def _responsible_ok(prm: Params, a, slack, v_f, v_l, d, brake):
    g, xf, vf, xl, vl = _period_gap(prm, slack, v_f, a, v_l, -d)
    return (g >= -TOL_M) & _keeps_margin(xl - xf, vf, vl, d, brake)


def _responsible(prm: Params, wanted, slack, v_f, v_l, d, brake):
    """The largest ``a <= wanted`` passing the definition (bisection), ``ROOT_EPS`` on the safe side; ``-brake``
    where none down to ``-brake`` does."""
    ok = _responsible_ok(prm, wanted, slack, v_f, v_l, d, brake)
    out = wanted.copy()
    todo = ~ok
    if todo.any():
        idx = np.flatnonzero(todo)
        args = (slack[idx], v_f[idx], v_l[idx], d[idx], brake[idx])
        lo, hi = -brake[idx] - 1.0, wanted[idx]  # below -brake nothing matters: the answer is floored there
        for _ in range(BISECT_ITERS):
            mid = 0.5 * (lo + hi)
            good = _responsible_ok(prm, mid, *args)
            lo, hi = np.where(good, mid, lo), np.where(good, hi, mid)
        out[idx] = np.maximum(lo - ROOT_EPS, -brake[idx])
    return out


def reference_answers(prm: Params, kind: str, requests: list) -> list:
    """Answers to a list of same-kind requests, in one batched reference computation."""
    if kind == "chain":
        out = [None] * len(requests)
        by_n = defaultdict(list)
        for i, (x, *_rest) in enumerate(requests):
            by_n[len(x)].append(i)
        for rows in by_n.values():
            x, v, promise, human = (np.array([requests[i][k] for i in rows], dtype=dt)
                                    for k, dt in ((0, float), (1, float), (2, float), (3, bool)))  # fmt: skip
            chain = ref_leader_chain(x, v, promise, prm, human)
            for i, l1, bounds in zip(rows, chain.l1_decel, chain.decel, strict=True):
                out[i] = float(l1), bounds.tolist()
        return out
    if kind == "leaders":  # every leader of every request in one batch
        flat = [leader for req in requests for leader in req]
        accs = iter(reference_answers(prm, "leader", flat))
        return [[next(accs) for _ in req] for req in requests]
    cols = [np.array(c) for c in zip(*requests, strict=True)]
    if kind == "plan":
        *state, aggressive = cols
        margin = prm.p_m - TOL_M
        ev = ref_evasion_exists(*state, aggressive.astype(bool), prm, margin, margin)
        return [RefPlan(ev, i, req, prm) for i, req in enumerate(requests)]
    if kind == "follow":
        return [float(z) for z in _follow(prm, *cols)]
    if kind in ("responsible", "leader"):
        cols = [c.astype(np.float64) for c in cols]
        if kind == "responsible":
            cols.append(np.full(len(requests), prm.a_x_d))
        return [float(a) for a in _responsible(prm, *cols)]
    raise ValueError(f"unknown request {kind!r}")


def reference_loop(scenarios, prm: Params, steps: int, **behaviour) -> list[dict]:
    """``scenario_loop`` for each ``(batch, row)`` of ``scenarios``, all in lockstep on the reference; the outcome
    rows in the same order."""
    loops = {i: scenario_loop(b, row, prm, steps, **behaviour) for i, (b, row) in enumerate(scenarios)}
    pending = {i: next(loop) for i, loop in loops.items()}
    done = {}
    while pending:
        by_kind = defaultdict(list)
        for i, (kind, _) in pending.items():
            by_kind[kind].append(i)
        for kind, ids in by_kind.items():
            answers = reference_answers(prm, kind, [pending[i][1] for i in ids])
            for i, answer in zip(ids, answers, strict=True):
                try:
                    pending[i] = loops[i].send(answer)
                except StopIteration as end:
                    done[i] = end.value
                    del pending[i]
    return [done[i] for i in range(len(scenarios))]

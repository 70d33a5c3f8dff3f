"""Exact motion within one control period and the exact extrema of gaps between two motions.

Every vehicle's longitudinal acceleration is piecewise constant; a braking vehicle stops and stays at rest
(speed never goes negative). A *motion* over one period ``[0, dt]`` is stored as knots: times
``t (..., K+1)`` from 0 to ``dt``, positions/speeds at the knots and one acceleration per segment. Gap
extrema between two motions are exact: on each interval of the merged knots the gap is one quadratic, so
its extrema lie at the knots or at the vertex.

**One source.** The arithmetic per instant, per segment and per interval — one vehicle's segment at constant
acceleration with stopping (:func:`constant_segment`), the state at a time (:func:`state_at`), a segment's
acceleration from its end speeds (:func:`piece_acc`), the extrema of one quadratic piece (:func:`vertex_extrema`,
:func:`piece_extrema`), the instants a segment crosses a level (:func:`segment_crossings`) and one interval of a
windowed gap (:func:`windowed_piece`) — is written once against the backend ``xp`` (:mod:`safelane.safety._backend`)
and marked ``jitable``: the functions below evaluate it on NumPy arrays (every knot, segment and interval of a batch
at once), the compiled checks (:mod:`._fast_general`, :mod:`._fast_checks`, the compiled closed loop) per row. What
stays apart is structure: here the knots of a batch are merged with ``np.sort`` and a time's segment found by
counting knots; a compiled row merges its knots into scratch and walks them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._motion import piece_acc, stop_time, stop_time_core
from ..safety._backend import ARRAY, INF, jitable

__all__ = [
    "Fleet",
    "Motion",
    "constant_segment",
    "crossing_knots",
    "extrema",
    "gap_extrema",
    "piece_acc",
    "piece_extrema",
    "segment_crossings",
    "state_at",
    "vertex_extrema",
    "windowed_gap_extrema",
    "windowed_piece",
]


@dataclass(frozen=True)
class Motion:
    """Piecewise-constant-acceleration motion over one period (knots on the last axis)."""

    t: np.ndarray  # (..., K+1) knot times, ascending, t[..., 0] = 0, t[..., -1] = dt
    x: np.ndarray  # (..., K+1) positions at the knots
    v: np.ndarray  # (..., K+1) speeds at the knots
    acc: np.ndarray  # (..., K) acceleration on each segment

    @classmethod
    def constant(cls, x, v, a, dt) -> Motion:
        """Constant acceleration with stopping: knots ``0, t_stop, dt`` (a vehicle already at rest that "brakes"
        simply stays: one segment of zero acceleration). The knots of :meth:`Fleet.constant`."""
        x, v, a = np.broadcast_arrays(np.asarray(x, float), np.asarray(v, float), np.asarray(a, float))
        return Fleet.constant(x, v, a, dt).motion(...)

    @classmethod
    def free(cls, x, v, a, dt) -> Motion:
        """Constant acceleration without stopping (lateral motion): knots ``0, dt``."""
        x, v, a = np.broadcast_arrays(np.asarray(x, float), np.asarray(v, float), np.asarray(a, float))
        t = np.stack([np.zeros_like(x), np.full_like(x, dt)], -1)
        x1, v1 = x + v * dt + 0.5 * a * dt * dt, v + a * dt
        return cls(t=t, x=np.stack([x, x1], -1), v=np.stack([v, v1], -1), acc=a[..., None])

    @classmethod
    def from_samples(cls, t, x, v) -> Motion:
        """Knots from exact samples of a piecewise-constant-acceleration motion whose switches are knots."""
        return cls(t=t, x=x, v=v, acc=piece_acc(ARRAY, v[..., :-1], v[..., 1:], np.diff(t, axis=-1)))

    def at(self, tq):
        """Exact ``(x, v)`` at query times ``tq (..., Q)`` (broadcast against the motion's batch)."""
        inner = self.t[..., 1:-1]
        seg = (inner[..., None, :] <= tq[..., :, None]).sum(-1)
        seg, t = np.broadcast_arrays(seg, tq)
        batch = seg.shape[:-1]

        def pick(arr):
            return np.take_along_axis(np.broadcast_to(arr, (*batch, arr.shape[-1])), seg, -1)

        return state_at(ARRAY, pick(self.x), pick(self.v), pick(self.acc), t - pick(self.t))

    @property
    def end(self):
        return self.x[..., -1], self.v[..., -1]


@dataclass(frozen=True)
class Fleet:
    """Many vehicles each at one constant acceleration with stopping over the period, as flat per-vehicle arrays
    (any shape, e.g. ``(B, K)`` column-major): :meth:`Motion.constant`'s numbers without its stacked knots,
    which are built by :meth:`motion` only for the entries that need them."""

    x: np.ndarray
    v: np.ndarray
    acc: np.ndarray  # 0 for a vehicle already at rest
    t_stop: np.ndarray  # dt where it does not stop inside the period
    x_end: np.ndarray
    v_end: np.ndarray
    dt: float
    #: ``None``, or the second segment of vehicles whose acceleration switches inside the period (L(N+1)'s
    #: profiles): :class:`Switch`. Those entries are two segments; ``acc``/``t_stop`` describe the first.
    switch: Switch | None = None

    @property
    def switching(self) -> np.ndarray | None:
        """Mask of the entries with a switch inside the period (``None`` when there are none)."""
        return None if self.switch is None else self.switch.mask

    @classmethod
    def constant(cls, x, v, a, dt: float) -> Fleet:
        """Each entry at its constant acceleration ``a`` with stopping: :func:`constant_segment`."""
        with np.errstate(over="ignore"):  # a vanishing deceleration: v / tiny -> inf, then capped at dt
            acc, ts, xs, vs = constant_segment(ARRAY, x, v, a, dt)
        return cls(x=x, v=v, acc=acc, t_stop=ts, x_end=xs, v_end=vs, dt=dt)

    @classmethod
    def switched(cls, x, v, a1, t_switch, a2, dt: float) -> Fleet:
        """Like :meth:`constant`, but entries with ``t_switch < dt`` change to ``a2`` at ``t_switch`` (exactly, with
        stopping in either segment; a vehicle at rest stays at rest unless ``a2 > 0``)."""
        mask = t_switch < dt
        if not mask.any():
            return cls.constant(x, v, a1, dt)
        first = cls.constant(x, v, a1, dt)
        # The first segment ends at the switch: the state there, then the second segment to the period's end.
        ts1 = np.minimum(first.t_stop, t_switch)
        x_sw = x + v * ts1 + 0.5 * first.acc * ts1 * ts1
        v_sw = np.where(first.t_stop <= t_switch, 0.0, np.maximum(v + first.acc * ts1, 0.0))  # stopped: exactly 0
        rest = np.maximum(dt - t_switch, 0.0)
        ts2 = stop_time(v_sw, a2, rest)
        at_rest = ts2 <= 0.0
        acc2, ts2 = np.where(at_rest, 0.0, a2), np.where(at_rest, rest, ts2)
        x2 = x_sw + v_sw * ts2 + 0.5 * acc2 * ts2 * ts2
        v2 = np.where(ts2 < rest, 0.0, np.maximum(v_sw + acc2 * ts2, 0.0))
        sw = Switch(mask=mask, t=np.where(mask, t_switch, dt), x=x_sw, v=v_sw, acc=acc2, t_stop=t_switch + ts2)
        return cls(
            x=x,
            v=v,
            acc=first.acc,
            t_stop=np.where(mask, ts1, first.t_stop),
            x_end=np.where(mask, x2, first.x_end),
            v_end=np.where(mask, v2, first.v_end),
            dt=dt,
            switch=sw,
        )

    @property
    def end(self):
        return self.x_end, self.v_end

    @property
    def max_abs_acc(self) -> float:
        """The largest ``|acceleration|`` of any entry in any segment (for the near-pair filters)."""
        top = float(np.abs(self.acc).max(initial=0.0))
        if self.switch is not None:
            top = max(top, float(np.abs(self.switch.acc[self.switch.mask]).max(initial=0.0)))
        return top

    def row_max_abs_acc(self) -> np.ndarray:
        """:attr:`max_abs_acc` per row of a ``(B, K)`` fleet: ``(B,)``."""
        top = np.abs(self.acc).max(1, initial=0.0)
        if self.switch is not None:
            top = np.maximum(top, np.abs(np.where(self.switch.mask, self.switch.acc, 0.0)).max(1, initial=0.0))
        return top

    def motion(self, *idx) -> Motion:
        """The :class:`Motion` (knots ``0, t_stop, dt``) of the entries ``self.x[idx]`` (``...`` for all). After
        the stop knot the vehicle is at rest (or, if it never stops, the stop knot is ``dt`` itself). With switches
        in the fleet, every motion has the knots ``0, t_stop1, t_switch, t_stop2, dt`` (repeated where unused)."""
        ts, xs, vs = self.t_stop[idx], self.x_end[idx], self.v_end[idx]
        if self.switch is None:
            return Motion(
                t=np.stack([np.zeros_like(ts), ts, np.full_like(ts, self.dt)], -1),
                x=np.stack([self.x[idx], xs, xs], -1),
                v=np.stack([self.v[idx], vs, vs], -1),
                acc=np.stack([self.acc[idx], np.zeros_like(ts)], -1),
            )
        sw = self.switch
        on = sw.mask[idx]
        t_sw = np.where(on, sw.t[idx], self.dt)
        x_sw = np.where(on, sw.x[idx], xs)
        v_sw = np.where(on, sw.v[idx], vs)
        ts2 = np.where(on, sw.t_stop[idx], self.dt)
        zero = np.zeros_like(ts)
        return Motion(
            t=np.stack([zero, ts, t_sw, ts2, np.full_like(ts, self.dt)], -1),
            # From the first segment's end (its stop or the switch) the vehicle rests until the switch: the state
            # at both knots is the state at the switch.
            x=np.stack([self.x[idx], x_sw, x_sw, xs, xs], -1),
            v=np.stack([self.v[idx], v_sw, v_sw, vs, vs], -1),
            acc=np.stack([self.acc[idx], zero, np.where(on, sw.acc[idx], 0.0), zero], -1),
        )


@dataclass(frozen=True)
class Switch:
    """The second segment of :meth:`Fleet.switched` entries (arrays shaped like the fleet's)."""

    mask: np.ndarray  # a switch inside the period
    t: np.ndarray  # switch instant (dt where none)
    x: np.ndarray  # state at the switch
    v: np.ndarray
    acc: np.ndarray  # acceleration after it (0 for a vehicle at rest)
    t_stop: np.ndarray  # stop instant in the second segment (dt where it does not stop)


def gap_extrema(behind: Motion, ahead: Motion):
    """Exact ``(min, max)`` over the period of ``ahead.x(t) − behind.x(t)``."""
    batch = np.broadcast_shapes(behind.t.shape[:-1], ahead.t.shape[:-1])
    parts = [np.broadcast_to(m.t, (*batch, m.t.shape[-1])) for m in (behind, ahead)]
    knots = np.sort(np.concatenate(parts, -1), -1)
    xa, va = ahead.at(knots)
    xb, vb = behind.at(knots)
    return _extrema(knots, xa - xb, va - vb)


def extrema(m: Motion):
    """Exact ``(min, max)`` of ``m.x`` over the period."""
    return _extrema(m.t, m.x, m.v)


def _extrema(knots, d, dv):
    span = np.diff(knots, axis=-1)
    rel_acc = piece_acc(ARRAY, dv[..., :-1], dv[..., 1:], span)
    vertex_lo, vertex_hi = vertex_extrema(ARRAY, d[..., :-1], dv[..., :-1], rel_acc, span)
    return np.minimum(d.min(-1), vertex_lo.min(-1)), np.maximum(d.max(-1), vertex_hi.max(-1))


def crossing_knots(m: Motion, level: float) -> np.ndarray:
    """``m``'s knots plus every instant where ``m.x`` crosses ``level`` (sorted; unused slots repeat a knot).

    Between consecutive returned knots ``m.x − level`` has a constant sign.
    """
    extra = segment_crossings(ARRAY, m.t[..., :-1], np.diff(m.t, axis=-1), m.x[..., :-1], m.v[..., :-1], m.acc, level)
    return np.sort(np.concatenate([m.t, *extra], -1), -1)


def windowed_gap_extrema(behind: Motion, ahead: Motion, lateral: Motion, lateral_knots, level: float):
    """Exact ``(min, max)`` of ``ahead.x − behind.x`` over the instants of the period where ``lateral.x > level``
    (``(inf, −inf)`` where there are none). ``lateral_knots`` comes from :func:`crossing_knots`."""
    batch = np.broadcast_shapes(behind.t.shape[:-1], ahead.t.shape[:-1], lateral_knots.shape[:-1])
    parts = [np.broadcast_to(k, (*batch, k.shape[-1])) for k in (behind.t, ahead.t, lateral_knots)]
    knots = np.sort(np.concatenate(parts, -1), -1)
    y_mid = lateral.at(0.5 * (knots[..., :-1] + knots[..., 1:]))[0]
    xa, va = ahead.at(knots)
    xb, vb = behind.at(knots)
    d, dv = xa - xb, va - vb
    lo, hi = windowed_piece(ARRAY, d[..., :-1], dv[..., :-1], d[..., 1:], dv[..., 1:], np.diff(knots, axis=-1),
                            y_mid, level)  # fmt: skip
    return lo.min(-1), hi.max(-1)


def constant_segment(xp, x, v, a, dt):
    """One vehicle over the period at constant acceleration ``a`` from ``(x, v)``, stopping at rest:
    ``(acc, t_stop, x_end, v_end)`` — the acceleration of its first segment (0 for a vehicle already at rest that
    "brakes": it stays), the instant it stops (``dt`` where it does not stop inside the period) and its state at
    ``dt``. :meth:`Fleet.constant`'s numbers; backend-generic (the compiled closed loop's vehicles, row by row)."""
    ts = stop_time_core(xp, v, a, dt)
    at_rest = ts <= 0.0
    acc, ts = xp.where(at_rest, 0.0, a), xp.where(at_rest, dt, ts)
    xs = x + v * ts + 0.5 * acc * ts * ts
    vs = xp.where(ts < dt, 0.0, xp.maximum(v + acc * ts, 0.0))
    return acc, ts, xs, vs


def state_at(xp, x, v, a, tau):
    """``(x, v)`` a time ``tau`` into a segment at constant acceleration ``a`` that starts at ``(x, v)``.
    Backend-generic; every argument broadcasts."""
    return x + v * tau + 0.5 * a * tau * tau, v + a * tau


def vertex_extrema(xp, d0, dv0, acc, span):
    """The vertex of ``d0 + dv0 t + acc t²/2`` as a candidate ``(min, max)`` over ``0 < t < span``: the vertex where
    it lies strictly inside and is a minimum (``acc > 0``), else ``inf``; where it is a maximum (``acc < 0``), else
    ``−inf``. Backend-generic."""
    tau = xp.div(-dv0, acc, -1.0)
    inside = (tau > 0.0) & (tau < span)
    vertex = d0 + dv0 * tau + 0.5 * acc * tau * tau
    return xp.where(inside & (acc > 0.0), vertex, INF), xp.where(inside & (acc < 0.0), vertex, -INF)


def piece_extrema(xp, d0, dv0, d1, acc, span):
    """Exact ``(min, max)`` over ``[0, span]`` of one quadratic piece ``d0 + dv0 t + acc t²/2`` that ends at ``d1``:
    its ends and its vertex. Backend-generic."""
    vertex_lo, vertex_hi = vertex_extrema(xp, d0, dv0, acc, span)
    return xp.minimum(xp.minimum(d0, d1), vertex_lo), xp.maximum(xp.maximum(d0, d1), vertex_hi)


def windowed_piece(xp, d0, dv0, d1, dv1, span, y_mid, level):
    """One interval of :func:`windowed_gap_extrema` (between consecutive merged knots, the gap ``d`` with rate ``dv``
    at its ends): its :func:`piece_extrema` where the lateral position at its midpoint ``y_mid`` is above ``level``
    (the whole interval is then: no crossing lies inside it), else ``(inf, −inf)``. Backend-generic."""
    lo, hi = piece_extrema(xp, d0, dv0, d1, piece_acc(xp, dv0, dv1, span), span)
    active = y_mid > level
    return xp.where(active, lo, INF), xp.where(active, hi, -INF)


def segment_crossings(xp, t0, span, x0, v0, a, level):
    """The two instants at which a segment starting at time ``t0`` in state ``(x0, v0)`` with acceleration ``a``
    crosses ``level`` strictly inside it (``0 < t − t0 < span``), each replaced by ``t0`` where there is no such
    root: the extra knots of :func:`crossing_knots`. Backend-generic."""
    y0 = x0 - level
    disc = v0 * v0 - 2.0 * a * y0
    root = xp.sqrt(disc)
    quad = (a != 0.0) & (disc >= 0.0)
    lin = (a == 0.0) & (v0 != 0.0)
    r1 = xp.where(quad, xp.div(-v0 - root, a, -1.0), xp.where(lin, xp.div(-y0, v0, -1.0), -1.0))
    r2 = xp.where(quad, xp.div(-v0 + root, a, -1.0), -1.0)
    return xp.where((r1 > 0.0) & (r1 < span), t0 + r1, t0), xp.where((r2 > 0.0) & (r2 < span), t0 + r2, t0)


# The per-instant, per-segment and per-interval arithmetic, compiled into the checks' kernels (safety/_compile.py).
jitable(constant_segment, state_at, piece_acc, vertex_extrema, piece_extrema, windowed_piece, segment_crossings)

"""A command as the shield issues it, and the commands in flight under an actuation delay — one type for the shield
(which carries the ego over the commands in flight before it decides, :mod:`.stages`) and for every host that
executes them (the simulator, highway-env, SUMO).

A :class:`Command` holds, per row, the acceleration at the period's start and, for the rows that abort, the held
plan's exact knots over the period with the constant accelerations between them (a plan switches inside a period).
Its :meth:`~Command.piece` is the same command as piecewise-constant accelerations ``(dur, a_x, a_y)``, arrays
``(B, S)`` (S segments: an abort's knots less one — 7 for the shield's plans; the other rows one segment of the
whole period and empty ones; S = 1 where no row aborts), and
:meth:`~Command.carry` moves an ego over it exactly (stopping rather than reversing), one segment at a time by
:func:`segment_core`, the one source of that motion (the compiled period, ``_fast_period.carried_ego``, calls it per
row). :class:`InFlight` is the queue of commands issued but not acting yet, oldest first; both select and join rows
(:meth:`Command.take`, :meth:`Command.join`: a shield over vehicles that come and go, :mod:`.rows`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._motion import advance_core, piece_acc
from ..safety._backend import ARRAY, jitable


@dataclass(frozen=True)
class Command:
    """One period's command for ``B`` rows (see the module docstring)."""

    a_x: np.ndarray  # (B,) longitudinal acceleration at the period's start [m/s²]
    a_y: np.ndarray  # (B,) lateral
    rows: np.ndarray  # (R,) rows following their held plan over the period (aborting)
    knots: np.ndarray | None  # (R, S + 1) the plan's knots, relative to the period's start; None when R == 0
    ax_seg: np.ndarray | None  # (R, S) the accelerations between the knots (0 on zero-length segments)
    ay_seg: np.ndarray | None
    completing: np.ndarray  # (B,) the command completes the lane change

    @classmethod
    def idle(cls, batch: int) -> Command:
        """Zero acceleration, not completing: what acts before the first issued command under actuation delay."""
        zero = np.zeros(batch)
        return cls(zero, zero, np.zeros(0, np.intp), None, None, None, np.zeros(batch, bool))

    @classmethod
    def issued(cls, a_x, a_y, abort, completing) -> Command:
        """From the shield's commands: ``abort`` is the aborting rows' exact motion ``(rows, knots, px, vx, py, vy)``
        (:meth:`~.decision.Decision.abort_motion`)."""
        rows, knots, _, vx, _, vy = abort
        ax_seg = ay_seg = None
        if rows.size:
            span = np.diff(knots, axis=-1)
            ax_seg = piece_acc(ARRAY, vx[..., :-1], vx[..., 1:], span)
            ay_seg = piece_acc(ARRAY, vy[..., :-1], vy[..., 1:], span)
        return cls(a_x, a_y, rows, knots, ax_seg, ay_seg, completing)

    @classmethod
    def of(cls, decision) -> Command:
        """The command a :class:`~.decision.Decision` issues."""
        return cls.issued(decision.a_x, decision.a_y, decision.abort_motion(), decision.completing)

    def piece(self, dt: float):
        """``(dur, a_x, a_y)``, each ``(B, S)``: the command as piecewise-constant accelerations."""
        n = len(self.a_x)
        segments = self.knots.shape[1] - 1 if self.rows.size else 1
        dur = np.zeros((n, segments))
        dur[:, 0] = dt
        ax, ay = np.repeat(self.a_x[:, None], segments, 1), np.repeat(self.a_y[:, None], segments, 1)
        if self.rows.size:
            dur[self.rows] = np.diff(self.knots, axis=-1)
            ax[self.rows], ay[self.rows] = self.ax_seg, self.ay_seg
        return dur, ax, ay

    def carry(self, ex, ey, evx, evy, dt: float):
        """The ego's state ``(x, y, vx, vy)`` after the command has acted for one period (exact; it stops rather
        than reverses)."""
        dur, ax, ay = self.piece(dt)
        return tuple(states[-1] for states in segment_states((ex, ey, evx, evy), dur, ax, ay))

    def plan_samples(self, ex, ey, evx, evy):
        """``(px, py, vx, vy)``, each ``(R, K)``: the aborting rows' exact states at their knots, from the ego's state
        (the rows of ``self.rows``; its knots' durations and accelerations)."""
        r = self.rows
        dur = np.diff(self.knots, axis=-1)
        return tuple(np.stack(s, -1) for s in segment_states((ex[r], ey[r], evx[r], evy[r]), dur, self.ax_seg,
                                                              self.ay_seg))  # fmt: skip

    def take(self, rows) -> Command:
        """The rows ``rows`` (indices) only, in that order (an aborting row keeps its knots)."""
        rows = np.asarray(rows, np.intp)
        slot = np.full(len(self.a_x), -1, np.intp)
        slot[self.rows] = np.arange(self.rows.size)
        src = slot[rows]
        kept = np.flatnonzero(src >= 0)
        src = src[kept]
        knots, ax_seg, ay_seg = (None, None, None) if not kept.size else (self.knots[src], self.ax_seg[src],
                                                                          self.ay_seg[src])  # fmt: skip
        return Command(self.a_x[rows], self.a_y[rows], kept, knots, ax_seg, ay_seg, self.completing[rows])

    def join(self, other: Command) -> Command:
        """These rows, then ``other``'s (aborting rows of both: the same number of knots)."""
        parts = [c for c in (self, other) if c.rows.size]
        if len(parts) == 2 and self.knots.shape[1] != other.knots.shape[1]:
            raise ValueError("Command.join: the aborting rows of the two commands have different numbers of knots")
        rows = np.concatenate([self.rows, other.rows + len(self.a_x)]).astype(np.intp)
        knots, ax_seg, ay_seg = (None, None, None) if not parts else (
            np.concatenate([c.knots for c in parts]), np.concatenate([c.ax_seg for c in parts]),
            np.concatenate([c.ay_seg for c in parts]))  # fmt: skip
        return Command(np.concatenate([self.a_x, other.a_x]), np.concatenate([self.a_y, other.a_y]), rows, knots,
                       ax_seg, ay_seg, np.concatenate([self.completing, other.completing]))  # fmt: skip


def segment_states(ego, dur, ax, ay):
    """``(xs, ys, vxs, vys)``: lists of the states at the start and after each of the piecewise-constant segments
    ``(dur, ax, ay)``, arrays ``(B, S)`` (exact; longitudinally it stops rather than reverses, laterally it is
    free)."""
    x, y, vx, vy = ([q] for q in ego)
    for k in range(dur.shape[1]):
        with np.errstate(over="ignore"):  # (as _motion.advance: a vanishing deceleration stops at the horizon)
            x1, y1, v1, vy1 = segment_core(ARRAY, x[-1], y[-1], vx[-1], vy[-1], dur[:, k], ax[:, k], ay[:, k])
        x.append(x1)
        y.append(y1)
        vx.append(v1)
        vy.append(vy1)
    return x, y, vx, vy


def segment_core(xp, x, y, vx, vy, h, a_x, a_y):
    """``(x, y, vx, vy)`` after one segment of length ``h`` at constant accelerations ``(a_x, a_y)``: exact;
    longitudinally it stops rather than reverses (:func:`~safelane._motion.advance_core`), laterally it is free.
    Backend-generic, the one source of a command's motion (:func:`segment_states` on arrays, the compiled period per
    row)."""
    x1, vx1 = advance_core(xp, x, vx, a_x, h)
    return x1, y + vy * h + 0.5 * a_y * h * h, vx1, vy + a_y * h


@dataclass(frozen=True)
class InFlight:
    """The commands issued but not acting yet (actuation delay), oldest first."""

    commands: tuple

    @classmethod
    def idle(cls, batch: int, periods: int) -> InFlight:
        """``periods`` commands of zero acceleration (the ego cruising when the shield starts)."""
        return cls(commands=(Command.idle(batch),) * periods)

    def push(self, command: Command) -> tuple[Command, InFlight]:
        """Issue ``command``: ``(the oldest command, which acts now, the queue with command appended)``."""
        return self.commands[0], InFlight(commands=(*self.commands[1:], command))

    def carry(self, ex, ey, evx, evy, dt: float):
        """The ego's state after all commands in flight have acted (exact)."""
        for command in self.commands:
            ex, ey, evx, evy = command.carry(ex, ey, evx, evy, dt)
        return ex, ey, evx, evy

    def take(self, rows) -> InFlight:
        """The rows ``rows`` of every command (:meth:`Command.take`)."""
        return InFlight(commands=tuple(c.take(rows) for c in self.commands))

    def join(self, other: InFlight) -> InFlight:
        """These rows, then ``other``'s, command by command (both queues as long)."""
        if len(self.commands) != len(other.commands):
            raise ValueError("InFlight.join: the two queues hold different numbers of commands")
        return InFlight(commands=tuple(a.join(b) for a, b in zip(self.commands, other.commands, strict=True)))


jitable(segment_core)

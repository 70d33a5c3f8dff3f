"""A command as the shield issues it, and the commands in flight under an actuation delay — one type for the shield
(which carries the ego over the commands in flight before it decides, :mod:`.stages`) and for every host that
executes them (the simulator, highway-env, SUMO).

A :class:`Command` holds, per row, the acceleration at the period's start and, for the rows that abort, the held
plan's exact knots over the period with the constant accelerations between them (a plan switches inside a period).
Its :meth:`~Command.piece` is the same command as piecewise-constant accelerations ``(dur, a_x, a_y)``, arrays
``(B, S)`` (S segments: an abort's knots less one — 7 for the shield's plans; the other rows one segment of the
whole period and empty ones; S = 1 where no row aborts), and
:meth:`~Command.carry` moves an ego over it exactly (stopping rather than reversing). :class:`InFlight` is the
queue of commands issued but not acting yet, oldest first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._motion import advance


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
            safe = np.where(span > 0.0, span, 1.0)
            ax_seg = np.where(span > 0.0, np.diff(vx, axis=-1) / safe, 0.0)
            ay_seg = np.where(span > 0.0, np.diff(vy, axis=-1) / safe, 0.0)
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


def segment_states(ego, dur, ax, ay):
    """``(xs, ys, vxs, vys)``: lists of the states at the start and after each of the piecewise-constant segments
    ``(dur, ax, ay)``, arrays ``(B, S)`` (exact; longitudinally it stops rather than reverses, laterally it is
    free)."""
    x, y, vx, vy = ([q] for q in ego)
    for k in range(dur.shape[1]):
        h = dur[:, k]
        x1, v1 = advance(x[-1], vx[-1], ax[:, k], h)
        x.append(x1)
        vx.append(v1)
        y.append(y[-1] + vy[-1] * h + 0.5 * ay[:, k] * h * h)
        vy.append(vy[-1] + ay[:, k] * h)
    return x, y, vx, vy


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

"""V2X messages of connected vehicles and their conversion into the leader-chain arrays (paper §3.2).

Every control period a connected vehicle broadcasts a :class:`V2XMessage`: its state, its promised
acceleration range ``[-a_m_d, a_m_a]`` (``promise_decel``, ``promise_accel``; magnitudes in m/s²) and its
planned accelerations. Messages are validated on construction; limits that depend on :class:`Params` are
checked by :meth:`V2XMessage.check_limits` (every converter here calls it).

Conservative fallback: a message older than ``max_age_s`` (default :data:`MAX_AGE_S`) at the ego's time
``now_s`` does not count — its sender is treated as NON-connected, which stops the leader chain there (it becomes
``L(N+1)``, assumed to brake at ``a_x_d``). Results say so (``stale_ids``, ``reason``). A vehicle known only from
a stale message or the ego's sensors is moved to ``now_s`` as if it had braked at ``a_x_d`` since then — the
lowest position and speed it can have, hence the worst case for everyone behind it. See ``docs/v2x.md``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator, model_validator

from ._motion import advance
from .params import Params
from .tolerances import TIME_TOL_S

MAX_AGE_S = 0.3
"""Default maximum message age [s]: three control periods (``dt = 0.1`` s). One lost message is tolerated twice
over; beyond that, extrapolating with a reported acceleration the sender is no longer bound to is not trusted."""

_TIME_TOL_S = TIME_TOL_S  # times on the dt grid (e.g. 1.0 − 0.7) are not exact in float64
_PAD_GAP_M = 1e6  # padding vehicles sit this far apart ahead of L(N+1): far enough never to constrain it

Intent = Literal["collaborative", "aggressive"]


class V2XMessage(BaseModel):
    """One broadcast of a connected vehicle. Frozen; unknown fields, NaN and inf are errors.

    ``planned_accel`` holds the planned accelerations [m/s²] at the control period ``Params.dt`` over the
    sender's planning horizon (may be empty); each lies within the promise. The reported ``accel_mps2`` need
    not: a vehicle may brake beyond its promise when its own safety requires it (an expected violation).
    """

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    vehicle_id: str = Field(min_length=1, description="Sender's id, unique among the vehicles in one batch.")
    timestamp_s: float = Field(description="Time the state was measured [s], on the ego's clock.")
    position_m: float = Field(description="Longitudinal position of the reference point (centre) [m].")
    speed_mps: float = Field(ge=0.0, description="Longitudinal speed [m/s].")
    accel_mps2: float = Field(description="Current longitudinal acceleration, signed [m/s²].")
    promise_decel: float = Field(ge=0.0, description="Promised maximum deceleration a_m_d >= 0 [m/s²].")
    promise_accel: float = Field(ge=0.0, description="Promised maximum acceleration a_m_a >= 0 [m/s²].")
    planned_accel: tuple[float, ...] = Field((), description="Planned accelerations at period dt [m/s²].")
    human_driven: bool = Field(description="True for a connected human-driven vehicle, False for autonomous.")
    intent: Intent | None = Field(None, description="Declared attitude towards a lane change ahead of it.")

    @field_validator("planned_accel", mode="before")
    @classmethod
    def _array_to_tuple(cls, value):
        return tuple(value.tolist()) if isinstance(value, np.ndarray) else value

    @model_validator(mode="after")
    def _check(self, info: ValidationInfo) -> V2XMessage:
        for k, a in enumerate(self.planned_accel):
            if not -self.promise_decel <= a <= self.promise_accel:
                raise ValueError(
                    f"planned_accel[{k}]={a!r} of vehicle {self.vehicle_id!r} lies outside the promise "
                    f"[-promise_decel, promise_accel] = [{-self.promise_decel}, {self.promise_accel}]"
                )
        params = (info.context or {}).get("params")
        return self.check_limits(params) if params is not None else self

    def check_limits(self, params: Params) -> V2XMessage:
        """Raise ``ValueError`` if the promise is wider than the mechanical limits; return ``self``."""
        for name, limit in (("promise_decel", "a_x_d"), ("promise_accel", "a_x_a")):
            if getattr(self, name) > getattr(params, limit):
                raise ValueError(
                    f"{name}={getattr(self, name)!r} of vehicle {self.vehicle_id!r} exceeds the mechanical "
                    f"limit {limit}={getattr(params, limit)}"
                )
        return self

    def age_s(self, now_s: float) -> float:
        """Age of the message at ``now_s`` [s]; ``ValueError`` if it comes from the future."""
        return _age(self, now_s)


class SensedVehicle(BaseModel):
    """A vehicle known only from the ego's own sensors (non-connected): state at ``timestamp_s``."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    vehicle_id: str = Field(min_length=1)
    timestamp_s: float
    position_m: float
    speed_mps: float = Field(ge=0.0)


Vehicle = V2XMessage | SensedVehicle


def _age(vehicle: Vehicle, now_s: float) -> float:
    now = float(now_s)
    if not np.isfinite(now):
        raise ValueError(f"now_s must be finite; got {now_s!r}")
    age = now - vehicle.timestamp_s
    if age < -_TIME_TOL_S:
        raise ValueError(
            f"timestamp_s={vehicle.timestamp_s!r} of vehicle {vehicle.vehicle_id!r} is after now_s={now!r}: "
            "clocks disagree; no state can be trusted"
        )
    return max(age, 0.0)


def _stale_reason(msg: V2XMessage, now_s: float, max_age_s: float) -> str | None:
    if not (np.isfinite(max_age_s) and max_age_s >= 0.0):
        raise ValueError(f"max_age_s must be finite and >= 0; got {max_age_s!r}")
    age = _age(msg, now_s)
    if age > max_age_s + _TIME_TOL_S:
        return f"stale: age {age:.3g} s > max_age_s {max_age_s:.3g} s; counted as non-connected"
    return None


def check_stream(messages: Sequence[V2XMessage]) -> tuple[V2XMessage, ...]:
    """Check a history of one vehicle's messages: one ``vehicle_id``, strictly increasing ``timestamp_s``.

    A repeated timestamp is rejected too: it is a duplicate or two conflicting states for one instant.
    """
    msgs = tuple(messages)
    for k in range(1, len(msgs)):
        prev, cur = msgs[k - 1], msgs[k]
        if cur.vehicle_id != msgs[0].vehicle_id:
            raise ValueError(f"vehicle_id={cur.vehicle_id!r} at message {k} differs from {msgs[0].vehicle_id!r}")
        if cur.timestamp_s <= prev.timestamp_s:
            raise ValueError(
                f"timestamp_s={cur.timestamp_s!r} at message {k} of vehicle {cur.vehicle_id!r} is out of order: "
                f"not after {prev.timestamp_s!r}"
            )
    return msgs


def check_batch(vehicles: Sequence[Vehicle]) -> None:
    """Raise ``ValueError`` if two entries of one batch share a ``vehicle_id``."""
    seen: dict[str, int] = {}
    for k, veh in enumerate(vehicles):
        if veh.vehicle_id in seen:
            raise ValueError(
                f"vehicle_id={veh.vehicle_id!r} is duplicated in one batch (entries {seen[veh.vehicle_id]} and {k})"
            )
        seen[veh.vehicle_id] = k


def extrapolate(p, v, a, dt_s):
    """State after ``dt_s >= 0`` seconds at constant acceleration ``a`` [m/s²], stopping at rest (never reversing).

    Broadcasting arrays or scalars; returns ``(p, v)`` as float64.
    """
    return advance(*np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (p, v, a, dt_s))))


@dataclass(frozen=True)
class LeaderChain:
    """Leader-chain arrays for :func:`safelane.safety.leader_chain`, plus how they were obtained.

    Attributes:
        p, v: ``(N+1,)`` positions [m] and speeds [m/s] of ``L1..L(N+1)`` at ``now_s``.
        promise_decel: ``(N,)`` promised decelerations of the connected ``L1..LN`` [m/s²].
        human_driven: ``(N,)`` bool.
        n_connected: ``N``, the number of consecutive fresh connected leaders from ``L1``.
        ids: ``N+1`` ids of ``L1..L(N+1)``; ``dropped_ids``: vehicles beyond ``L(N+1)``, ignored.
        stale_ids: every input message older than ``max_age_s`` (counted as non-connected).
        reason: why the chain stops at ``L(N+1)``.
    """

    p: np.ndarray
    v: np.ndarray
    promise_decel: np.ndarray
    human_driven: np.ndarray
    n_connected: int
    ids: tuple[str, ...]
    dropped_ids: tuple[str, ...]
    stale_ids: tuple[str, ...]
    reason: str


def leader_arrays(
    leaders: Sequence[Vehicle], now_s: float, params: Params, *, max_age_s: float = MAX_AGE_S
) -> LeaderChain:
    """Convert the leaders ``L1, L2, ...`` (nearest first) into a :class:`LeaderChain` at time ``now_s``.

    The chain takes consecutive fresh :class:`V2XMessage` senders from ``L1``; the first :class:`SensedVehicle`
    or stale message becomes ``L(N+1)`` and everything beyond it is dropped. If every leader is fresh and
    connected, the last one is ``L(N+1)``: nothing is known ahead of it, so it gets the worst case.
    Fresh senders are extrapolated with their reported speed and acceleration; ``L(N+1)`` known from a stale
    message or sensors, as braking at ``a_x_d`` since its timestamp.
    """
    leaders = tuple(leaders)
    if not leaders:
        raise ValueError("leaders must hold at least one vehicle (L(N+1)); got none")
    check_batch(leaders)
    stale: dict[str, str] = {}
    for veh in leaders:
        if isinstance(veh, V2XMessage):
            veh.check_limits(params)
            reason = _stale_reason(veh, now_s, max_age_s)
            if reason is not None:
                stale[veh.vehicle_id] = reason
        else:
            _age(veh, now_s)
    n = 0
    while n < len(leaders) - 1 and isinstance(leaders[n], V2XMessage) and leaders[n].vehicle_id not in stale:
        n += 1
    last = leaders[n]
    if last.vehicle_id in stale:
        reason = f"L{n + 1} {last.vehicle_id!r} {stale[last.vehicle_id]}"
    elif isinstance(last, SensedVehicle):
        reason = f"L{n + 1} {last.vehicle_id!r} is not connected"
    else:
        reason = f"L{n + 1} {last.vehicle_id!r} is the last known leader"
    kept = leaders[: n + 1]
    worst = [not isinstance(veh, V2XMessage) or veh.vehicle_id in stale for veh in kept]
    accel = [-params.a_x_d if w else veh.accel_mps2 for veh, w in zip(kept, worst, strict=True)]
    ages = [_age(veh, now_s) for veh in kept]
    p, v = extrapolate([veh.position_m for veh in kept], [veh.speed_mps for veh in kept], accel, ages)
    return LeaderChain(
        p=p,
        v=v,
        promise_decel=np.array([veh.promise_decel for veh in kept[:n]], dtype=np.float64),
        human_driven=np.array([veh.human_driven for veh in kept[:n]], dtype=bool),
        n_connected=n,
        ids=tuple(veh.vehicle_id for veh in kept),
        dropped_ids=tuple(veh.vehicle_id for veh in leaders[n + 1 :]),
        stale_ids=tuple(stale),
        reason=reason,
    )


@dataclass(frozen=True)
class ChainBatch:
    """A batch of leader chains of varying ``N``, padded to a common width ``K = max(N) + 1``.

    Attributes:
        p, v: ``(B, K)``; promise_decel, human_driven: ``(B, K-1)``; valid: ``(B, K)`` True for real vehicles.
        n_connected: ``(B,)`` int; stale_ids, reasons: per scenario, as in :class:`LeaderChain`.

    The padding is neutral, so the padded arrays feed :func:`safelane.safety.leader_chain` directly and give the
    same result as each chain alone: padding vehicles sit ``1e6`` m apart ahead of ``L(N+1)`` at its speed, and
    ``L(N+1)``'s padded promise is ``a_x_d``, so it still brakes at ``max(a_x_d, z) -> a_x_d`` (clipped).
    """

    p: np.ndarray
    v: np.ndarray
    promise_decel: np.ndarray
    human_driven: np.ndarray
    valid: np.ndarray
    n_connected: np.ndarray
    stale_ids: tuple[tuple[str, ...], ...]
    reasons: tuple[str, ...]


def chain_arrays(
    scenarios: Sequence[Sequence[Vehicle]], now_s, params: Params, *, max_age_s: float = MAX_AGE_S
) -> ChainBatch:
    """:func:`leader_arrays` for each scenario (leading axis ``B``); ``now_s`` is a scalar or ``(B,)``.

    Messages are per-vehicle objects by nature, so this boundary loops in Python; the arrays it returns do not.
    """
    scenarios = tuple(scenarios)
    now = np.broadcast_to(np.asarray(now_s, dtype=np.float64), (len(scenarios),))
    chains = [leader_arrays(s, t, params, max_age_s=max_age_s) for s, t in zip(scenarios, now.tolist(), strict=True)]
    width = max((c.n_connected + 1 for c in chains), default=1)
    batch = len(chains)
    p, v = np.zeros((batch, width)), np.zeros((batch, width))
    promise = np.full((batch, width - 1), params.a_x_d)
    human = np.zeros((batch, width - 1), dtype=bool)
    valid = np.zeros((batch, width), dtype=bool)
    for b, c in enumerate(chains):
        k = c.n_connected + 1
        p[b, :k], v[b, :k], valid[b, :k] = c.p, c.v, True
        p[b, k:] = c.p[-1] + _PAD_GAP_M * np.arange(1, width - k + 1)
        v[b, k:] = c.v[-1]
        promise[b, : k - 1], human[b, : k - 1] = c.promise_decel, c.human_driven
    return ChainBatch(
        p=p,
        v=v,
        promise_decel=promise,
        human_driven=human,
        valid=valid,
        n_connected=np.array([c.n_connected for c in chains], dtype=np.int64),
        stale_ids=tuple(c.stale_ids for c in chains),
        reasons=tuple(c.reason for c in chains),
    )


@dataclass(frozen=True)
class FollowerStatus:
    """What the follower ``F``'s message says. ``connected`` needs a fresh message; ``collaborative`` also
    needs ``intent == "collaborative"`` — anything else (no message, stale, aggressive, undeclared) is not."""

    connected: bool
    stale: bool
    collaborative: bool
    intent: Intent | None
    reason: str


def follower_status(
    message: V2XMessage | None, now_s: float, params: Params, *, max_age_s: float = MAX_AGE_S
) -> FollowerStatus:
    """Classify the follower's latest message (``None`` when it sent none) at ``now_s``."""
    if message is None:
        return FollowerStatus(False, False, False, None, "no message: not connected")
    message.check_limits(params)
    reason = _stale_reason(message, now_s, max_age_s)
    if reason is not None:
        return FollowerStatus(False, True, False, message.intent, f"F {message.vehicle_id!r} {reason}")
    collaborative = message.intent == "collaborative"
    return FollowerStatus(True, False, collaborative, message.intent, f"fresh; intent {message.intent!r}")


def received_chain(t_msg, p_msg, v_msg, a_msg, connected, now_s: float, params: Params, *, max_age_s=MAX_AGE_S):
    """:func:`leader_arrays` over a batch of *received* messages as arrays (the simulator's V2X emulation).

    Args:
        t_msg, p_msg, v_msg, a_msg: ``(B, K)`` timestamp [s], position, speed and reported acceleration of the last
            message received from each of ``L1..LK`` (nearest first); for a vehicle not connected these hold what
            the ego's sensors saw and when (``t_msg = now_s`` for a vehicle sensed now).
        connected: ``(B, K)`` bool, the vehicle is a V2X sender (the last column is never a connected leader of
            the chain: nothing is known ahead of it).
        now_s: the ego's time.

    Returns ``(p, v, n_connected, stale)``: ``(B, K)`` positions and speeds at ``now_s`` — consecutive fresh
    senders from ``L1`` extrapolated with their reported acceleration; the first stale or non-connected vehicle is
    ``L(N+1)``, moved as braking at ``a_x_d`` since its timestamp (a fresh sender in the last column is ``L(N+1)``
    too, extrapolated like any fresh sender); everything beyond it is padding ``1e6`` m apart
    ahead of it at its speed (neutral for :func:`safelane.safety.leader_chain`) — ``(B,)`` N and the ``(B, K)``
    stale mask. The same semantics as :func:`leader_arrays`, vectorized (tested against it).
    """
    t_msg, p_msg, v_msg, a_msg = (np.asarray(x, dtype=np.float64) for x in (t_msg, p_msg, v_msg, a_msg))
    connected = np.asarray(connected, dtype=bool)
    bsz, k = p_msg.shape
    age = np.maximum(now_s - t_msg, 0.0)
    stale = connected & (age > max_age_s + _TIME_TOL_S)
    chain = connected & ~stale
    chain[:, -1] = False  # so that every row has a slot out of the chain: L(N+1), the last slot at most
    n = np.argmin(chain, 1)  # consecutive fresh senders from L1: the first slot out of the chain
    slots = np.arange(k)[None, :]
    fresh_sender = connected & ~stale  # extrapolated with what it reported; anything else at the worst case
    p, v = extrapolate(p_msg, v_msg, np.where(fresh_sender, a_msg, -params.a_x_d), age)
    rows = np.arange(bsz)
    head_p, head_v = p[rows, n], v[rows, n]
    beyond = slots > n[:, None]
    p = np.where(beyond, head_p[:, None] + _PAD_GAP_M * (slots - n[:, None]), p)
    v = np.where(beyond, head_v[:, None], v)
    return p, v, n, stale

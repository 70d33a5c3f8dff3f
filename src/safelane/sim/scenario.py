"""Scenario batches: initial states and per-scenario settings, padded to one vehicle axis.

Target-lane vehicles live on one axis of length ``K``: index 0 is the follower F, 1..N the connected leaders
L1..LN, N+1 the first non-connected leader L(N+1); indices beyond are padding (``valid`` False). Vehicles
beyond L(N+1) are not simulated. The ego starts at the origin of the original lane (``x = 0``, ``y = 0``).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, fields

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from ..params import Params
from ..planners.variants import VARIANT_NAMES, get_variant
from ..tolerances import SETTING_SLACK
from .inputs import check_scenario_ranges

#: Bounds of :class:`ScenarioConfig` that hold whatever the ``Params``: promises beyond 15 m/s² (1.5 g, more than any
#: road vehicle's tyres give), gaps (centre to centre) shorter than the shortest car, speeds above 100 m/s.
MAX_ACCEL_MPS2 = 15.0
MIN_GAP_M = 2.5
MAX_SPEED_MPS = 100.0


class ScenarioConfig(BaseModel):
    """Scenario distribution. Defaults are the paper's sampler (§4.1)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    ego_speed: tuple[float, float] = Field((29.0, 31.0), description="Ego speed range U[lo, hi] [m/s] (paper).")
    traffic_speed: float = Field(
        30.0, ge=0.0, le=MAX_SPEED_MPS, description="Speed of F and the leaders [m/s] (paper)."
    )
    gap: tuple[float, float] = Field((17.0, 22.0), description="Inter-vehicle distance δp ~ U[lo, hi] [m] (paper).")
    promise_decel: float = Field(
        0.5, ge=0.0, le=MAX_ACCEL_MPS2, description="Promised max deceleration a_m_d [m/s²] (paper)."
    )
    promise_accel: float = Field(
        0.5, ge=0.0, le=MAX_ACCEL_MPS2, description="Promised max acceleration a_m_a [m/s²] (our assumption)."
    )
    follower_connected_share: float = Field(
        1.0, ge=0.0, le=1.0, description="Share of connected (hence collaborative) followers (paper: F connected)."
    )
    follower_aggressive_share: float = Field(
        0.5, ge=0.0, le=1.0, description="Share of aggressive followers among non-connected ones (our assumption)."
    )
    human_share: float = Field(0.0, ge=0.0, le=1.0, description="Share of human-driven connected leaders.")

    # Reversed or impossible ranges fail here, naming the field (not as a NumPy error later): see sim/inputs.py.
    _check_ranges = model_validator(mode="after")(check_scenario_ranges)

    @model_validator(mode="after")
    def _check_physical(self) -> ScenarioConfig:
        # Without Params at hand, the bounds no car passes; a run checks against its own Params too
        # (sim/inputs.py: promises beyond a_x_d / a_x_a refused, gaps below vehicle_length warned about).
        lo, hi = self.gap
        if lo < MIN_GAP_M:
            raise ValueError(
                f"gap=({lo}, {hi}): the lower bound must be >= {MIN_GAP_M} m — gaps are centre-to-centre distances, "
                f"and below {MIN_GAP_M} m (shorter than any car) every scenario starts with the vehicles overlapping"
            )
        lo, hi = self.ego_speed
        if hi > MAX_SPEED_MPS:
            raise ValueError(f"ego_speed=({lo}, {hi}): the upper bound must be <= {MAX_SPEED_MPS} m/s")
        return self


@dataclass(frozen=True)
class ScenarioBatch:
    """Initial conditions and settings of ``B`` scenarios (leading axis)."""

    ego_x: np.ndarray  # (B,)
    ego_y: np.ndarray
    ego_vx: np.ndarray
    ego_vy: np.ndarray
    x: np.ndarray  # (B, K) target-lane vehicles
    v: np.ndarray
    valid: np.ndarray
    connected: np.ndarray
    human: np.ndarray
    promise_decel: np.ndarray  # (B, K)
    promise_accel: np.ndarray
    n_connected: np.ndarray  # (B,) N
    follower_aggressive: np.ndarray  # (B,) true type of F
    decel_last: np.ndarray  # (B,) a_x_N+1_d, the sudden braking of L(N+1)
    p_v: np.ndarray  # (B,) unexpected promise-violation probability per connected vehicle and period
    variant: np.ndarray  # (B,) index into VARIANT_NAMES
    scenario_id: np.ndarray  # (B,) stable id: keys per-scenario random draws
    #: ``(B, P)`` L(N+1)'s acceleration profile (segment start times, accelerations), or ``None`` for the sudden
    #: braking at ``decel_last`` from ``SimConfig.brake_start_s``; set with
    #: :func:`safelane.sim.traffic.with_last_profile`.
    last_profile_t: np.ndarray | None = None
    last_profile_a: np.ndarray | None = None
    #: The own lane's leader L0 (real_roads.md): ``(B,)`` initial position and speed (``+inf`` position: none) and its
    #: ``(B, P)`` acceleration profile (as ``last_profile_*``); ``None``: the paper's empty original lane.
    l0_x: np.ndarray | None = None
    l0_v: np.ndarray | None = None
    l0_profile_t: np.ndarray | None = None
    l0_profile_a: np.ndarray | None = None
    #: The own lane as a chain (real_roads.md, "A connected own lane"): ``(B, J)`` the vehicles ahead of ``L0``,
    #: nearest first (``+inf`` position: none), their speeds, ``(B, J)`` the promised maximum deceleration of the
    #: connected ones from ``L0`` on (``L0`` first), ``(B,)`` how many from ``L0`` on are connected (at most ``J``;
    #: the first one that is not, the head, drives ``l0_profile_*``), and ``(B, J)`` the instant each connected one
    #: starts braking at its promise (``inf``: never). ``None``: ``L0`` alone, not connected.
    own_ahead_x: np.ndarray | None = None
    own_ahead_v: np.ndarray | None = None
    own_promise: np.ndarray | None = None
    own_n_connected: np.ndarray | None = None
    own_brake_t: np.ndarray | None = None
    #: ``(B,)`` counter key of the realistic world's draws (measurement errors, L0), default the scenario id.
    world_key: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.ego_x)

    def take(self, idx) -> ScenarioBatch:
        """Rows ``idx`` (a slice, index array or mask) as a new batch."""
        return ScenarioBatch(
            **{f.name: None if getattr(self, f.name) is None else getattr(self, f.name)[idx] for f in fields(self)}
        )


def paper_scenarios(
    planner: str,
    n_leaders: int,
    decel: float,
    samples: int,
    rng: np.random.Generator,
    config: ScenarioConfig | None = None,
    first_id: int = 0,
    p_v: float = 0.0,
) -> ScenarioBatch:
    """The paper's sampler: ego speed U[29, 31], F and leaders at 30 m/s, one δp ~ U[17, 22] per scenario
    (F at −δp, L_i at i·δp), promise ``a_m_d = 0.5``; L1..LN connected, L(N+1) not."""
    cfg = config or ScenarioConfig()
    _check_cell(planner, n_leaders, decel, samples, p_v)
    k = n_leaders + 2
    gap = rng.uniform(*cfg.gap, size=samples)
    ego_vx = rng.uniform(*cfg.ego_speed, size=samples)
    f_connected = rng.uniform(size=samples) < cfg.follower_connected_share
    f_aggressive = ~f_connected & (rng.uniform(size=samples) < cfg.follower_aggressive_share)
    human = np.zeros((samples, k), bool)
    human[:, 1 : n_leaders + 1] = rng.uniform(size=(samples, n_leaders)) < cfg.human_share
    slots = np.arange(k)
    connected = (slots >= 1) & (slots <= n_leaders)
    connected = np.broadcast_to(connected, (samples, k)).copy()
    connected[:, 0] = f_connected
    return ScenarioBatch(
        ego_x=np.zeros(samples),
        ego_y=np.zeros(samples),
        ego_vx=ego_vx,
        ego_vy=np.zeros(samples),
        x=np.where(slots == 0, -1.0, slots.astype(float)) * gap[:, None],
        v=np.full((samples, k), cfg.traffic_speed),
        valid=np.ones((samples, k), bool),
        connected=connected,
        human=human,
        promise_decel=np.full((samples, k), cfg.promise_decel),
        promise_accel=np.full((samples, k), cfg.promise_accel),
        n_connected=np.full(samples, n_leaders),
        follower_aggressive=f_aggressive,
        decel_last=np.full(samples, float(decel)),
        p_v=np.full(samples, float(p_v)),
        variant=np.full(samples, VARIANT_NAMES.index(planner)),
        scenario_id=np.arange(first_id, first_id + samples, dtype=np.int64),
    )


def penetration_scenarios(
    planner: str,
    penetration: float,
    decel: float,
    samples: int,
    rng: np.random.Generator,
    config: ScenarioConfig | None = None,
    max_leaders: int = 10,
    first_id: int = 0,
    p_v: float = 0.0,
) -> ScenarioBatch:
    """The general sampler: each leader (up to ``max_leaders + 1``) and F is connected with probability
    ``penetration``; N is the index of the first non-connected leader; a non-connected F is aggressive with
    ``follower_aggressive_share``; connected leaders are human-driven with ``human_share``."""
    if not 0.0 <= penetration <= 1.0:
        raise ValueError(f"penetration must lie in [0, 1]; got {penetration!r}")
    cfg = config or ScenarioConfig()
    conn = rng.uniform(size=(samples, max_leaders + 1)) < penetration
    conn[:, -1] = False  # at most max_leaders connected: the last slot is always L(N+1)
    n = np.argmin(conn, axis=1)  # first non-connected leader
    parts = [
        paper_scenarios(
            planner,
            int(nv),
            decel,
            int((n == nv).sum()),
            rng,
            cfg.model_copy(update={"follower_connected_share": penetration}),
            first_id=0,
            p_v=p_v,
        )
        for nv in np.unique(n)
    ]
    batch = concat(parts)
    order = np.argsort(np.concatenate([np.flatnonzero(n == nv) for nv in np.unique(n)]), kind="stable")
    batch = batch.take(order)
    return ScenarioBatch(
        **{
            **{f.name: getattr(batch, f.name) for f in fields(batch)},
            "scenario_id": np.arange(first_id, first_id + samples, dtype=np.int64),
        }
    )


def concat(batches: list[ScenarioBatch]) -> ScenarioBatch:
    """Stack batches row-wise, padding the vehicle axis (padding is invalid and never simulated)."""
    k = max(b.x.shape[1] for b in batches)
    out = {}
    profiles = {b.last_profile_t is None for b in batches}
    if len(profiles) > 1:
        raise ValueError("cannot concatenate batches with and without an L(N+1) profile (last_profile_t)")
    for f in fields(ScenarioBatch):
        if getattr(batches[0], f.name) is None:
            out[f.name] = None
            continue
        parts = []
        for b in batches:
            a = getattr(b, f.name)
            if a.ndim == 2 and a.shape[1] < k and not f.name.startswith("last_profile"):
                pad = np.repeat(a[:, -1:], k - a.shape[1], axis=1)
                if f.name in ("valid", "connected", "human"):
                    pad = np.zeros_like(pad)
                elif f.name == "x":
                    pad = pad + 1e6 * np.arange(1, k - a.shape[1] + 1)
                a = np.concatenate([a, pad], axis=1)
            parts.append(a)
        out[f.name] = np.concatenate(parts)
    return ScenarioBatch(**out)


def _check_cell(planner: str, n_leaders: int, decel: float, samples: int, p_v: float = 0.0) -> None:
    get_variant(planner)
    if not 0.0 <= p_v <= 1.0:
        raise ValueError(f"p_v (promise-violation rate) must lie in [0, 1]; got {p_v!r}")
    if not isinstance(n_leaders, int | np.integer) or n_leaders < 0:
        raise ValueError(f"n_leaders must be a non-negative integer; got {n_leaders!r}")
    if not np.isfinite(decel) or decel <= 0:
        raise ValueError(f"decel (a_x_N+1_d) must be a positive finite number; got {decel!r}")
    if not isinstance(samples, int | np.integer) or samples < 1:
        raise ValueError(f"samples must be a positive integer; got {samples!r}")


def check_batch(batch: ScenarioBatch, prm: Params) -> None:
    """Reject batches the simulator cannot run; warn where they leave the paper's assumptions."""
    if len(batch) == 0:
        raise ValueError("the scenario batch is empty")
    if batch.x.shape[1] < 2:
        raise ValueError("each scenario needs a follower and at least one leader (K >= 2)")
    if (batch.decel_last > prm.others_decel + SETTING_SLACK).any():
        worst = float(batch.decel_last.max())
        # Allowed, but outside the paper's assumptions: say so rather than silently promising safety.
        warnings.warn(
            f"a_x_N+1_d={worst} exceeds the others' maximum braking params.a_o_d={prm.others_decel} (a_x_d unless "
            "set): L(N+1) brakes harder than the worst case the "
            "safety analysis assumes, so collisions are possible",
            stacklevel=3,
        )
    for name in ("ego_vx",):
        if (getattr(batch, name) < 0).any():
            raise ValueError(f"{name} must be >= 0")
    if (batch.v < 0).any():
        raise ValueError("vehicle speeds v must be >= 0")


def explicit_scenarios(
    *,
    ego,
    follower,
    leaders,
    n_connected=None,
    planner: str = "CV_all",
    decel_last=5.0,
    follower_connected=True,
    follower_aggressive=False,
    promise_decel=0.5,
    promise_accel=0.5,
    human=False,
    p_v=0.0,
    first_id: int = 0,
) -> ScenarioBatch:
    """A batch of explicit initial states — the one documented way to build scenarios by hand.

    Args:
        ego: ``(x, y, vx, vy)``, each a scalar or ``(B,)`` (``y`` from the original lane's centre).
        follower: ``(x, v)`` of F.
        leaders: ``(x, v)``, each ``(M,)`` or ``(B, M)``: ``L1, L2, …``, nearest first; the last one is ``L(N+1)``.
        n_connected: N (default ``M − 1``: all but the last connected); leaders beyond ``L(N+1)`` are dropped.
        planner: the variant's name. decel_last: ``a_x_N+1_d``. p_v: unexpected promise-violation rate.
        follower_connected, follower_aggressive, promise_decel, promise_accel, human: scalars or per-scenario.

    Leader positions must increase along the chain and F must be behind L1; speeds are ``>= 0``.
    """
    ex, ey, evx, evy = (np.atleast_1d(np.asarray(a, float)) for a in ego)
    fx, fv = (np.atleast_1d(np.asarray(a, float)) for a in follower)
    lx, lv = (np.atleast_2d(np.asarray(a, float)) for a in leaders)
    b = max(len(ex), len(ey), len(evx), len(evy), len(fx), len(fv), lx.shape[0], lv.shape[0])
    try:
        ex, ey, evx, evy, fx, fv = (np.broadcast_to(a, (b,)).copy() for a in (ex, ey, evx, evy, fx, fv))
        lx, lv = (np.broadcast_to(a, (b, lx.shape[1])).copy() for a in (lx, lv))
    except ValueError as exc:
        raise ValueError(f"ego, follower and leaders must share one batch size; {exc}") from None
    m = lx.shape[1]
    n = m - 1 if n_connected is None else int(n_connected)
    if not 0 <= n <= m - 1:
        raise ValueError(f"n_connected must lie in [0, {m - 1}] for {m} leaders; got {n_connected!r}")
    lx, lv = lx[:, : n + 1], lv[:, : n + 1]
    if not np.isfinite(np.concatenate([ex, ey, evx, evy, fx, fv, lx.ravel(), lv.ravel()])).all():
        raise ValueError("explicit scenario states must be finite")
    if (np.concatenate([evx, fv, lv.ravel()]) < 0).any():
        raise ValueError("speeds (ego vx, follower v, leaders v) must be >= 0")
    if (np.diff(lx, axis=1) <= 0).any():
        raise ValueError("leader positions must increase along the chain (L1 nearest)")
    if (fx >= lx[:, 0]).any():
        raise ValueError("the follower must be behind L1 (follower x < leaders x[:, 0])")
    get_variant(planner)
    k = n + 2
    x = np.column_stack([fx, lx])
    v = np.column_stack([fv, lv])
    slots = np.arange(k)
    connected = np.broadcast_to((slots >= 1) & (slots <= n), (b, k)).copy()
    connected[:, 0] = np.broadcast_to(np.asarray(follower_connected, bool), (b,))
    human_rows = np.zeros((b, k), bool)
    human_rows[:, 1 : n + 1] = _per_row(human, b, bool)[:, None]
    promise_d = np.repeat(_per_row(promise_decel, b, float)[:, None], k, 1)
    promise_a = np.repeat(_per_row(promise_accel, b, float)[:, None], k, 1)
    return ScenarioBatch(
        ego_x=ex, ego_y=ey, ego_vx=evx, ego_vy=evy, x=x, v=v, valid=np.ones((b, k), bool), connected=connected,
        human=human_rows, promise_decel=promise_d, promise_accel=promise_a, n_connected=np.full(b, n),
        follower_aggressive=_per_row(follower_aggressive, b, bool), decel_last=_per_row(decel_last, b, float),
        p_v=_per_row(p_v, b, float), variant=np.full(b, VARIANT_NAMES.index(planner)),
        scenario_id=np.arange(first_id, first_id + b, dtype=np.int64),
    )  # fmt: skip


def _per_row(value, b: int, dtype) -> np.ndarray:
    """A scalar or ``(B,)`` setting as a ``(B,)`` array."""
    arr = np.asarray(value, dtype=dtype)
    if arr.ndim > 1 or (arr.ndim == 1 and arr.shape != (b,)):
        raise ValueError(f"a per-scenario setting must be a scalar or have shape ({b},); got {arr.shape}")
    return np.broadcast_to(arr, (b,)).copy()

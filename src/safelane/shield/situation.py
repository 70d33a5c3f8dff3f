"""What the ego knows at a control step: :class:`Situation`, the shield's only input besides the proposal.

A batch of ``B`` situations, every array with the batch on its leading axis. The frame is the paper's: ``x`` along
the direction of travel, ``y`` the lateral position of the ego's centre from the *original* lane's centre, positive
toward the target lane (target-lane centre at ``y = Params.lane_width``). A simulator with other conventions maps
them in one place with :class:`LaneFrame` (e.g. highway-env: ``y`` grows to the right, lane 0 leftmost).

The leader chain is as the ego sees it: ``L1`` (sensed) and, ahead of it, the connected leaders whose V2X messages
are fresh, then the first non-connected (or stale) leader ``L(N+1)``; vehicles beyond it are padding far ahead
(see :func:`safelane.v2x.received_chain`, which builds exactly these arrays from messages).

Beyond the paper's world (all optional; absent, the shield is exactly the paper's):

* the ego's **own lane**: ``own_x``/``own_v`` are ``L0`` (the nearest vehicle ahead of the ego in its original lane)
  and, where ``L0`` is connected, the chain ahead of it, in the same layout as the target lane's chain; a position of
  ``+inf`` marks "no vehicle" (a row without ``L0``);
* **bounded sensing error**: ``err_f (B, 2)``, ``err_chain (B, M, 2)``, ``err_own (B, K, 2)`` — the bound on the
  position error [m] and the speed error [m/s] of each measured state (the ego's own state is exact; relative
  measurement errors belong to the others' bounds). :class:`SensingBounds` fills them from connectivity;
* **other vehicles** that can enter the ego's path (in the lane beyond the target lane, on the ego's other side, or
  straddling): ``others``, a :class:`~.world.Others` record, which the shield folds into F, the chain and the own
  lane before anything else (:func:`safelane.shield.world.roles`; docs/safety.md, "Other vehicles' lane changes").
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..params import Params
from .geometry import order_problems, report_order
from .world import Others


@dataclass(frozen=True)
class LaneFrame:
    """Maps a simulator's lateral coordinate into the shield's: ``y = sign · (y_sim − origin_y)``.

    Attributes:
        origin_y: the original lane's centre in the simulator's frame.
        sign: ``+1`` if the target lane lies at larger ``y_sim``, ``−1`` otherwise.
    """

    origin_y: float = 0.0
    sign: float = 1.0

    def __post_init__(self):
        if self.sign not in (1.0, -1.0):
            raise ValueError(f"LaneFrame.sign must be +1 or -1; got {self.sign!r}")
        if not np.isfinite(self.origin_y):
            raise ValueError(f"LaneFrame.origin_y must be finite; got {self.origin_y!r}")

    def y(self, y_sim, vy_sim):
        """``(y, v_y)`` in the shield's frame."""
        return self.sign * (np.asarray(y_sim, float) - self.origin_y), self.sign * np.asarray(vy_sim, float)

    def y_back(self, a_y):
        """A lateral acceleration of the shield's frame in the simulator's."""
        return self.sign * np.asarray(a_y, float)


@dataclass(frozen=True)
class Situation:
    """A batch of ``B`` snapshots of what the ego knows (see the module docstring for the frame).

    Attributes:
        t: time [s] (scalar).
        ego_x, ego_y, ego_vx, ego_vy: ``(B,)`` the ego's state.
        f_x, f_v: ``(B,)`` the follower F's sensed position and speed.
        f_connected: ``(B,)`` F's latest V2X message is fresh.
        f_collaborative: ``(B,)`` F declares itself collaborative over V2X (counts only where ``f_connected``).
        chain_x, chain_v: ``(B, M)`` ``L1, L2, …`` as the ego sees them (``L1`` first; ``M >= 1``).
        chain_promise: ``(B, M−1)`` promised maximum deceleration of ``L1..L(M−1)`` (used for ``L_i``, ``i <= N``).
        chain_human: ``(B, M−1)`` connected human-driven (they keep ``p_m_human``).
        n_connected: ``(B,)`` N, the connected leaders at the head of the chain (``L(N+1)`` is the next slot).
        f_speed_observed: ``(B,)`` the ego's measurement of F's speed for the aggressiveness assessment (default
            ``f_v``; a simulator adds its sensor noise here).
        f_aggressive_truth: ``(B,)`` F's true type, or ``None``; only the ``truth`` assessment (a study of the
            paper's guarantee, which assumes an exact assessment) reads it.
        v2x_stale: ``(B,)`` some sender's latest message is stale (the chain and F above already fall back).
        own_x, own_v: ``(B, K)`` ``L0`` and the vehicles ahead of it in the ego's own lane (``+inf`` position: none),
            or ``None`` (the paper's empty original lane).
        own_promise: ``(B, K−1)`` promised maximum deceleration of the connected own-lane leaders.
        own_n_connected: ``(B,)`` how many own-lane leaders from ``L0`` on are connected (``0``: ``L0`` brakes at
            ``a_x_d`` in the worst case).
        err_f, err_chain, err_own: sensing-error bounds ``[..., (position m, speed m/s)]`` or ``None`` (exact).
        others: the vehicles besides F, the chain and L0 that can enter the ego's path (:class:`~.world.Others`,
            ``(B, K)`` in this frame), or ``None`` (the paper's world: nobody else changes lanes).
    """

    t: float
    ego_x: np.ndarray
    ego_y: np.ndarray
    ego_vx: np.ndarray
    ego_vy: np.ndarray
    f_x: np.ndarray
    f_v: np.ndarray
    f_connected: np.ndarray
    f_collaborative: np.ndarray
    chain_x: np.ndarray
    chain_v: np.ndarray
    chain_promise: np.ndarray
    chain_human: np.ndarray
    n_connected: np.ndarray
    f_speed_observed: np.ndarray | None = None
    f_aggressive_truth: np.ndarray | None = None
    v2x_stale: np.ndarray | None = None
    own_x: np.ndarray | None = None
    own_v: np.ndarray | None = None
    own_promise: np.ndarray | None = None
    own_n_connected: np.ndarray | None = None
    err_f: np.ndarray | None = None
    err_chain: np.ndarray | None = None
    err_own: np.ndarray | None = None
    others: Others | None = None

    def __len__(self) -> int:
        return len(self.ego_x)

    @property
    def observed_f_speed(self) -> np.ndarray:
        return self.f_v if self.f_speed_observed is None else self.f_speed_observed

    @classmethod
    def from_arrays(
        cls,
        *,
        t: float,
        ego: tuple,
        follower: tuple,
        leaders: tuple,
        n_connected,
        promise_decel=0.5,
        human_driven=False,
        f_connected=False,
        f_collaborative=False,
        frame: LaneFrame | None = None,
        params: Params | None = None,
        own_leaders: tuple | None = None,
        own_n_connected=0,
        own_promise=0.5,
        sensing: SensingBounds | None = None,
        geometry: str = "warn",
        others: Others | tuple | None = None,
    ) -> Situation:
        """A validated batch from plain arrays (any batch size; scalars give ``B = 1``).

        Args:
            ego: ``(x, y, vx, vy)`` in the simulator's frame (mapped by ``frame``).
            follower: ``(x, v)`` of F.
            leaders: ``(x, v)``, each ``(B, M)`` (or ``(M,)``): ``L1`` first.
            n_connected: ``(B,)`` or scalar N (``<= M − 1``).
            promise_decel, human_driven: scalars or ``(B, M−1)``.
            f_connected, f_collaborative: scalars or ``(B,)``.
            own_leaders: ``(x, v)``, each ``(B, K)`` (or ``(K,)``): ``L0`` first, ``+inf`` position where none; or
                ``None`` (the original lane is empty).
            own_n_connected, own_promise: as ``n_connected`` and ``promise_decel`` for the own lane.
            sensing: error bounds filled per vehicle by connectivity, or ``None`` (exact states).
            others: the other vehicles (:class:`~.world.Others`): a record in the shield's frame as it is, or a tuple
                ``(x, y, vx, vy[, connected, announce_lane, announce_t])`` of ``(B, K)`` (or ``(K,)``) arrays in the
                simulator's frame (``y``, ``vy`` mapped by ``frame``); ``x = +inf`` pads a row.

        Geometry (``geometry``): the lanes' order — the target lane's ``F ≤ L1 ≤ L2 ≤ … ≤ L(N+1)``, the own lane's
        ``L0`` first — is checked (:meth:`order_problems`); a break (leaders given farthest first, F and L1
        swapped) gives a :class:`GeometryWarning` naming the field, the row and the positions (``"warn"``, the
        default), an :class:`~safelane.errors.InputError` (``"raise"``), or nothing (``"ignore"``). It is not refused
        by default because real loops produce it — a hand-written world or a simulator without collisions between
        the others lets a vehicle pass through another, states extrapolated from stale V2X messages at their worst
        case can cross — and because the shield's answer to it is conservative: a leader behind the one it follows
        makes that link unsafe, so ``L1``'s worst case is ``a_x_d``; F ahead of L1 means one of them is on the
        wrong side of the ego. Where L1 and F stand relative to the *ego* (the other lane) is never an error:
        ``L1`` beside or behind the ego (the ego overtaking in its own lane) and ``F`` ahead of it are real
        situations, and the fallback is conservative: the evasion check needs ``L1`` at least ``p_m`` ahead of the
        ego and ``F`` at least ``p_m`` behind it from the first instant on, so no step that leaves the own lane is
        accepted (the shield hesitates or aborts) until they are where a lane change needs them
        (``tests/test_validation_situation.py``).
        """
        prm = params or Params()
        frame = frame or LaneFrame()
        ex, ey, evx, evy = (np.atleast_1d(np.asarray(a, float)) for a in ego)
        ey, evy = frame.y(ey, evy)
        fx, fv = (np.atleast_1d(np.asarray(a, float)) for a in follower)
        lx, lv = (np.atleast_2d(np.asarray(a, float)) for a in leaders)
        b = max(len(ex), len(fx), len(lx))
        ex, ey, evx, evy, fx, fv = (np.broadcast_to(a, (b,)).copy() for a in (ex, ey, evx, evy, fx, fv))
        lx, lv = (np.broadcast_to(a, (b, a.shape[-1])).copy() for a in (lx, lv))
        m = lx.shape[1]
        n = np.broadcast_to(np.asarray(n_connected), (b,)).astype(np.int64)
        promise = np.broadcast_to(np.asarray(promise_decel, float), (b, m - 1)).copy()
        human = np.broadcast_to(np.asarray(human_driven, bool), (b, m - 1)).copy()
        f_conn = np.broadcast_to(np.asarray(f_connected, bool), (b,)).copy()
        f_coll = np.broadcast_to(np.asarray(f_collaborative, bool), (b,)).copy()
        situation = cls(
            t=float(t), ego_x=ex, ego_y=ey, ego_vx=evx, ego_vy=evy, f_x=fx, f_v=fv, f_connected=f_conn,
            f_collaborative=f_coll, chain_x=lx, chain_v=lv, chain_promise=promise, chain_human=human, n_connected=n,
        )  # fmt: skip
        if own_leaders is not None:
            ox, ov = (np.atleast_2d(np.asarray(a, float)) for a in own_leaders)
            ox, ov = (np.broadcast_to(a, (b, a.shape[-1])).copy() for a in (ox, ov))
            k = ox.shape[1]
            situation = dataclasses.replace(
                situation, own_x=ox, own_v=ov,
                own_promise=np.broadcast_to(np.asarray(own_promise, float), (b, k - 1)).copy(),
                own_n_connected=np.broadcast_to(np.asarray(own_n_connected), (b,)).astype(np.int64),
            )  # fmt: skip
        if sensing is not None:
            situation = sensing.apply(situation)
        if others is not None:
            if not isinstance(others, Others):
                others = Others.from_arrays(*others, frame=frame)
            if others.x.ndim == 2 and others.x.shape[0] == 1 and b > 1:
                others = Others.from_arrays(*dataclasses.astuple(others), batch=b)
            situation = dataclasses.replace(situation, others=others)
        situation.validate(prm)
        report_order(situation, geometry)
        return situation

    @classmethod
    def from_v2x(
        cls,
        *,
        t: float,
        ego: tuple,
        follower,
        leaders,
        frame: LaneFrame | None = None,
        params: Params | None = None,
        max_age_s: float | None = None,
    ) -> Situation:
        """One situation (``B = 1``) from :mod:`safelane.v2x` objects, with the staleness fallback applied.

        Args:
            ego: ``(x, y, vx, vy)`` in the simulator's frame.
            follower: F as a :class:`~safelane.v2x.V2XMessage` (its ``intent`` says whether it is collaborative)
                or a :class:`~safelane.v2x.SensedVehicle`.
            leaders: ``L1, L2, …`` nearest first, messages or sensed vehicles (:func:`safelane.v2x.leader_arrays`).
        """
        from .. import v2x

        prm = params or Params()
        age = v2x.MAX_AGE_S if max_age_s is None else max_age_s
        chain = v2x.leader_arrays(leaders, t, prm, max_age_s=age)
        if isinstance(follower, v2x.V2XMessage):
            status = v2x.follower_status(follower, t, prm, max_age_s=age)
            connected, collaborative = status.connected, status.collaborative
            fx, fv = v2x.extrapolate(follower.position_m, follower.speed_mps, follower.accel_mps2,
                                     max(t - follower.timestamp_s, 0.0))  # fmt: skip
        else:
            connected = collaborative = False
            fx, fv = v2x.extrapolate(follower.position_m, follower.speed_mps, -prm.a_x_d,
                                     max(t - follower.timestamp_s, 0.0))  # fmt: skip
        n = chain.n_connected
        stale = bool(chain.stale_ids) or (isinstance(follower, v2x.V2XMessage) and not connected)
        situation = cls.from_arrays(
            t=t, ego=ego, follower=(fx, fv), leaders=(chain.p[None, :], chain.v[None, :]), n_connected=n,
            promise_decel=chain.promise_decel[None, :], human_driven=chain.human_driven[None, :],
            f_connected=connected, f_collaborative=collaborative, frame=frame, params=prm,
        )  # fmt: skip
        return dataclasses.replace(situation, v2x_stale=np.array([stale]))

    def validate(self, params: Params) -> None:
        """Raise a ``ValueError`` naming the field for shapes that disagree or values the analysis cannot take."""
        b = len(self.ego_x)
        for name in ("ego_y", "ego_vx", "ego_vy", "f_x", "f_v", "f_connected", "f_collaborative", "n_connected"):
            if np.shape(getattr(self, name)) != (b,):
                raise ValueError(f"Situation.{name} must have shape ({b},); got {np.shape(getattr(self, name))}")
        if self.chain_x.ndim != 2 or self.chain_x.shape[0] != b or self.chain_x.shape[1] < 1:
            raise ValueError(f"Situation.chain_x must have shape ({b}, M >= 1); got {self.chain_x.shape}")
        m = self.chain_x.shape[1]
        if self.chain_v.shape != self.chain_x.shape:
            raise ValueError(f"Situation.chain_v must have shape {self.chain_x.shape}; got {self.chain_v.shape}")
        for name in ("chain_promise", "chain_human"):
            if getattr(self, name).shape != (b, m - 1):
                raise ValueError(f"Situation.{name} must have shape ({b}, {m - 1}); got {getattr(self, name).shape}")
        if not self._values_pass(params, m):  # the rules below, each naming its field
            for name in ("ego_x", "ego_y", "ego_vx", "ego_vy", "f_x", "f_v", "chain_x", "chain_v", "chain_promise"):
                arr = getattr(self, name)
                if not np.isfinite(arr).all():
                    raise ValueError(f"Situation.{name} must be finite; got {arr[~np.isfinite(arr)].flat[0]!r}")
            for name in ("ego_vx", "f_v", "chain_v"):
                if (getattr(self, name) < 0).any():
                    raise ValueError(f"Situation.{name} must be >= 0 (vehicles do not reverse)")
            if ((self.chain_promise < 0) | (self.chain_promise > params.a_x_d)).any():
                raise ValueError(f"Situation.chain_promise must lie in [0, a_x_d={params.a_x_d}]")
            if ((self.n_connected < 0) | (self.n_connected > m - 1)).any():
                raise ValueError(f"Situation.n_connected must lie in [0, M-1={m - 1}]")
        self._validate_own(params, b)
        self._validate_errors(b, m)
        if self.others is not None:
            if not isinstance(self.others, Others):
                raise ValueError(f"Situation.others must be a safelane.shield.world.Others record or None; got "
                                 f"{type(self.others).__name__}")  # fmt: skip
            self.others.validate(b)

    def _values_pass(self, params: Params, m: int) -> bool:
        """Whether the value rules of :meth:`validate` all hold, in a few array operations over the fields laid end
        to end (a step's validation at batch 1 is otherwise dozens of tiny NumPy calls); ``False`` sends
        :meth:`validate` through the rules one by one, which find and name the offending field."""
        # speeds first (must be >= 0), the promises last (in [0, a_x_d]); every value must be finite
        speeds = (self.ego_vx, self.f_v, self.chain_v.ravel())
        rest = (self.ego_x, self.ego_y, self.ego_vy, self.f_x, self.chain_x.ravel())
        promise = self.chain_promise.ravel()
        values = np.concatenate((*speeds, *rest, promise))
        n_speeds, n_promise = sum(len(a) for a in speeds), len(promise)
        if not np.isfinite(values).all() or (n_speeds and values[:n_speeds].min() < 0):
            return False
        if n_promise and (values[-n_promise:].min() < 0 or values[-n_promise:].max() > params.a_x_d):
            return False
        return len(self.n_connected) == 0 or (self.n_connected.min() >= 0 and self.n_connected.max() <= m - 1)

    def order_problems(self) -> list[tuple[str, str]]:
        """``(field, description)`` of each break of the lanes' order — the target lane's ``F ≤ L1 ≤ L2 ≤ … ≤
        L(N+1)``, the own lane's ``L0 ≤ …`` (one lane: no vehicle is behind the one it follows; equal positions, an
        overlap, are not a break) — the first row of each kind; ``[]`` when there is none. Slots beyond ``L(N+1)``
        are not read by the analysis and not checked. See :meth:`from_arrays` for what the shield makes of it."""
        return order_problems(self)

    def _validate_own(self, params: Params, b: int) -> None:
        own = (self.own_x, self.own_v, self.own_promise, self.own_n_connected)
        if all(a is None for a in own):
            return
        if any(a is None for a in own):
            raise ValueError("Situation.own_x, own_v, own_promise and own_n_connected go together (all or none)")
        if self.own_x.ndim != 2 or self.own_x.shape[0] != b or self.own_x.shape[1] < 1:
            raise ValueError(f"Situation.own_x must have shape ({b}, K >= 1); got {self.own_x.shape}")
        k = self.own_x.shape[1]
        if self.own_v.shape != self.own_x.shape:
            raise ValueError(f"Situation.own_v must have shape {self.own_x.shape}; got {self.own_v.shape}")
        if self.own_promise.shape != (b, k - 1):
            raise ValueError(f"Situation.own_promise must have shape ({b}, {k - 1}); got {self.own_promise.shape}")
        if np.shape(self.own_n_connected) != (b,):
            raise ValueError(f"Situation.own_n_connected must have shape ({b},); got {np.shape(self.own_n_connected)}")
        # each rule one or two array operations (a comparison is false for NaN)
        if not (self.own_x > -np.inf).all():
            raise ValueError("Situation.own_x must be finite, or +inf for 'no vehicle'")
        if not ((self.own_v >= 0) & (self.own_v < np.inf)).all():
            raise ValueError("Situation.own_v must be finite and >= 0 (vehicles do not reverse)")
        if not ((self.own_promise >= 0) & (self.own_promise <= params.a_x_d)).all():
            raise ValueError(f"Situation.own_promise must lie in [0, a_x_d={params.a_x_d}]")
        if b and (self.own_n_connected.min() < 0 or self.own_n_connected.max() > k - 1):
            raise ValueError(f"Situation.own_n_connected must lie in [0, K-1={k - 1}]")
        if k > 1:
            present = np.isfinite(self.own_x)
            if (present[:, 1:] & ~present[:, :-1]).any():
                raise ValueError("Situation.own_x: a vehicle (finite position) behind an empty slot (+inf)")

    def _validate_errors(self, b: int, m: int) -> None:
        k = None if self.own_x is None else self.own_x.shape[1]
        for name, shape in (("err_f", (b, 2)), ("err_chain", (b, m, 2)), ("err_own", (b, k, 2))):
            arr = getattr(self, name)
            if arr is None:
                continue
            if k is None and name == "err_own":
                raise ValueError("Situation.err_own needs own_x (the own-lane leaders it bounds)")
            if np.shape(arr) != shape:
                raise ValueError(f"Situation.{name} must have shape {shape}; got {np.shape(arr)}")
            if not np.isfinite(arr).all() or (arr < 0).any():
                raise ValueError(f"Situation.{name} must be finite and >= 0 (error bounds)")

    @property
    def has_own_lane(self) -> bool:
        """Some row has a vehicle ahead of the ego in its own lane."""
        return self.own_x is not None and bool(np.isfinite(self.own_x[:, 0]).any())

    @property
    def has_errors(self) -> bool:
        return any(getattr(self, n) is not None for n in ("err_f", "err_chain", "err_own"))

    def chain_promise_used(self, a_x_d: float) -> np.ndarray:
        """``(B, M−1)`` promises of the connected leaders, ``a_x_d`` beyond ``L_N`` (they are not connected)."""
        slots = np.arange(self.chain_promise.shape[1])[None, :]
        return np.where(slots < self.n_connected[:, None], self.chain_promise, a_x_d)


@dataclass(frozen=True)
class SensingBounds:
    """Bounds on the measurement error of the others' states, by how the state reaches the ego.

    Defaults (documented in ``docs/real_roads.md``): a connected vehicle's state comes from its own V2X message,
    fused with the ego's sensors (position ±0.5 m, speed ±0.2 m/s); a non-connected vehicle is sensed only (radar or
    lidar at up to ~100 m: position ±1.0 m, speed ±0.5 m/s). Zero bounds give the paper's exact states.
    """

    connected_pos_m: float = 0.5
    connected_speed_mps: float = 0.2
    sensed_pos_m: float = 1.0
    sensed_speed_mps: float = 0.5

    def __post_init__(self):
        for name in ("connected_pos_m", "connected_speed_mps", "sensed_pos_m", "sensed_speed_mps"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"SensingBounds.{name} must be finite and >= 0; got {value!r}")

    def _pair(self, connected) -> np.ndarray:
        connected = np.asarray(connected, bool)
        pos = np.where(connected, self.connected_pos_m, self.sensed_pos_m)
        speed = np.where(connected, self.connected_speed_mps, self.sensed_speed_mps)
        return np.stack([pos, speed], -1)

    def apply(self, situation: Situation) -> Situation:
        """``situation`` with ``err_*`` filled: F by ``f_connected``; the chain's first ``n_connected`` connected;
        the own lane's first ``own_n_connected``."""
        m = situation.chain_x.shape[1]
        chain_conn = np.arange(m)[None, :] < situation.n_connected[:, None]
        out = dict(err_f=self._pair(situation.f_connected), err_chain=self._pair(chain_conn))
        if situation.own_x is not None:
            k = situation.own_x.shape[1]
            out["err_own"] = self._pair(np.arange(k)[None, :] < situation.own_n_connected[:, None])
        return dataclasses.replace(situation, **out)

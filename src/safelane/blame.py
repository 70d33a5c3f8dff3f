"""Who is responsible for a collision or a ``p_m`` violation: RSS's blame rule, one home for every host.

The rule (Shalev-Shwartz, Shammah, Shashua 2017, "On a Formal Model of Safe and Scalable Self-driving Cars", §3:
the dangerous time, its *blame time* and the proper response), for a pair of vehicles — the ego and one other —
driving the same way along ``+x`` on a straight road (``y`` lateral, either sign):

1. **Safe / dangerous.** At a sample the pair is *longitudinally safe* when its bumper-to-bumper distance exceeds
   RSS's safe longitudinal distance (the rear vehicle accelerates at ``accel_max`` for its response time ρ, then
   brakes at ``brake_min``; the front one brakes at ``brake_max``:
   :func:`safelane.baselines.rss.longitudinal_safe_distance_exact`), and *laterally safe* when its edge-to-edge
   distance exceeds RSS's safe lateral distance (each accelerates toward the other at ``lat_accel_max`` for its ρ,
   then brakes laterally at ``lat_brake_min``, plus μ: :func:`~safelane.baselines.rss.lateral_safe_distance`),
   compared as ad-rss compares (greater by at least 1 mm: :func:`~safelane.baselines.rss.is_safe`). It is
   *dangerous* when neither holds. The ego's ρ is ``response_time_ego``, the other's ``response_time_other``.
2. **Blame time.** The last sample at or before the event at which the pair was safe in at least one direction
   (RSS's danger threshold: every sample after it up to the event is dangerous). The event sample itself counts as
   dangerous whatever the distances say (the host says it happened).
3. **Responsible** — the vehicle whose action made the situation dangerous, RSS's Definition of the proper
   response read as blame (who did not respond properly):

   * ``lateral`` — at the blame time the pair was **laterally safe** (RSS checks this first): it became laterally
     unsafe while longitudinally unsafe, a lane change or a drift. Responsible: the vehicle that moved laterally
     toward the other between the blame time and the event (by more than μ/2, RSS's lateral fluctuation), both if
     both did; if neither did by that much, the one that moved more toward the other (both on a tie).
   * ``longitudinal`` — at the blame time the pair was longitudinally safe but not laterally (the same lane, or
     lanes too close): it became longitudinally unsafe. Responsible: the **rear** vehicle (at the blame time),
     which should have kept RSS's distance and braked at ``brake_min`` —
   * ``front_braked`` — unless the **front** vehicle braked harder than ``brake_max`` (by more than ad-rss's
     acceleration precision, 1e-4 m/s², speeds differenced between samples) at some sample after the blame time:
     then the front one is responsible.
   * ``never_safe`` — no safe sample in the record (a simpler, stated rule: the record starts inside the danger):
     the rear vehicle if the two bodies overlapped laterally at the first sample, else the vehicle that moved more
     toward the other since then (both on a tie).

   The answer is ``"ego"``, ``"other"`` or ``"both"`` (``None`` without an event).

**A ``p_m`` violation** is judged like a collision with the safe distances raised to the margins that define it:
``min_lon_gap_m`` (bumper to bumper, e.g. ``p_m − length`` for safelane's centre-to-centre ``p_m``) and
``min_lat_gap_m`` (edge to edge, e.g. ``(lane_width − vehicle_width)/2``, how far a lane-centred vehicle's edge is
from an ego whose body has just reached the lane line): a pair closer than those is never safe.

**Parameters.** Any :class:`~safelane.baselines.rss.RssParams`; the default is ``RssParams()``, ad-rss's documented
starting values (ρ 1 s for the ego and 2 s for the other, ``accel_max`` 3.5, ``brake_min`` 4, ``brake_max`` 8,
``lat_accel_max`` 0.2, ``lat_brake_min`` 0.8 m/s², μ 0.1 m). The hosts pass ``RssParams.matched(params)`` — RSS with
their world's limits (ρ one control period, ``brake_min = brake_max = a_x_d``): with ad-rss's defaults no lane change
of the paper's scenarios (17–22 m gaps) is ever at a safe distance (docs/rss.md), so every contact after one would
be the ego's.

**Sampling.** The rule sees the pair at the host's samples only (velocities as given, or differenced from positions
by a host that has no speeds: say so where it does). A transition between two samples is decided by which direction
was safe at the earlier one.

**Interface** (pure NumPy, batch-first; every array ``(...)`` is a batch of pairs):

* :class:`Track` — one vehicle's ``x, y, vx, vy, length, width`` (a sample: ``(...)``; a trajectory: ``(..., T)``).
* :func:`blame` — trajectories of both vehicles at sample times ``t`` and each pair's event time → :class:`Blame`
  (``responsible``, ``clause``, ``blame_t``, with :meth:`Blame.labels`). A loop over samples only.
* :func:`start` / :func:`update` / :func:`verdict` — the same rule as a running state (:class:`BlameState`, O(1)
  memory per pair) for hosts that see one sample at a time: ``state = update(state, t, ego, other, rss)`` every
  sample, ``verdict(state)`` when an event happens (after the update with the event's sample). :func:`blame` is
  this fold.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .baselines.rss import RssParams, is_safe, lateral_safe_distance, longitudinal_safe_distance_exact
from .errors import InputError

#: Responsible-party codes (a bit mask: ``BOTH = EGO | OTHER``); ``NONE``: no event.
NONE, EGO, OTHER, BOTH = 0, 1, 2, 3
#: Labels of the codes: ``RESPONSIBLE[code]``.
RESPONSIBLE = (None, "ego", "other", "both")
#: Clause codes and their names: ``CLAUSES[code]`` (``""``: no event).
NO_CLAUSE, LONGITUDINAL, FRONT_BRAKED, LATERAL, NEVER_SAFE = 0, 1, 2, 3, 4
CLAUSES = ("", "longitudinal", "front_braked", "lateral", "never_safe")
#: ad-rss's acceleration precision [m/s²]: a front vehicle brakes "harder than brake_max" beyond it.
BRAKE_TOL_MPS2 = 1e-4

_DEFAULT_RSS = RssParams()


class Track(NamedTuple):
    """One vehicle's state: centre ``x, y`` [m], velocity ``vx, vy`` [m/s], body ``length, width`` [m]; arrays that
    broadcast (a sample: ``(...)``; a trajectory: ``(..., T)``, where ``length``/``width`` may be ``(...)``). In
    :func:`blame` a non-finite ``x`` marks a sample the host did not record (padding)."""

    x: np.ndarray
    y: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    length: np.ndarray
    width: np.ndarray


@dataclass(frozen=True)
class Blame:
    """Per event ``(...)``: ``responsible`` (:data:`NONE`, :data:`EGO`, :data:`OTHER`, :data:`BOTH`), ``clause``
    (:data:`CLAUSES` codes), ``blame_t`` (the blame time [s]; NaN for ``never_safe`` and without an event)."""

    responsible: np.ndarray
    clause: np.ndarray
    blame_t: np.ndarray

    def labels(self) -> np.ndarray:
        """``responsible`` as ``None``/``"ego"``/``"other"``/``"both"`` (an object array of the same shape)."""
        return _lookup(RESPONSIBLE, self.responsible)

    def clause_names(self) -> np.ndarray:
        """``clause`` as its names (``""`` without an event)."""
        return _lookup(CLAUSES, self.clause)

    @property
    def ego_responsible(self) -> np.ndarray:
        """The ego is responsible (alone or with the other)."""
        return (self.responsible & EGO) != 0


def _lookup(names, codes) -> np.ndarray:
    codes = np.asarray(codes)
    return np.asarray(names, object)[codes.reshape(-1)].reshape(codes.shape)


@dataclass(frozen=True)
class BlameState:
    """The running rule for a batch of pairs ``(...)``: the last safe sample (the *anchor*; the first sample until
    one is safe) and what the verdict needs from it and since it."""

    seen: np.ndarray  # any sample yet
    t_safe: np.ndarray  # time of the last safe sample (NaN: none yet)
    lat_safe: np.ndarray  # at the anchor: laterally safe
    overlap: np.ndarray  # at the anchor: the bodies overlap laterally
    ego_x: np.ndarray  # at the anchor
    other_x: np.ndarray
    ego_y: np.ndarray
    other_y: np.ndarray
    ego_overbraked: np.ndarray  # braked harder than brake_max at some sample after the anchor
    other_overbraked: np.ndarray
    t: np.ndarray  # the latest sample
    ego_vx: np.ndarray
    other_vx: np.ndarray
    ego_y_now: np.ndarray
    other_y_now: np.ndarray

    def where(self, mask, other: BlameState) -> BlameState:
        """This state where ``mask``, ``other`` elsewhere."""
        return BlameState(**{f.name: np.where(mask, getattr(self, f.name), getattr(other, f.name))
                             for f in dataclasses.fields(self)})  # fmt: skip

    def take(self, index) -> BlameState:
        """The pairs ``index`` (along the leading axis)."""
        return BlameState(**{f.name: getattr(self, f.name)[index] for f in dataclasses.fields(self)})


def start(shape=()) -> BlameState:
    """A state for a batch of pairs of ``shape`` that has seen nothing."""
    nan, false = np.full(shape, np.nan), np.zeros(shape, bool)
    return BlameState(seen=false, t_safe=nan, lat_safe=false, overlap=false, ego_x=nan, other_x=nan, ego_y=nan,
                      other_y=nan, ego_overbraked=false, other_overbraked=false, t=nan, ego_vx=nan, other_vx=nan,
                      ego_y_now=nan, other_y_now=nan)  # fmt: skip


def pair_safety(ego: Track, other: Track, rss: RssParams = _DEFAULT_RSS, min_lon_gap_m=0.0, min_lat_gap_m=0.0):
    """``(lon_safe, lat_safe, lat_overlap)`` of the pairs at one sample (module docstring, step 1); arrays
    broadcast."""
    other_ahead = other.x > ego.x
    lon_distance = np.maximum(np.abs(other.x - ego.x) - 0.5 * (ego.length + other.length), 0.0)
    v_e, v_o = np.maximum(ego.vx, 0.0), np.maximum(other.vx, 0.0)  # RSS takes speeds >= 0 (vehicles stop)
    lon_needed = longitudinal_safe_distance_exact(
        np.where(other_ahead, v_o, v_e), np.where(other_ahead, v_e, v_o),
        np.where(other_ahead, rss.response_time_ego, rss.response_time_other), rss.accel_max, rss.brake_min,
        rss.brake_max, rss.max_speed_on_acceleration, rss.min_longitudinal_safety_distance,
    )  # fmt: skip
    lateral_gap = np.abs(other.y - ego.y) - 0.5 * (ego.width + other.width)
    # ad-rss's lateral axis points from the upper vehicle (larger y) to the lower one: its lateral speeds are -vy.
    other_upper = other.y > ego.y
    lat_needed = lateral_safe_distance(
        np.where(other_upper, -other.vy, -ego.vy), np.where(other_upper, rss.response_time_other,
                                                            rss.response_time_ego),
        np.where(other_upper, -ego.vy, -other.vy), np.where(other_upper, rss.response_time_ego,
                                                            rss.response_time_other),
        rss.lat_accel_max, rss.lat_brake_min, rss.lateral_fluctuation_margin,
    )  # fmt: skip
    lon_safe = is_safe(lon_distance, np.maximum(lon_needed, min_lon_gap_m))
    lat_safe = is_safe(np.maximum(lateral_gap, 0.0), np.maximum(lat_needed, min_lat_gap_m))
    return lon_safe, lat_safe, lateral_gap < 0.0


def update(state: BlameState, t, ego: Track, other: Track, rss: RssParams = _DEFAULT_RSS, *, min_lon_gap_m=0.0,
           min_lat_gap_m=0.0, active=True) -> BlameState:  # fmt: skip
    """The state after one more sample at time ``t`` (after the previous one) of the pairs ``(ego, other)``; pairs
    where ``active`` is false keep their state. ``min_lon_gap_m``, ``min_lat_gap_m``: module docstring (``p_m``)."""
    ego, other = (Track(*(np.asarray(q, float) for q in tr)) for tr in (ego, other))
    lon_safe, lat_safe, overlap = pair_safety(ego, other, rss, min_lon_gap_m, min_lat_gap_m)
    safe = lon_safe | lat_safe
    anchor = safe | ~state.seen
    limit = rss.brake_max + BRAKE_TOL_MPS2
    with np.errstate(invalid="ignore", divide="ignore"):
        span = t - state.t
        ok = state.seen & (span > 0.0)
        ego_over = ok & ((state.ego_vx - np.maximum(ego.vx, 0.0)) / np.where(ok, span, 1.0) > limit)
        other_over = ok & ((state.other_vx - np.maximum(other.vx, 0.0)) / np.where(ok, span, 1.0) > limit)
    shape = np.broadcast_shapes(np.shape(state.seen), np.shape(lon_safe), np.shape(active))
    b = lambda a: np.broadcast_to(a, shape)  # noqa: E731
    new = BlameState(
        seen=b(True), t_safe=b(np.where(safe, t, state.t_safe)),
        lat_safe=b(np.where(anchor, lat_safe, state.lat_safe)), overlap=b(np.where(anchor, overlap, state.overlap)),
        ego_x=b(np.where(anchor, ego.x, state.ego_x)), other_x=b(np.where(anchor, other.x, state.other_x)),
        ego_y=b(np.where(anchor, ego.y, state.ego_y)), other_y=b(np.where(anchor, other.y, state.other_y)),
        ego_overbraked=b(~anchor & (state.ego_overbraked | ego_over)),
        other_overbraked=b(~anchor & (state.other_overbraked | other_over)),
        t=b(np.asarray(t, float)), ego_vx=b(np.maximum(ego.vx, 0.0)), other_vx=b(np.maximum(other.vx, 0.0)),
        ego_y_now=b(ego.y), other_y_now=b(other.y),
    )  # fmt: skip
    if active is True:
        return new
    return new.where(b(active), BlameState(**{f.name: b(getattr(state, f.name)) for f in dataclasses.fields(state)}))


def verdict(state: BlameState, rss: RssParams = _DEFAULT_RSS, event=True) -> Blame:
    """Who is responsible for an event at the state's latest sample (module docstring, step 3), where ``event``
    (``(...)``, default all) — :data:`NONE` elsewhere and where no sample was seen."""
    event = np.asarray(event, bool) & state.seen
    toward = np.where(state.other_y >= state.ego_y, 1.0, -1.0)  # from the ego toward the other, at the anchor
    ego_moved = (state.ego_y_now - state.ego_y) * toward
    other_moved = -(state.other_y_now - state.other_y) * toward
    tol = 0.5 * rss.lateral_fluctuation_margin
    moved = np.where(ego_moved > tol, EGO, NONE) | np.where(other_moved > tol, OTHER, NONE)
    more = np.where(ego_moved > other_moved, EGO, np.where(other_moved > ego_moved, OTHER, BOTH))
    mover = np.where(moved != NONE, moved, more)
    ego_behind = state.ego_x < state.other_x
    rear = np.where(ego_behind, EGO, np.where(state.ego_x > state.other_x, OTHER, BOTH))
    front_over = np.where(ego_behind, state.other_overbraked, state.ego_overbraked)
    never = np.isnan(state.t_safe)
    lateral = ~never & state.lat_safe
    clause = np.select([never, lateral, front_over], [NEVER_SAFE, LATERAL, FRONT_BRAKED], LONGITUDINAL)
    front = np.where(ego_behind, OTHER, EGO)
    who = np.select([never & state.overlap, never, lateral, front_over], [rear, mover, mover, front], rear)
    return Blame(responsible=np.where(event, who, NONE).astype(np.int8),
                 clause=np.where(event, clause, NO_CLAUSE).astype(np.int8),
                 blame_t=np.where(event & ~never, state.t_safe, np.nan))  # fmt: skip


def _field(name: str, value, shape=None):
    a = np.asarray(value, float)
    if shape is not None:
        try:
            a = np.broadcast_to(a, shape)
        except ValueError:
            raise InputError(f"blame: {name} has shape {np.shape(value)}, which does not broadcast to the pairs' "
                             f"trajectories {shape}", name) from None  # fmt: skip
    return a


def blame(t, ego: Track, other: Track, event_t, rss: RssParams = _DEFAULT_RSS, *, min_lon_gap_m=0.0,
          min_lat_gap_m=0.0) -> Blame:  # fmt: skip
    """The rule (module docstring) for a batch of pairs from their trajectories.

    ``t``: sample times [s], ``(T,)`` or ``(..., T)``, increasing along the last axis; ``ego``, ``other``:
    :class:`Track` s of ``(..., T)`` arrays (``length``/``width`` also ``(...)`` or scalars; a non-finite ``x``:
    not recorded); ``event_t``: ``(...)``, each pair's event time (NaN: no event). Samples after the event are
    ignored. ``min_lon_gap_m``, ``min_lat_gap_m``: ``(...)`` or scalars, for ``p_m`` violations.
    Bad input raises :class:`~safelane.errors.InputError` naming the field.
    """
    if not isinstance(ego, Track) or not isinstance(other, Track):
        raise InputError("blame: ego and other must be Track(x, y, vx, vy, length, width)", "ego")
    t = np.asarray(t, float)
    if t.ndim == 0 or t.shape[-1] == 0:
        raise InputError(f"blame: t must have a time axis with at least one sample; got shape {t.shape}", "t")
    event_t = np.asarray(event_t, float)
    try:
        shape = np.broadcast_shapes(*(np.shape(getattr(tr, q)) for tr in (ego, other) for q in ("x", "y", "vx",
                                                                                               "vy")),
                                    t.shape, (*event_t.shape, t.shape[-1]))  # fmt: skip
    except ValueError:
        raise InputError(f"blame: the shapes of t {t.shape}, event_t {event_t.shape} and the tracks' x, y, vx, vy "
                         f"do not broadcast to one (..., T)", "ego.x") from None  # fmt: skip
    tracks = {}
    for who, tr in (("ego", ego), ("other", other)):
        fields = {}
        for q in ("x", "y", "vx", "vy"):
            fields[q] = _field(f"{who}.{q}", getattr(tr, q), shape)
        recorded = np.isfinite(fields["x"])
        for q in ("y", "vx", "vy"):
            bad = recorded & ~np.isfinite(fields[q])
            if bad.any():
                raise InputError(f"blame: {who}.{q} is not finite at {int(bad.sum())} recorded sample(s) (x finite)",
                                 f"{who}.{q}")  # fmt: skip
        for q in ("length", "width"):
            a = np.asarray(getattr(tr, q), float)
            if a.ndim and a.ndim == len(shape) - 1:
                a = a[..., None]
            a = _field(f"{who}.{q}", a, shape)
            if not (np.isfinite(a) & (a > 0.0)).all():
                raise InputError(f"blame: {who}.{q} must be finite and > 0 [m]", f"{who}.{q}")
            fields[q] = a
        tracks[who] = (Track(**fields), recorded)
    tt = np.broadcast_to(t, shape)
    if not np.isfinite(tt).all():
        raise InputError("blame: t must be finite", "t")
    if shape[-1] > 1 and not (np.diff(tt, axis=-1) > 0.0).all():
        raise InputError("blame: t must increase along the time axis", "t")
    if np.isinf(event_t).any():
        raise InputError("blame: event_t must be finite or NaN (no event)", "event_t")
    (e, e_rec), (o, o_rec) = tracks["ego"], tracks["other"]
    event_t = np.broadcast_to(event_t, shape[:-1])
    state = start(shape[:-1])
    with np.errstate(invalid="ignore"):
        for k in range(shape[-1]):
            active = e_rec[..., k] & o_rec[..., k] & (tt[..., k] <= event_t)
            state = update(state, tt[..., k], Track(*(q[..., k] for q in e)), Track(*(q[..., k] for q in o)), rss,
                           min_lon_gap_m=min_lon_gap_m, min_lat_gap_m=min_lat_gap_m, active=active)  # fmt: skip
    return verdict(state, rss, event=np.isfinite(event_t))


class PairTracker:
    """The running rule for one ego against a changing set of other vehicles, keyed by the host's ids (vehicles come
    and go; one that is not observed in a sample is forgotten). For hosts that step one sample at a time (highway-env,
    SUMO): :meth:`observe` every sample, :meth:`verdict` for the vehicles of an event."""

    def __init__(self, rss: RssParams = _DEFAULT_RSS, *, min_lon_gap_m: float = 0.0, min_lat_gap_m: float = 0.0):
        self.rss, self.min_lon_gap_m, self.min_lat_gap_m = rss, min_lon_gap_m, min_lat_gap_m
        self.ids: list = []
        self.state = start((0,))

    def observe(self, t: float, ego: Track, ids, others: Track) -> None:
        """One sample at time ``t``: the ego (scalars) and the other vehicles ``ids`` (``others``: ``(n,)`` arrays)."""
        ids = list(ids)
        row = {key: i for i, key in enumerate(self.ids)}
        rows = np.array([row.get(key, -1) for key in ids], np.int64)
        known = rows >= 0
        prior = start((len(ids),))
        if known.any():
            prior = self.state.take(np.where(known, rows, 0)).where(known, prior)
        self.state = update(prior, t, ego, others, self.rss, min_lon_gap_m=self.min_lon_gap_m,
                            min_lat_gap_m=self.min_lat_gap_m)  # fmt: skip
        self.ids = ids

    def verdict(self, ids) -> Blame:
        """The rule for an event with each of ``ids`` at the latest sample (:data:`NONE` for an id not observed)."""
        row = {key: i for i, key in enumerate(self.ids)}
        rows = np.array([row.get(key, -1) for key in ids], np.int64)
        if not len(self.ids):
            return verdict(start((len(rows),)), self.rss)
        out = verdict(self.state.take(np.where(rows >= 0, rows, 0)), self.rss, event=rows >= 0)
        return out

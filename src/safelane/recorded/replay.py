"""Open-loop replay: the shield's verdict, every 0.1 s, on what a recorded human actually did (docs/real_traffic.md).

The human keeps driving as recorded: nothing the shield says changes the trajectory (an open-loop judgement; the
closed loop on the log is :mod:`.log_loop`'s). For every event-frame of :func:`.events.event_frames`:

1. **The situation** (:func:`situations`) in the shield's frame: the changing vehicle is the ego; its ``x`` and
   speed as recorded, its lateral state mapped by a :class:`~safelane.shield.LaneFrame` that puts the line it
   crosses at ``lane_width / 2`` (``y = ±(y_rec − line) + lane_width/2``, positive toward the target lane: the
   crossing instant is the same in both frames). The shield knows one vehicle length (``Params.vehicle_length``);
   the others' positions are shifted so that every bumper-to-bumper gap to the ego is the recorded one. F, L1..LK
   and L0 as :func:`.events.event_frames` finds them; a vehicle the recording does not have (outside the filmed
   stretch) is absent (F 1 km behind, leaders 1 km ahead: they never bind).
2. **The proposal**: the human's accelerations over the next 0.1 s (those that take the recorded state to the next
   recorded position exactly), clipped into the shield's admissible box (``[−a_x_d, a_x_a]``, ``|a_y| ≤ a_y_m``;
   ``clipped`` says where that changed them).
3. **The verdict**: a fresh shield (``Shield.from_preset``) is reset on the situation and steps once with that
   proposal — every event-frame at once, one batch. Fresh, because the recording, not the shield, decided what
   happened before: no held plan, no history for the aggressiveness assessment (a non-connected F is taken for
   aggressive), no commands in flight (the actuation delay is set to 0: the recording is the executed motion).
4. **The crossing check** (``crossing_verdict``): the same, with the ego's lateral state replaced by the one it had
   at its crossing step (and that step's lateral acceleration): would the shield have let it cross *now*? At the
   crossing step itself the two agree. Its first ``proceed`` at or after the human's crossing gives the delay.
5. **RSS** on the same situations and proposals: the shield's RSS decision rule (``RSS``: ad-rss's default
   parameters, no V2X; ``RSS_V2X`` when some vehicles are connected), the NumPy closed forms that
   ``tests/test_rss.py`` holds against ad-rss; where ad-rss imports, its own pair checks on the crossing rows are
   compared (:func:`adrss_agreement`).

**Connectivity** (a stated assumption; NGSIM drivers had none): each recorded vehicle is connected with probability
``connected_share`` (seeded; 0: none, 1: all). A connected leader broadcasts its state and promises not to brake
harder than ``promise_decel`` (it is human-driven: ``p_m_human``); a connected F broadcasts its state but declares
no collaboration. Connectivity narrows the sensing-error bounds and lets ``CV_all`` use the chain.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..shield import ABORT, COMPLETED, HESITATE, PROCEED, Shield, Situation
from ..shield.situation import LaneFrame
from ..tolerances import TIME_TOL_S
from .events import EventFrames, LaneChangeEvent, event_frames, find_lane_changes
from .recording import Recording

VERDICT_NAMES = {PROCEED: "proceed", HESITATE: "hesitate", ABORT: "abort", COMPLETED: "completed", -1: "crossed"}
#: Where the recording has no vehicle: this far behind (F) or ahead (leaders, in steps) of the ego [m].
ABSENT_M = 1000.0


@dataclass(frozen=True)
class ReplaySettings:
    """What a replay assumes (recorded in ``run.json``).

    Attributes:
        preset: the shield's preset (``realistic``: the own lane, sensing error; docs/real_roads.md).
        variant: the shield's variant (``CV_all``: uses whatever connectivity there is).
        connected_share: probability that a recorded vehicle is connected, in ``[0, 1]``.
        seed: seeds the connectivity draw.
        promise_decel: a connected leader's promised maximum deceleration [m/s²].
        before_s, after_s: the window around each crossing.
        n_leaders: target-lane leaders in the chain (``L1..LK``).
    """

    preset: str = "realistic"
    variant: str = "CV_all"
    connected_share: float = 0.0
    seed: int = 0
    promise_decel: float = 0.5
    before_s: float = 3.0
    after_s: float = 2.0
    n_leaders: int = 3

    def __post_init__(self):
        from ..errors import InputError

        if not 0.0 <= self.connected_share <= 1.0:
            raise InputError(f"connected_share must lie in [0, 1]; got {self.connected_share!r}", "connected_share")
        if self.before_s < 0.1 or self.after_s < 0.0:
            raise InputError("before_s must be >= 0.1 and after_s >= 0", "before_s")

    @property
    def rss_variant(self) -> str:
        return "RSS_V2X" if self.connected_share > 0.0 else "RSS"


@dataclass(frozen=True)
class ReplayResult:
    """One recording's replay.

    Attributes:
        source: the file.
        rows: one row per event-frame (columns in docs/real_traffic.md).
        events: one row per replayed event (allowed at the crossing, delay, margins; the same for RSS).
        skipped: ``(event, why)`` of lane changes not replayed (no target-lane vehicle at the crossing).
        adrss: ``(agreeing, compared)`` pair verdicts of ad-rss and the NumPy RSS on the crossing rows, or ``None``
            where ad-rss is not installed.
    """

    source: str
    rows: pd.DataFrame
    events: pd.DataFrame
    skipped: list[tuple[LaneChangeEvent, str]]
    adrss: tuple[int, int] | None


def _shifted(rec: Recording, other: np.ndarray, ego: np.ndarray, frame: np.ndarray, length: float, ahead: bool):
    """Positions of ``other`` rows (``-1``: absent) shifted so the bumper gap to the ego is the recorded one with
    every vehicle ``length`` long; absent ones ``ABSENT_M`` away (leaders: one more km per slot)."""
    present = other >= 0
    idx = np.where(present, other, 0)
    f = frame if other.ndim == 1 else frame[:, None]
    e = ego if other.ndim == 1 else ego[:, None]
    half = 0.5 * (rec.length[idx] + rec.length[e])
    x = rec.x[idx, f] + (half - length if ahead else length - half)
    ex = rec.x[e, f]
    steps = 1.0 if other.ndim == 1 else np.arange(1, other.shape[1] + 1)[None, :]
    far = ex + ABSENT_M * steps if ahead else ex - ABSENT_M * steps
    v = np.where(present, rec.speed[idx, f], rec.speed[e, f])
    return np.where(present, x, far), v


def human_accelerations(rec: Recording, ego: np.ndarray, frame: np.ndarray):
    """``(a_x, a_y, vx, vy)`` per row: the constant accelerations that take the recorded state at ``frame`` to the
    recorded position at ``frame + 1`` (the recorded ``accel`` and lateral acceleration at a vehicle's last frame);
    ``vx`` from speed and lateral speed."""
    vy_all = rec.lateral_speed()
    vy = vy_all[ego, frame]
    vx = np.sqrt(np.maximum(rec.speed[ego, frame] ** 2 - vy**2, 0.0))
    nxt = np.minimum(frame + 1, rec.n_frames - 1)
    has_next = (frame + 1 < rec.n_frames) & rec.valid[ego, nxt]
    dt = rec.dt
    a_x = np.where(has_next, 2.0 * (rec.x[ego, nxt] - rec.x[ego, frame] - vx * dt) / dt**2, rec.accel[ego, frame])
    a_y = np.where(has_next, 2.0 * (rec.y[ego, nxt] - rec.y[ego, frame] - vy * dt) / dt**2,
                   rec.lateral_accel()[ego, frame])  # fmt: skip
    return a_x, a_y, vx, vy


def situations(rec: Recording, fr: EventFrames, settings: ReplaySettings, params, sensing, lateral=None):
    """``(Situation, LaneFrame arrays (origin, sign), connected)`` for every event-frame (module docstring, step 1).
    ``lateral``: ``(y_rec, vy_rec)`` to use instead of the ego's recorded lateral state (the crossing check)."""
    rng = np.random.default_rng(settings.seed)
    connected = rng.random(rec.n_vehicles) < settings.connected_share
    ego, frame = fr.ego, fr.frame
    _, _, vx, vy = human_accelerations(rec, ego, frame)
    y = rec.y[ego, frame] if lateral is None else lateral[0]
    vy = vy if lateral is None else lateral[1]
    sign = np.where(fr.to_left, 1.0, -1.0)
    origin = fr.line_y - sign * 0.5 * params.lane_width
    shield_y, shield_vy = sign * (y - origin), sign * vy  # LaneFrame(origin, sign) row by row
    length = params.vehicle_length
    fx, fv = _shifted(rec, fr.follower, ego, frame, length, ahead=False)
    lx, lv = _shifted(rec, fr.leaders, ego, frame, length, ahead=True)
    lx = np.concatenate([lx, (rec.x[ego, frame] + ABSENT_M * (fr.leaders.shape[1] + 1))[:, None]], axis=1)
    lv = np.concatenate([lv, rec.speed[ego, frame][:, None]], axis=1)  # L(K+1): never connected
    lead_conn = (fr.leaders >= 0) & connected[np.where(fr.leaders >= 0, fr.leaders, 0)]
    n_conn = np.cumprod(lead_conn, axis=1).sum(axis=1)
    f_conn = (fr.follower >= 0) & connected[np.where(fr.follower >= 0, fr.follower, 0)]
    ox, ov = _shifted(rec, fr.own_leader, ego, frame, length, ahead=True)
    has_own = fr.own_leader >= 0
    own_conn = has_own & connected[np.where(has_own, fr.own_leader, 0)]
    with warnings.catch_warnings():  # the lanes' order after the length shift: conservative, see from_arrays
        warnings.simplefilter("ignore")
        situation = Situation.from_arrays(
            t=0.0, ego=(rec.x[ego, frame], shield_y, vx, shield_vy), follower=(fx, fv), leaders=(lx, lv),
            n_connected=n_conn, promise_decel=settings.promise_decel, human_driven=True, f_connected=f_conn,
            f_collaborative=False, frame=LaneFrame(), params=params,
            own_leaders=(np.stack([np.where(has_own, ox, np.inf), np.full(len(ox), np.inf)], 1),
                         np.stack([ov, ov], 1)),
            own_n_connected=own_conn.astype(int), own_promise=settings.promise_decel,
            sensing=sensing, geometry="ignore",
        )  # fmt: skip
    return situation, (origin, sign), connected


def _judge(situation: Situation, proposal, settings: ReplaySettings, variant: str):
    shield = Shield.from_preset(settings.preset, variant=variant, config={"actuation_delay_s": 0.0})
    shield.reset(situation)
    return shield.step(situation, proposal)


def replay(recording: Recording, settings: ReplaySettings | None = None) -> ReplayResult:
    """Every lane change of ``recording`` with a target-lane vehicle at its crossing, replayed (module docstring)."""
    from ..sim.preset import load_preset

    cfg = settings or ReplaySettings()
    rec = recording
    preset = load_preset(cfg.preset)
    params = preset.params
    sensing = preset.sim.sensing_bounds() if preset.sim.shield.sensing else None
    events = find_lane_changes(rec)
    fr_all = event_frames(rec, events, cfg.before_s, cfg.after_s, cfg.n_leaders)
    # The crossing step: from the last frame in the old lane (t_rel = -dt) to the first in the new one.
    at_cross = np.isclose(fr_all.t_rel, -rec.dt)
    has_neighbour = np.zeros(len(events), bool)
    has_neighbour[fr_all.event[at_cross]] = (fr_all.follower[at_cross] >= 0) | (fr_all.leaders[at_cross, 0] >= 0)
    skipped = [(e, "no target-lane vehicle at the crossing") for e, ok in zip(events, has_neighbour, strict=True)
               if not ok]  # fmt: skip
    kept = np.flatnonzero(has_neighbour)
    events = [events[i] for i in kept]
    fr = event_frames(rec, events, cfg.before_s, cfg.after_s, cfg.n_leaders)
    if not events:
        return ReplayResult(rec.source, pd.DataFrame(), pd.DataFrame(), skipped, None)

    a_x, a_y, _, vy = human_accelerations(rec, fr.ego, fr.frame)
    ax_c = np.clip(a_x, -params.a_x_d, params.a_x_a)
    ay_c = np.clip(a_y, -params.a_y_m, params.a_y_m)
    clipped = (ax_c != a_x) | (ay_c != a_y)
    situation, _, connected = situations(rec, fr, cfg, params, sensing)
    # the crossing check: every row at its event's crossing-step lateral state and lateral acceleration
    cross_row = np.full(len(events), -1)
    crossing = np.isclose(fr.t_rel, -rec.dt)
    cross_row[fr.event[crossing]] = np.flatnonzero(crossing)
    c = cross_row[fr.event]
    lateral = (rec.y[fr.ego[c], fr.frame[c]], vy[c])
    crossing_situation, _, _ = situations(rec, fr, cfg, params, sensing, lateral)
    cross_proposal = (ax_c, ay_c[c])

    shield_y = situation.ego_y
    out = {"t_rel_s": fr.t_rel, "y_to_line_m": shield_y - 0.5 * params.lane_width, "clipped": clipped}
    for tag, variant in (("shield", cfg.variant), ("rss", cfg.rss_variant)):
        human = _judge(situation, (ax_c, ay_c), cfg, variant)
        cross = _judge(crossing_situation, cross_proposal, cfg, variant)
        # the human's steps up to and including the crossing step; after it the lane change is done (open loop:
        # what follows is following L1, which the closed loop judges)
        out[f"{tag}_verdict"] = np.where(fr.t_rel < -TIME_TOL_S, human.behaviour, -1)
        out[f"{tag}_crossing_verdict"] = cross.behaviour
        if tag == "shield":
            out["margin_l1_m"] = np.where(fr.leaders[:, 0] >= 0, human.plan.min_gap_leader - params.p_m, np.nan)
            out["margin_f_m"] = np.where(fr.follower >= 0, human.plan.min_gap_follower - params.p_m, np.nan)
    rss = _rss_margins(situation, params)
    out["rss_margin_l1_m"] = np.where(fr.leaders[:, 0] >= 0, rss["rss_margin_l1_m"], np.nan)
    out["rss_margin_f_m"] = np.where(fr.follower >= 0, rss["rss_margin_f_m"], np.nan)
    rows = _rows_table(rec, fr, out, connected, cfg)
    return ReplayResult(rec.source, rows, _events_table(rec, events, rows, cfg), skipped,
                        adrss_agreement(situation, params, crossing))  # fmt: skip


def _rss_margins(situation: Situation, params) -> dict[str, np.ndarray]:
    """RSS's longitudinal margins (distance − safe distance, bumper to bumper, ad-rss's defaults) to L1 (ego behind)
    and to F (F behind the ego), at the row's state."""
    from ..baselines.rss import longitudinal_safe_distance, rss_params_for

    rss = rss_params_for("ad_rss", params)
    ex, ev = situation.ego_x, situation.ego_vx
    l1x, l1v = situation.chain_x[:, 0], situation.chain_v[:, 0]
    fx, fv = situation.f_x, situation.f_v
    common = (rss.accel_max, rss.brake_min, rss.brake_max, rss.max_speed_on_acceleration,
              rss.min_longitudinal_safety_distance)  # fmt: skip
    safe_l1 = longitudinal_safe_distance(l1v, ev, rss.response_time_ego, *common)
    safe_f = longitudinal_safe_distance(ev, fv, rss.response_time_other, *common)
    length = params.vehicle_length
    return {"rss_margin_l1_m": (l1x - ex - length) - safe_l1, "rss_margin_f_m": (ex - fx - length) - safe_f}


def adrss_agreement(situation: Situation, params, rows: np.ndarray) -> tuple[int, int] | None:
    """``(agreeing, compared)``: ad-rss's pair verdicts (ego–L1, ego–F, both in the target lane's centre) against
    the NumPy closed forms on ``rows``; ``None`` without ad-rss. A loop over a few rows: a check, not a hot path."""
    from ..baselines import rss as rss_np
    from ..baselines import rss_adrss

    if not rss_adrss.available():
        return None
    rss = rss_np.rss_params_for("ad_rss", params)
    agree = total = 0
    lane = params.lane_width
    for i in np.flatnonzero(rows):
        ego = (situation.ego_x[i], situation.ego_y[i], situation.ego_vx[i], situation.ego_vy[i])
        for x, v in ((situation.chain_x[i, 0], situation.chain_v[i, 0]), (situation.f_x[i], situation.f_v[i])):
            ours = bool(rss_np.pair_check(*ego, x, lane, v, 0.0, rss, params)[0])
            theirs = bool(rss_adrss.pair_check(*ego, x, lane, v, 0.0, rss, params)[0])
            agree += ours == theirs
            total += 1
    return agree, total


def _rows_table(rec, fr: EventFrames, out, connected, cfg: ReplaySettings) -> pd.DataFrame:
    def vid(rows):
        return np.where(rows >= 0, rec.vehicle_ids[np.where(rows >= 0, rows, 0)], -1)

    table = pd.DataFrame({
        "file": rec.source, "event": fr.event, "vehicle_id": rec.vehicle_ids[fr.ego], "frame": fr.frame,
        "t_s": rec.t[fr.frame], **{k: v for k, v in out.items() if not k.endswith("verdict")},
        "f_id": vid(fr.follower), "l1_id": vid(fr.leaders[:, 0]), "l0_id": vid(fr.own_leader),
        "entrant_ids": [" ".join(str(v) for v in vid(row) if v >= 0) for row in fr.entrants],
        "f_connected": (fr.follower >= 0) & connected[np.where(fr.follower >= 0, fr.follower, 0)],
        "connected_share": cfg.connected_share,
    })  # fmt: skip
    for key, codes in out.items():
        if key.endswith("verdict"):
            table[key] = [VERDICT_NAMES.get(int(code), str(code)) for code in codes]
    return table


def _first_allowed(t_rel: np.ndarray, allowed: np.ndarray, dt: float) -> tuple[float, float]:
    """``(first t_rel allowed in the window, delay from the crossing step until allowed)``; NaN where never."""
    first = t_rel[allowed].min() if allowed.any() else np.nan
    later = allowed & (t_rel >= -dt - TIME_TOL_S)
    delay = t_rel[later].min() + dt if later.any() else np.nan
    return float(first), float(delay)


def _events_table(rec: Recording, events: list[LaneChangeEvent], rows: pd.DataFrame, cfg) -> pd.DataFrame:
    """One row per event (a loop over events: a handful per file; the verdicts are already batched)."""
    out = []
    for k, e in enumerate(events):
        r = rows[rows["event"] == k]
        cross = r[np.isclose(r["t_rel_s"], -rec.dt)].iloc[0]
        item = {"file": rec.source, "event": k, "vehicle_id": e.vehicle_id, "crossing_t_s": e.crossing_t,
                "from_lane": e.from_lane, "to_lane": e.to_lane, "direction": "left" if e.to_left else "right",
                "f_id": int(cross["f_id"]), "l1_id": int(cross["l1_id"]), "connected_share": cfg.connected_share,
                "clipped_at_crossing": bool(cross["clipped"])}  # fmt: skip
        for tag in ("shield", "rss"):
            allowed = (r[f"{tag}_crossing_verdict"] == "proceed").to_numpy()
            first, delay = _first_allowed(r["t_rel_s"].to_numpy(), allowed, rec.dt)
            item[f"{tag}_allowed"] = cross[f"{tag}_verdict"] == "proceed"
            item[f"{tag}_verdict_at_crossing"] = cross[f"{tag}_verdict"]
            item[f"{tag}_first_allowed_t_rel_s"] = first
            item[f"{tag}_delay_s"] = delay
        for col in ("margin_l1_m", "margin_f_m", "rss_margin_l1_m", "rss_margin_f_m"):
            item[col] = float(cross[col])
        out.append(item)
    return pd.DataFrame(out)

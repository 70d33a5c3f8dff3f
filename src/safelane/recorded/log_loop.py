"""Closed loop on the log: each recorded lane change redone by safelane's planner under the shield, the other
vehicles replayed as recorded (non-reactive) — the log-playback mode of Waymax and nuPlan, and how Pek et al. (2020)
ran their fail-safe verification on recorded highway traffic.

For every :class:`~.events.LaneChangeEvent`, from ``lead_s`` before the human's crossing (no earlier than the
recording's start or the first frame of the human's run in its original lane), the lane-changing vehicle is replaced
by an **ego** starting at the human's recorded state (position, speed, lateral position and speed), with the human's
length and width, the human's target lane, and the **human's gap**: the planner aims between the target-lane
follower and leader the human had at its crossing (:func:`~.events.event_frames`). The shield judges with the
vehicles actually around the ego each period (the nearest behind / ahead in the target lane, the nearest ahead in
its own lane), so the gap choice never hides a vehicle from it. All events run as one batch: one
:meth:`Shield.step <safelane.shield.Shield.step>` per 0.1 s over every event (the loop is over time steps only).

**Mapping into the shield's frame**, per event: ``x`` is the recording's; the lateral position ``y`` [m] is measured
from the original lane's centre toward the target lane (:func:`~.log_batch.lane_frame`) and scaled so that the
target lane's centre sits at ``Params.lane_width`` (the recorded lanes are 3.4-3.7 m wide; the shield's lane is 3.5
m). The shield's vehicles are all ``Params.vehicle_length`` long, the recorded ones are not, so each other vehicle
is shown to the shield shifted along the road so that its bumper-to-bumper gap to the ego is the true one. States
are exact (the recording); the preset's sensing-error bounds and actuation delay still act in the shield (and the
delay in the ego's motion).

**Connectivity**: ``"none"`` (default; the recorded drivers of 2005 send nothing: ``L1`` may brake at ``a_x_d`` and
``F`` is assessed from its speed), or ``"chain"`` — a what-if in which the target lane's leaders broadcast and
promise ``promise_decel``; recorded drivers keep no promise, so the assumption monitor decides when to stop
believing them.

**Outcomes** per event (:func:`run_log_loop`'s table): completed (the shield's completion, the ego's centre across
the line, and held there to the end of the horizon) and when, beside the human's crossing time from the same start;
hesitations and aborts; the first collision, with whom and whose fault; ``p_m`` violations, by the same blame split
(:mod:`.log_checks`: geometry and the blame rule). A pair that already breaks ``p_m`` at the start is handed over by
the recording and counted apart (``pm_inherited``) until it clears.
"""

from __future__ import annotations

import numpy as np

from ..planners.base import Observation
from ..shield import ABORT, HESITATE, Shield, Situation
from ..shield.command import Command, InFlight
from ..tolerances import DIST_TOL_M
from . import log_checks as chk
from .log_batch import log_batch
from .recording import Recording

#: A missing F / leader is shown to the shield this far away [m] (as the SUMO integration does).
FAR_M = 1e4

CONNECTIVITY = ("none", "chain")

#: Gap below ``p_m`` that counts as a violation (the simulator's feasibility tolerance).
PM_TOL_M = DIST_TOL_M


def _shifted(x, length, ego_x, ego_len, shield_len):
    """Positions shown to the shield: each vehicle moved along the road so that, at the shield's common vehicle
    length, its bumper-to-bumper gap to the ego is the recorded one."""
    half = 0.5 * (length + ego_len[:, None]) - shield_len
    return np.where(x > ego_x[:, None], x - half, x + half)


def _situation(t, ego, xs, v, in_own, in_tgt, prm, connectivity, chain_slots, promise_decel, sensing):
    """The :class:`Situation` of every event at one instant: F the nearest target-lane vehicle at or behind the ego,
    the chain the nearest ``chain_slots`` ahead of it, ``L0`` the nearest ahead in the original lane (``xs``: the
    shifted positions; ``in_own``, ``in_tgt``: the vehicle's body overlaps that lane; all ``(B, V)``). A vehicle on
    a line is in both lanes (one changing lanes, or drifting into the ego's lane from the far side, counts where it
    already takes room)."""
    ex, ey, evx, evy = ego
    n = len(ex)
    tgt = in_tgt
    behind = np.where(tgt & (xs <= ex[:, None]), xs, -np.inf)
    f_idx = np.argmax(behind, 1)
    has_f = np.isfinite(behind[np.arange(n), f_idx])
    fx = np.where(has_f, behind[np.arange(n), f_idx], ex - FAR_M)
    fv = np.where(has_f, v[np.arange(n), f_idx], 0.0)
    ahead = np.where(tgt & (xs > ex[:, None]), xs, np.inf)
    order = np.argsort(ahead, 1, kind="stable")[:, :chain_slots]
    cx = np.take_along_axis(ahead, order, 1)
    present = np.isfinite(cx)
    pad = ex[:, None] + FAR_M * (1.0 + np.arange(cx.shape[1]))[None, :]
    cv = np.where(present, np.take_along_axis(v, order, 1), evx[:, None])
    cx = np.where(present, cx, pad)
    n_conn = 0 if connectivity == "none" else np.clip(present.sum(1) - 1, 0, chain_slots - 1)
    own = np.where(in_own & (xs > ex[:, None]), xs, np.inf)
    l0 = np.argmin(own, 1)
    ox = own[np.arange(n), l0]
    ov = np.where(np.isfinite(ox), v[np.arange(n), l0], 0.0)
    return Situation.from_arrays(
        t=t, ego=(ex, ey, evx, evy), follower=(fx, fv), leaders=(cx, cv), n_connected=n_conn,
        promise_decel=promise_decel, params=prm, own_leaders=(ox[:, None], ov[:, None]), own_n_connected=0,
        sensing=sensing, geometry="ignore",
    )  # fmt: skip


def _gap_ends(slot, fallback_x, fallback_v, xs, v, valid):
    """The planner's view of one end of the human's gap: the recorded vehicle of ``slot`` where it is present, else
    the shield's neighbour (``fallback``)."""
    n = len(slot)
    idx = np.maximum(slot, 0)
    ok = (slot >= 0) & valid[np.arange(n), idx]
    return np.where(ok, xs[np.arange(n), idx], fallback_x), np.where(ok, v[np.arange(n), idx], fallback_v)


def _observation(t, ego, sit, data, xs, v, valid, completed, gap_fraction):
    """What the nominal planner sees: the ego and the two ends of the human's gap. An end that is missing (no such
    vehicle in the recording) is put where the ego already is the planner's place in the gap (``gap_fraction`` of
    the way from F to L1), at the ego's speed, so that the planner neither chases nor flees a vehicle that is not
    there (both missing: ±30 m)."""
    ex, ey, evx, evy = ego
    n = len(ex)
    g = gap_fraction
    lx, lv = _gap_ends(data["gap_l"], sit.chain_x[:, 0], sit.chain_v[:, 0], xs, v, valid)
    fx, fv = _gap_ends(data["gap_f"], sit.f_x, sit.f_v, xs, v, valid)
    no_l, no_f = lx - ex > 0.5 * FAR_M, ex - fx > 0.5 * FAR_M
    lx = np.where(no_l, np.where(no_f, ex + 30.0, ex + (1.0 - g) / g * (ex - fx)), lx)
    fx = np.where(no_f, np.where(no_l, ex - 30.0, ex - g / (1.0 - g) * (lx - ex)), fx)
    lv, fv = np.where(no_l, evx, lv), np.where(no_f, evx, fv)
    return Observation(
        p_x=ex, p_y=ey, v_x=evx, v_y=evy, p_x_l=lx, v_x_l=lv, p_x_f=fx, v_x_f=fv, l1_plan=np.zeros((n, 10)),
        l1_connected=np.zeros(n, bool), f_connected=np.zeros(n, bool), completed=completed, t=t,
        scenario_id=np.arange(n),
    )  # fmt: skip


def _pairs(recordings, events):
    if isinstance(recordings, Recording):
        return [(recordings, events)]
    recordings = list(recordings)
    events = [None] * len(recordings) if events is None else list(events)
    if len(events) != len(recordings):
        raise ValueError(f"events: one list per recording ({len(recordings)}); got {len(events)}")
    return list(zip(recordings, events, strict=True))


def run_log_loop(
    recordings,
    events=None,
    *,
    preset="realistic",
    variant: str = "CV_all",
    nominal="expert",
    connectivity: str = "none",
    promise_decel: float = 0.5,
    chain_slots: int = 4,
    lead_s: float = 3.0,
    horizon_s: float = 8.0,
    config=None,
    trace: list | None = None,
):
    """The closed loop on the log (module docstring) over every lane change of ``recordings``.

    Args:
        recordings: a :class:`~.recording.Recording`, or a list of them.
        events: that recording's :class:`~.events.LaneChangeEvent` list (one list per recording for a list;
            ``None``: :func:`~.events.find_lane_changes` of each).
        preset: the shield's parameters and settings (:meth:`Shield.from_preset`); ``config``: overrides of them.
        variant: the shield's planner variant; ``nominal``: ``"expert"`` (the preset's rule-based planner), a
            registered name (``"mlp"``), a model file or a planner callable.
        connectivity: ``"none"`` or ``"chain"`` (the target lane's leaders promise ``promise_decel``; ``chain_slots``
            of them are read).
        lead_s: how long before the human's crossing the ego takes over; horizon_s: how long it drives (both cut
            by the recording).
        trace: a list to receive one dict of ``(B,)`` arrays per period (time, the ego's state in the lane frame,
            the shield's behaviour and acceleration, the F / L1 / L0 positions it was shown).

    Returns a ``pandas.DataFrame``, one row per event (:data:`COLUMNS`).
    """
    import pandas as pd

    from ..sim.inputs import preset_nominal
    from ..sim.preset import load_preset
    from .events import find_lane_changes

    if connectivity not in CONNECTIVITY:
        raise ValueError(f"connectivity must be one of {CONNECTIVITY}; got {connectivity!r}")
    chosen = load_preset(preset)
    shield = Shield.from_preset(chosen, variant=variant, config=config)
    prm, cfg = shield.params, shield.config
    planner = preset_nominal(chosen, nominal)
    sensing = chosen.sim.sensing_bounds() if cfg.sensing else None
    pairs = [(rec, find_lane_changes(rec) if evs is None else evs) for rec, evs in _pairs(recordings, events)]
    data = log_batch(pairs, lead_s=lead_s, horizon_s=horizon_s, dt=prm.dt)
    n = len(data["steps"])
    if n == 0:
        return pd.DataFrame(columns=COLUMNS)
    out = _drive(data, shield, planner, prm, cfg, sensing, connectivity, chain_slots, promise_decel, trace)
    for name in ("collision_with", "pm_with"):  # vehicle rows -> the source's ids
        row = out[name]
        out[name] = np.where(row >= 0, data["ids"][np.arange(n), np.maximum(row, 0)], -1)
    return pd.DataFrame({
        "source": data["source"], "vehicle_id": data["vehicle_id"], "crossing_t": data["crossing_t"],
        "start_t": data["start_t"], "horizon_s": data["steps"] * prm.dt, "human_time_s": data["human_t"], **out,
    })  # fmt: skip


COLUMNS = (
    "source",
    "vehicle_id",
    "crossing_t",
    "start_t",
    "horizon_s",
    "human_time_s",
    "initial_safe",
    "completed",
    "time_s",
    "n_hesitate",
    "n_abort",
    "collision",
    "collision_t",
    "collision_with",
    "collision_blame",
    "collision_ego",
    "collision_other",
    "pm_ego",
    "pm_other",
    "pm_inherited",
    "min_gap_m",
)


def _drive(data, shield, planner, prm, cfg, sensing, connectivity, chain_slots, promise_decel, trace=None) -> dict:
    """The loop over time steps (every event at once) and its referee; the outcome columns. ``trace``: a list that
    gets one dict of ``(B,)`` arrays per period (time, the ego's state in the lane frame, the behaviour)."""
    dt, n = prm.dt, len(data["steps"])
    x, y, v, valid = data["x"], data["y"], data["v"], data["valid"]
    length, width = data["length"], data["width"]
    ego_len, ego_w, lane_w, steps = data["ego_length"], data["ego_width"], data["lane_w"], data["steps"]
    scale = prm.lane_width / lane_w  # metres of the lane frame -> the shield's lateral frame
    # The shield's ego is Params.vehicle_width wide: shown where its edge toward the target lane is the real one's.
    edge = 0.5 * (scale * ego_w - prm.vehicle_width)
    ex, ey_m, evx, evy_m = data["ego"].T.copy()
    ey, evy = ey_m * scale + edge, evy_m * scale
    delay = round(cfg.actuation_delay_s / dt)
    in_flight = InFlight.idle(n, delay) if delay else None
    taus = dt * np.arange(1, chk.SUBSTEPS + 1) / chk.SUBSTEPS
    frac = taus / dt
    lanes = chk.lane_of(y, lane_w[:, None, None])
    margin = prm.p_m - prm.vehicle_length  # p_m (centre to centre at the shield's length) as a bumper gap
    entries = chk.EntryLog(ey_m, ego_w, lane_w, lanes[:, :, 0], margin)

    gap0, _ = chk.bumper_gap(ex[:, None], ego_len[:, None], x[:, :, 0], length)
    in0 = chk.body_in_lane(ey_m[:, None], ego_w[:, None], lanes[:, :, 0], lane_w[:, None])
    referee = chk.Referee(n, valid[:, :, 0] & in0 & (gap0 < margin - PM_TOL_M))
    o = {"shield_time_s": np.full(n, np.nan)}
    o["n_hesitate"], o["n_abort"] = np.zeros(n, np.int64), np.zeros(n, np.int64)
    o["min_gap_m"] = np.full(n, np.inf)
    gap_fraction = float(getattr(planner, "gap_fraction", 0.5))
    last_short = np.full(n, -np.inf)  # the last sample with the centre short of the line
    y_end = ey_m.copy()
    t = 0.0
    for k in range(int(steps.max())):
        if k:
            t = t + dt  # accumulated as the shield does
        active = k < steps
        xk, vk, ok = x[:, :, k], v[:, :, k], valid[:, :, k]
        xs = _shifted(np.where(ok, xk, 0.0), length, ex, ego_len, prm.vehicle_length)
        in_own, in_tgt = (ok & chk.body_in_lane(y[:, :, k], width, lane, lane_w[:, None]) for lane in (0, 1))
        sit = _situation(t, (ex, ey, evx, evy), xs, np.where(ok, vk, 0.0), in_own, in_tgt, prm, connectivity,
                         chain_slots, promise_decel, sensing)  # fmt: skip
        completed_before = np.zeros(n, bool) if shield.state is None else shield.state.completed.copy()
        obs = _observation(t, (ex, ey - edge, evx, evy), sit, data, xs, np.where(ok, vk, 0.0), ok, completed_before,
                           gap_fraction)  # fmt: skip
        proposal = planner(obs, prm)
        if k == 0:
            shield.reset(sit)
            o["initial_safe"] = shield.state.plan.feasible.copy()
        d = shield.step(sit, proposal)
        if trace is not None:
            trace.append({"t": t, "x": ex.copy(), "y": (ey - edge) / scale, "vx": evx.copy(), "vy": evy / scale,
                          "behaviour": d.behaviour.copy(), "a_x": d.a_x.copy(), "f_x": sit.f_x.copy(),
                          "l1_x": sit.chain_x[:, 0].copy(), "l0_x": sit.own_x[:, 0].copy()})  # fmt: skip
        o["n_hesitate"] += active & (d.behaviour == HESITATE)
        o["n_abort"] += active & (d.behaviour == ABORT)
        acting = Command.of(d)
        if in_flight is not None:  # the oldest command in flight acts now; this one joins the queue
            acting, in_flight = in_flight.push(acting)
        dur, ax, ay = acting.piece(dt)
        sx, sy, svx, svy = chk.sample_segments((ex, ey, evx, evy), dur, ax, ay, taus)
        ex, ey, evx, evy = acting.carry(ex, ey, evx, evy, dt)
        o["shield_time_s"] = np.where(acting.completing & active & np.isnan(o["shield_time_s"]), t + dt,
                                      o["shield_time_s"])  # fmt: skip

        # The referee: the replayed vehicles between frames k and k+1, the ego at its exact samples (lane frame, m).
        both = (ok & valid[:, :, k + 1])[:, :, None] & active[:, None, None]
        ox = xk[:, :, None] + (x[:, :, k + 1] - xk)[:, :, None] * frac
        oy = y[:, :, k, None] + (y[:, :, k + 1] - y[:, :, k])[:, :, None] * frac
        ov = vk[:, :, None] + (v[:, :, k + 1] - vk)[:, :, None] * frac
        oth = np.arctan2(y[:, :, k + 1] - y[:, :, k], x[:, :, k + 1] - xk)[:, :, None]
        sy_m, svy_m = (sy - edge[:, None]) / scale[:, None], svy / scale[:, None]
        eth = np.arctan2(svy_m, svx)[:, None, :]
        short = (sy_m <= 0.5 * lane_w[:, None]) & active[:, None]
        last_short = np.where(short.any(1), t + taus[np.argmax(np.cumsum(short, 1), 1)], last_short)
        y_end = np.where(active, sy_m[:, -1], y_end)
        hit = both & chk.boxes_overlap(
            sx[:, None, :],
            sy_m[:, None, :],
            eth,
            ego_len[:, None, None],
            ego_w[:, None, None],
            ox,
            oy,
            oth,
            length[:, :, None],
            width[:, :, None],
        )
        gap, behind = chk.bumper_gap(sx[:, None, :], ego_len[:, None, None], ox, length[:, :, None])
        olane = chk.lane_of(oy, lane_w[:, None, None])
        in_lane = chk.body_in_lane(sy_m[:, None, :], ego_w[:, None, None], olane, lane_w[:, None, None])
        near = both & in_lane
        o["min_gap_m"] = np.minimum(o["min_gap_m"], np.where(near, gap, np.inf).min((1, 2)))
        breaks = near & (gap < margin - PM_TOL_M)
        for j in range(chk.SUBSTEPS):  # sample by sample: the entry log is a history
            entries.update(sy_m[:, j], ego_w, lane_w, np.nan_to_num(gap[:, :, j], nan=-np.inf), behind[:, :, j],
                           svx[:, j], np.nan_to_num(ov[:, :, j]), olane[:, :, j])  # fmt: skip
            other = chk.blame_other(behind[:, :, j], in_lane[:, :, j], entries.clean_for(olane[:, :, j]),
                                    entries.cut_in)  # fmt: skip
            referee.sample(t + taus[j], hit[:, :, j], breaks[:, :, j], other)
    # Completed: the centre across the line and held there to the end; its time, the first sample of that stretch.
    o["completed"] = y_end > 0.5 * lane_w
    o["time_s"] = np.where(o["completed"], np.maximum(last_short, 0.0) + dt / chk.SUBSTEPS, np.nan)
    return {**o, **referee.columns()}


def summary(table) -> dict:
    """One row over the events of :func:`run_log_loop`'s ``table``: how many, completed, the median and worst time
    to complete beside the human's (over the events the ego completed, and over all of the human's), collisions in
    all and the ego's by the blame rule, ``p_m`` violations by blame, events with an abort, hesitations, and the
    events the shield found unsafe when it took over (``handed_over_unsafe``: no evasion existed at the start)."""
    done = table[table["completed"]]
    return {
        "events": len(table),
        "completed": int(table["completed"].sum()),
        "median_time_s": float(done["time_s"].median()) if len(done) else float("nan"),
        "worst_time_s": float(done["time_s"].max()) if len(done) else float("nan"),
        "human_median_time_s": float(table["human_time_s"].median()),
        "human_worst_time_s": float(table["human_time_s"].max()),
        "human_median_time_s_same": float(done["human_time_s"].median()) if len(done) else float("nan"),
        "human_worst_time_s_same": float(done["human_time_s"].max()) if len(done) else float("nan"),
        "collisions": int(table["collision"].sum()),
        "collisions_ego": int(table["collision_ego"].sum()),
        "pm_ego": int(table["pm_ego"].sum()),
        "pm_other": int(table["pm_other"].sum()),
        "events_aborting": int((table["n_abort"] > 0).sum()),
        "events_hesitating": int((table["n_hesitate"] > 0).sum()),
        "handed_over_unsafe": int((~table["initial_safe"].astype(bool)).sum()),
    }

"""The compiled closed loop's Python side: where it runs (:func:`covers`), and :func:`run`, which hands a
:class:`~.step.ClosedLoop`'s arrays to :func:`._fast_loop.loop_kernel` and returns what the results table reads.

The loop covers batches of :data:`FUSED_MIN_ROWS` scenarios or more with the expert planner (``ExpertPlanner`` itself,
any gains) or the adversarial planners (:func:`~safelane.planners.adversarial.adversary_table`: the four, or a
``Mixture`` of them, as data), the paper's traffic (with unexpected promise violations, with or without L(N+1)'s
profiles, with or without :class:`~.traffic.WaveHooks`: hooks as data), the paper's
four variants and the RSS variants (their rule: ``shield/_fast_rules.py``), the settings of the default and paper
presets (any assessment, the commit guard or the paper's completion rule, the monitor on or off, either leader rule,
supervised), the realistic world (the ``realistic`` preset: the own lane's leader ``L0``, alone or the first of a
connected chain, ``sim/own_chain.py``; sensing error with the shield's sensing on or off, the actuation delay with the
shield's delay off or the world's: :data:`WITH`) and an F that ignores the ego, without a trace or recorded
observations (those, and other planners, run its period: :class:`~._stepper.Stepper`).
Everything else — and everything with ``SAFELANE_NO_FUSED=1`` or without numba — runs period by period
(:mod:`.step`), whose parts are compiled where they have kernels. Importing this module does not import numba.
"""

from __future__ import annotations

import functools
import os
from types import SimpleNamespace

import numpy as np

from ..planners.adversarial import adversary_table
from ..planners.base import ExpertPlanner
from ..safety.evasion import fast_kernel
from ..safety.lateral import LATERAL_TOL_M
from ..shield.monitor import BREACH_KINDS, TOL_M, Breach
from ..shield.policies import SlowState
from ..shield.rules import rule_rows, rule_table, uncompiled_rules
from .traffic import WaveHooks

#: :func:`covers` takes batches from this many scenarios on.
FUSED_MIN_ROWS = 64
#: Scenarios per call of the compiled loop while a progress bar is shown.
PROGRESS_CHUNK = 4096


#: How the compiled loop treats each :class:`~.config.SimConfig` field (the shield's as ``shield.<name>``:
#: :func:`config_fields`). Every field is named in exactly one of the three tables, and :func:`reasons` refuses a
#: config whose class has a field named in none (a new setting is never run compiled as if it were at its default:
#: ``tests/test_fused_dispatch.py`` builds its cases from the field list).
#: The loop reads these fields' values (any value runs compiled, but as :data:`WITH` says):
READ = frozenset({"horizon_s", "brake_start_s", "shield.assess_window", "shield.assess_threshold",
                  "follower_open_decel", "follower_open_gap_m", "shield.monitor", "leader_rule",
                  "shield.assess_delay_s", "shield.assess_miss", "shield.assessment",
                  "follower_ignores_ego", "own_lane", "sensing_error", "actuation_delay_s"})  # fmt: skip
#: The loop implements these fields at this value (or these values) only; any other value runs period by period:
FIXED = {
    "shield.completion": ("commit_guard", "paper_evasion"),
    "sensor_noise_std": 0.0,
    "shield.enabled": True, "v2x_loss": 0.0, "v2x_latency_periods": 0,
    "shield.actuation_delay_s": 0.0, "neighbours": False,
}  # fmt: skip
#: A :data:`WITH` value: the other field at this field's value (the shield's delay the world's: the world's commands
#: in flight are then the shield's).
SAME = "the same value"
#: Settings the loop implements away from their defaults only together with other settings at these values: field →
#: ``{other field: its values}``. A :data:`FIXED` field's other values run compiled where the others are at their
#: values (and are refused, naming the field, where they are not); a :data:`READ` field away from its default refuses
#: where they are not. :data:`SAME` for the values: the other field at this field's value.
WITH = {
    # the shield's delay where it is the world's (its commands in flight: the world's queue, _fast_period.carried_ego)
    "shield.actuation_delay_s": {"actuation_delay_s": SAME},
}
#: These fields act only through another setting; while the fields named (or the nominal planner: ``"nominal"``)
#: are at the loop's values they change nothing, so any value runs compiled (where the setting named is read, any
#: value of these runs compiled but as :data:`WITH` says):
ONLY_WITH = {
    "v2x_max_age_s": ("v2x_loss", "v2x_latency_periods"),  # no message is ever late without the V2X emulation
    "l1_plan_steps": ("nominal",),  # L1's shared plan feeds the neural planners' features; the expert ignores it
    "l0_gap_min_m": ("own_lane",), "l0_gap_max_m": ("own_lane",), "l0_speed_spread_mps": ("own_lane",),
    "l0_decel_mps2": ("own_lane",), "l0_brake_window_s": ("own_lane",), "shield.own_lane": ("own_lane",),
    "own_lane_connected": ("own_lane",), "own_promise_decel": ("own_lane",),
    "sense_connected_pos_m": ("sensing_error",), "sense_connected_speed_mps": ("sensing_error",),
    "sense_sensed_pos_m": ("sensing_error",), "sense_sensed_speed_mps": ("sensing_error",),
    "sensing_edge_share": ("sensing_error",), "shield.sensing": ("sensing_error",),
    "neighbour_headway_min_s": ("neighbours",), "neighbour_headway_max_s": ("neighbours",),
    "neighbour_speed_spread_mps": ("neighbours",),
}  # fmt: skip


def config_fields(config_cls, prefix: str = "") -> list[str]:
    """The settings of a config class, a nested config's as ``name.field`` (``shield.assessment``)."""
    out = []
    for name, field in config_cls.model_fields.items():
        sub = field.annotation
        if isinstance(sub, type) and hasattr(sub, "model_fields"):
            out.extend(config_fields(sub, f"{prefix}{name}."))
        else:
            out.append(prefix + name)
    return out


def implemented(name: str) -> tuple:
    """The values of :data:`FIXED` setting ``name`` the loop implements."""
    value = FIXED[name]
    return value if isinstance(value, tuple) else (value,)


def setting(cfg, name: str):
    """The value of setting ``name`` (``shield.assessment``: a nested config's field)."""
    for part in name.split("."):
        cfg = getattr(cfg, part)
    return cfg


@functools.cache
def unclassified(config_cls) -> list[str]:
    """The fields of ``config_cls`` that the tables above do not name (or name twice); a class's answer is kept (the
    tables are constants: a reset of an env asks again for the same class)."""
    named = [*READ, *FIXED, *ONLY_WITH]
    fields = set(config_fields(config_cls))
    return sorted({f for f in fields if named.count(f) != 1} | (set(named) - fields))


def reasons(batch, cfg, nominal, traffic, trace: bool, record_observations: bool, stepping: bool = False) -> list[str]:
    """Why the compiled loop does not run this simulation (empty: it runs it); see the module docstring. Any
    :class:`~safelane.Params` runs compiled (the loop takes the ego's ``a_x_d`` and the others' maximum ``a_o_d``
    apart, as the stages do). ``stepping``: why its period (:class:`~._stepper.Stepper`) does not — the batch's size
    and the nominal planner do not count there (the planner runs between the periods)."""
    missing = unclassified(type(cfg))
    if missing:
        raise RuntimeError(
            f"sim/_fused.py does not classify the SimConfig field(s) {missing} (READ, FIXED or ONLY_WITH): say how the "
            "compiled loop treats each one before it can run"
        )
    out = []
    if fast_kernel() is None:
        out.append("numba is not installed (extra 'fast')")
    if os.environ.get("SAFELANE_NO_FUSED", "") == "1":
        out.append("SAFELANE_NO_FUSED=1")
    if trace:
        out.append("a trace is recorded")
    if record_observations:
        out.append("observations are recorded")
    if traffic is not None and type(traffic) is not WaveHooks:
        # WaveHooks (the paper's traffic, its wishes as data) run compiled, in the loop and in its period
        out.append("a traffic model other than the paper's default")
    if len(batch) < FUSED_MIN_ROWS and not stepping:
        out.append(f"fewer than {FUSED_MIN_ROWS} scenarios")
    if not stepping and type(nominal) is not ExpertPlanner and adversary_table(nominal, len(batch)) is None:
        out.append(f"the nominal planner {type(nominal).__name__} (the loop runs ExpertPlanner and the adversarial "
                   "planners only)")  # fmt: skip
    out.extend(config_reasons(cfg))
    if batch.l0_x is not None and batch.l0_profile_t is None:
        out.append("own-lane leaders without a profile (ScenarioBatch.l0_profile_t)")
    other = uncompiled_rules(rule_rows(batch.variant, len(batch)))
    if other:
        out.append(f"variants decided by a rule the loop does not implement: {other}")
    return out


def config_reasons(cfg) -> list[str]:
    """Why the loop does not run this configuration (:data:`FIXED` and :data:`WITH`; empty: it runs it)."""
    out = []
    for name, value in FIXED.items():
        now = setting(cfg, name)
        if now in implemented(name):
            continue
        needs = _values(WITH.get(name), now)
        if needs is None:
            out.append(f"config.{name}={now!r} (compiled: {value!r})")
        elif any(setting(cfg, other) not in values for other, values in needs.items()):
            out.append(f"config.{name}={now!r} (compiled: {value!r}, or {now!r} with {_needs(needs)})")
    for name, needs in WITH.items():
        now = setting(cfg, name)
        if name not in FIXED and now != setting(type(cfg)(), name):
            out.extend(f"config.{other}={setting(cfg, other)!r} with {name}={now!r} (compiled: {values!r})"
                       for other, values in _values(needs, now).items()
                       if setting(cfg, other) not in values)  # fmt: skip
    return out


def _values(needs: dict | None, now) -> dict | None:
    """:data:`WITH`'s ``{other field: its values}`` for a field at ``now`` (:data:`SAME`: ``(now,)``)."""
    return None if needs is None else {other: (now,) if values is SAME else values for other, values in needs.items()}


def _needs(needs: dict) -> str:
    return ", ".join(f"{other} in {values!r}" for other, values in needs.items())


def covers(batch, cfg, nominal, traffic, trace: bool, record_observations: bool) -> bool:
    """Whether the compiled loop runs this simulation (:func:`reasons` is empty)."""
    return not reasons(batch, cfg, nominal, traffic, trace, record_observations)


def run(sim, n_steps: int, progress: bool = False):
    """The final state's fields that :func:`~.results.results_table` reads, from :func:`run_chunk` on the whole
    batch; with ``progress``, in chunks of :data:`PROGRESS_CHUNK` scenarios behind a
    bar (the same table: the scenarios are independent)."""
    if not progress or len(sim.b) <= PROGRESS_CHUNK or not chunkable(sim):
        return _state(run_chunk(sim, n_steps), _slow(sim), _own(sim))
    from .._progress import track
    from .step import ClosedLoop

    parts = np.array_split(np.arange(len(sim.b)), -(-len(sim.b) // PROGRESS_CHUNK))
    chunk = lambda rows: ClosedLoop(sim.b.take(rows), sim.seed, sim.prm, sim.cfg, sim.nominal)  # noqa: E731
    bar = track(parts, f"simulating {len(sim.b)} scenarios")
    done = [run_chunk(chunk(rows), n_steps) for rows in bar]
    return _state({name: np.concatenate([fields[name] for fields in done]) for name in done[0]}, _slow(sim),
                  _own(sim))  # fmt: skip


def chunkable(sim) -> bool:
    """Whether rows of ``sim`` can run apart, rebuilt with the default traffic and its nominal planner (:func:`run`'s
    progress chunks, the blame's rerun): not with traffic hooks as data (by scenario id), nor with a planner whose
    parameters are per row (the adversaries index theirs by batch row)."""
    return type(sim.traffic_step.hooks) is not WaveHooks and type(sim.nominal) is ExpertPlanner


def run_chunk(sim, n_steps: int) -> dict:
    """The final state's arrays by name, from :func:`._fast_loop.loop_kernel` on :class:`~.step.ClosedLoop`
    ``sim``'s arrays."""
    from ._fast_loop import OUT_B, OUT_F, LoopOut, loop_kernel

    start = sim.initial_state()
    prm_vec, period_prm, batch = kernel_inputs(sim, planner=True)
    n = len(sim.b)
    rows = rows_of(start)
    out_f, out_b = np.empty((n, len(OUT_F))), np.empty((n, len(OUT_B)), np.bool_)
    counts, n_invalid = np.empty((n, 3), np.int64), np.empty(n, np.int64)
    flags, bad = np.empty((n, len(BREACH_KINDS)), np.bool_), np.empty(n, np.int64)
    own_x, own_v = np.empty_like(rows.own_x), np.empty_like(rows.own_v)
    loop_kernel(n_steps, prm_vec, period_prm, batch, rows, LoopOut(out_f, out_b, counts, n_invalid, flags, bad,
                                                                    own_x, own_v),
                sense_scratch(prm_vec, batch.x.shape[1]))  # fmt: skip
    if (bad >= 0).any():
        step = int(bad[bad >= 0].min())
        _non_finite(sim.b.scenario_id, np.flatnonzero(bad == step), (step + 1) * sim.prm.dt)
    return dict(zip(OUT_F, out_f.T, strict=True), **dict(zip(OUT_B, out_b.T, strict=True)), counts=counts,
                n_invalid=n_invalid, breach_flags=flags, initial_safe=start.initial_safe, own_x=own_x,
                own_v=own_v)  # fmt: skip


def kernel_inputs(sim, planner: bool = False):
    """The compiled loop's inputs from :class:`~.step.ClosedLoop` ``sim``: its parameter vector (``_fast_loop.PRM``),
    the shield's (``shield/_fast_period.PRM``) and the batch's arrays (``_fast_loop.LoopBatch``); ``planner``: with
    the nominal planner as data where it is an adversary (the loop's; the period's callers propose themselves)."""
    from ..shield.fast_step import period_constants
    from ..shield.policies import variant_flags
    from ._fast_loop import PRM, LoopBatch

    b, prm, cfg, nominal = sim.b, sim.prm, sim.cfg, sim.nominal
    traffic = sim.traffic_step  # the paper's, bound to the batch (covers() admits no other)
    gains = nominal if isinstance(nominal, ExpertPlanner) else ExpertPlanner()  # (read by the expert's loop only)
    values = dict(
        dt=prm.dt, a_x_a=prm.a_x_a, a_x_d=prm.a_x_d, a_y_m=prm.a_y_m, y_safe=prm.y_safe, p_m=prm.p_m,
        lane_width=prm.lane_width, vehicle_length=prm.vehicle_length, conflict=prm.y_safe + LATERAL_TOL_M,
        overlap=prm.lane_width - prm.vehicle_width, monitor_tol=TOL_M, brake_start_s=cfg.brake_start_s,
        open_decel=cfg.follower_open_decel, open_gap_m=cfg.follower_open_gap_m, k_p=gains.k_p, k_v=gains.k_v,
        gap_fraction=gains.gap_fraction, brake_comfort=gains.brake_comfort, omega2=gains.omega**2,
        two_omega=2.0 * gains.omega, a_o_d=prm.others_decel, reactive=cfg.leader_rule == "reactive",
        ignores_ego=cfg.follower_ignores_ego, own_width=prm.vehicle_width, shield_own=cfg.shield.own_lane,
        sensing=sim.sensing is not None, edge_share=cfg.sensing_edge_share,
        shield_sensing=cfg.shield.sensing and sim.sensing is not None,
        own_analysed=cfg.shield.own_lane and b.l0_x is not None and bool(np.isfinite(b.l0_x).any()),
    )  # fmt: skip
    c = np.ascontiguousarray
    is_last, acts = traffic.roles
    batch = LoopBatch(
        c(b.x), c(b.v), c(np.stack([b.ego_x, b.ego_y, b.ego_vx, b.ego_vy], 1)), c(b.valid),
        c(b.n_connected.astype(np.int64)), c(b.connected[:, 0]), c(b.follower_aggressive),
        c(np.stack(variant_flags(b.variant, len(b)), 1)), c(sim.chain_promise), c(sim.chain_margin), c(traffic.margin),
        c(is_last), c(acts), c(traffic.v_desired), c(b.promise_decel), c(b.promise_accel),
        c(b.decel_last.astype(np.float64)), c(traffic.gap0), c(sim.lane_pairs[0]), c(sim.lane_pairs[1]),
        c(b.p_v.astype(np.float64)), c(b.scenario_id.astype(np.int64)), np.array([sim.seed % 2**64], np.uint64),
        rule_table(rule_rows(b.variant, len(b)), len(b), prm), *_profile(b), *_waves(traffic.hooks, b),
        *_own_profile(b), c(_world_key(b).astype(np.int64)), *_sensing(sim), *_own_chain(sim),
        *_planner(nominal if planner else None, len(b)),
    )  # fmt: skip
    return np.array([float(values[name]) for name in PRM]), period_constants(prm, cfg.shield), batch


def sense_scratch(prm_vec: np.ndarray, slots: int):
    """The kernels' ``sense`` argument for the loop's parameter vector and ``slots`` target-lane vehicles: the scratch
    of the shield's sensing box (``_fast_rows.Sense``) where it is on, else ``None`` (the kernels are then compiled
    without it: nothing to pay for it)."""
    from ..shield._fast_period import ANCHOR_F
    from ._fast_loop import PRM
    from ._fast_rows import Sense

    if prm_vec[PRM.index("shield_sensing")] <= 0.0:
        return None
    m, f = slots - 1, len(ANCHOR_F)
    return Sense(np.zeros(3, bool), np.zeros((1, 1, 2)), np.empty((1, m)), np.empty((1, m)), np.empty((1, f)),
                 np.empty((1, m)), np.empty((1, m)), np.empty((1, m)), np.zeros(1, np.int64), np.empty((1, f)),
                 np.empty((1, m)), np.empty((1, m)), np.empty((1, m)), np.zeros(1, np.int64))  # fmt: skip


def _planner(nominal, n: int) -> tuple:
    """``LoopBatch``'s ``planner_kind``, ``planner_q``: an adversarial planner as data (none: no rows, the expert)."""
    table = None if nominal is None or type(nominal) is ExpertPlanner else adversary_table(nominal, n)
    return (np.zeros(0, np.int64), np.zeros((0, 7))) if table is None else table


def _profile(b) -> tuple:
    """``LoopBatch``'s ``profile_t``, ``profile_a``: ``L(N+1)``'s profile (none: ``(B, 0)``)."""
    if b.last_profile_t is None:
        return np.zeros((len(b), 0)), np.zeros((len(b), 0))
    return np.ascontiguousarray(b.last_profile_t, np.float64), np.ascontiguousarray(b.last_profile_a, np.float64)


def _own_profile(b) -> tuple:
    """``LoopBatch``'s ``l0_profile_t``, ``l0_profile_a``: the own lane's leader ``L0``'s profile (none: ``(B, 0)``)."""
    if b.l0_x is None:
        return np.zeros((len(b), 0)), np.zeros((len(b), 0))
    return np.ascontiguousarray(b.l0_profile_t, np.float64), np.ascontiguousarray(b.l0_profile_a, np.float64)


def _own_chain(sim) -> tuple:
    """``LoopBatch``'s ``own_nc``, ``own_promise``, ``own_brake_t``, ``own_v_desired``: the own lane's chain
    (:class:`~.own_chain.OwnLane`; without an own lane, one empty slot)."""
    c = np.ascontiguousarray
    own, n = sim.own, len(sim.b)
    if own is None:
        return np.zeros(n, np.int64), np.zeros((n, 0)), np.zeros((n, 0)), np.zeros((n, 1))
    return (c(own.n_connected, np.int64), c(own.promise, np.float64), c(own.brake_t, np.float64),
            c(own.v_desired, np.float64))  # fmt: skip


def _sensing(sim) -> tuple:
    """``LoopBatch``'s ``err_f``, ``err_chain``, ``err_own``: the sensing-error bounds of the situation the shield
    sees (``SensingBounds.apply``: constant over a run, by connectivity; zeros without sensing error)."""
    b = sim.b
    n, k = b.x.shape
    k0 = 0 if sim.own is None else sim.own.slots
    if sim.sensing is None:
        return np.zeros((n, 2)), np.zeros((n, k - 1, 2)), np.zeros((n, k0, 2))
    from .own_chain import start as own_start

    ego = (b.ego_x, b.ego_y, b.ego_vx, b.ego_vy)
    seen = sim.sensing.apply(sim.situation(0.0, ego, b.x, b.v, None, b.v[:, 0],
                                           None if sim.own is None else own_start(b)))  # fmt: skip
    c = lambda a: np.ascontiguousarray(a, np.float64)  # noqa: E731
    return c(seen.err_f), c(seen.err_chain), c(np.zeros((n, 0, 2)) if seen.err_own is None else seen.err_own)


def _world_key(b) -> np.ndarray:
    """The key of the world's draws (``realworld._key``): ``world_key`` where set, else the scenario id."""
    return b.scenario_id if b.world_key is None else b.world_key


def _waves(hooks, b) -> tuple:
    """``LoopBatch``'s :class:`~.traffic.WaveHooks` fields (``_fast_loop.LoopBatch``; none: no rows). The running
    minimum of the lane-gap sample is the hooks' own array (the loop writes it, as the NumPy path's hook does)."""
    k = b.x.shape[1]
    c = np.ascontiguousarray
    if type(hooks) is not WaveHooks:
        return (np.zeros((0, k, 5)), np.zeros(0), np.zeros((0, 4)), np.zeros((0, k - 1), bool), np.zeros((0, k - 1)),
                np.zeros(0))  # fmt: skip
    task = np.stack([hooks.task_low, hooks.task_span, hooks.task_hi, hooks.task_lo, hooks.task_phase], -1)
    f_wave = np.stack([hooks.f_period, hooks.f_phase, hooks.f_hi, hooks.f_lo], 1)
    waves = (c(task, np.float64), c(hooks.task_period, np.float64), c(f_wave, np.float64))
    if hooks.lane_ratio is None:
        return (*waves, np.zeros((0, k - 1), bool), np.zeros((0, k - 1)), np.zeros(0))
    if not (hooks.lane_ratio.flags.c_contiguous and hooks.lane_ratio.dtype == np.float64):
        raise ValueError("WaveHooks.lane_ratio must be a C-contiguous float64 array (the loop writes into it)")
    return (*waves, c(hooks.lane_valid, np.bool_), c(hooks.lane_margin, np.float64), hooks.lane_ratio)


#: ``_fast_loop.LoopBatch``'s fields with the batch on the last axis (the chain's inputs, vehicle-major as
#: :class:`~.step.ClosedLoop` keeps them) and those shared by every row (the key of the draws: the seed's); every
#: other field has the batch first (:meth:`~._stepper.Stepper.splice`), but the :class:`~.traffic.WaveHooks` fields,
#: by scenario id (no rows without them): a batch with them is not spliced.
BATCH_LAST, BATCH_SHARED = ("promise", "chain_margin"), ("key",)
BY_ID = ("task_wave", "task_period", "f_wave", "wave_lane_valid", "wave_lane_margin", "lane_sample")
#: ``_fast_loop.LoopBatch``'s fields the loop alone reads (the nominal planner as data; no rows in a period's inputs).
LOOP_ONLY = ("planner_kind", "planner_q")


def rows_of(start):
    """A :class:`~.step.SimState` at the start of a run (its first period not yet run) as the compiled loop's row
    state (``_fast_rows.Rows``)."""
    from ..shield._fast_period import ANCHOR_F
    from ..shield.command import InFlight
    from ..shield.fast_step import Packed, _queue_of
    from ._fast_rows import RB, RF, RI, Rows

    packed = Packed.of(start.shield)  # the shield's state as its compiled period holds it
    n, k = start.x.shape
    c = np.ascontiguousarray
    rf = np.empty((n, len(RF)))
    rf[:, :4] = np.stack(start.ego, 1)
    rf[:, 4], rf[:, 5], rf[:, 6:] = start.t, np.nan, np.inf
    if start.l0 is not None:  # the own lane, L0 first (sim/own_chain.py)
        own = (c(start.l0[0], np.float64), c(start.l0[1], np.float64), c(start.own_cap, np.float64))
    else:
        own = (np.full((n, 1), np.inf), np.zeros((n, 1)), np.full((n, 1), np.inf))
    snap = np.zeros((n, k - 1))
    rb = np.zeros((n, len(RB)), bool)
    rb[:, 7] = start.completed
    if start.own_pair_collided is not None:
        rb[:, 8] = start.own_pair_collided
    # the actuation delay's commands in flight: the idle ones the run starts with (InFlight.idle: cruise)
    if start.in_flight is not None and any(cmd.rows.size or cmd.a_x.any() or cmd.a_y.any() or cmd.completing.any()
                                           for cmd in start.in_flight.commands):  # fmt: skip
        raise ValueError("rows_of: a run starts with idle commands in flight (InFlight.idle)")
    queue = _queue_of(InFlight(commands=()) if start.in_flight is None else start.in_flight, n)  # Packed.queue's
    if packed.anchor is not None:
        raise ValueError("rows_of: a run starts with a monitor's anchor (it starts without a last period)")
    anchor = (np.zeros((n, len(ANCHOR_F))), snap.copy(), snap.copy(), snap.copy(), np.zeros(n, np.int64))
    return Rows(c(start.x), c(start.v), np.zeros((n, k)), np.full((n, k), np.inf), rf, rb,
                np.zeros((n, len(RI)), np.int64), c(packed.plan), c(packed.history), c(packed.count), c(packed.st),
                c(packed.sk), snap, snap.copy(), snap.copy(), np.zeros(n, np.int64), *queue, *anchor, *own)  # fmt: skip


def _slow(sim) -> bool:
    return sim.cfg.shield.assessment == "slow"


def _own(sim) -> bool:
    return sim.own is not None


def _non_finite(scenario_id: np.ndarray, rows: np.ndarray, t: float):
    ids = scenario_id[rows][:5].tolist()
    raise FloatingPointError(
        f"non-finite simulator state at t = {t:.1f} s in scenario(s) {ids} ({rows.size} in all): a bug in a behaviour "
        "model or hook, not an outcome"
    )


def _state(f: dict, slow: bool, own: bool = False):
    """The fields :func:`~.results.results_table` reads (a :class:`~.step.SimState`'s), from :func:`run_chunk`'s
    arrays; ``slow``: the belief is the 'slow' assessment's (``policies.SlowState``, which derives what it reports);
    ``own``: with the own lane (its columns; a chain's pairs where it has several slots)."""
    belief = SimpleNamespace(aggressive=f["aggressive"], first_collaborative_s=f["first_collaborative_s"])
    if slow:
        belief = SlowState(belief, f["slow_delay_s"], f["slow_missed"], f["slow_aggressive"])
    breach = Breach(flags=f["breach_flags"], first_s=f["breach_first_s"])
    names = ("completed", "collided", "violated", "leader_collided", "leader_violated", "t_complete", "min_gap_f",
             "min_gap_l1", "min_lane_ratio", "counts", "n_invalid", "initial_safe")  # fmt: skip
    if not own:
        return SimpleNamespace(**{name: f[name] for name in names}, belief=belief, breach=breach, l0=None)
    return SimpleNamespace(**{name: f[name] for name in names}, belief=belief, breach=breach,
                           l0=(f["own_x"], f["own_v"]), own_pair_collided=f["own_pair_collided"],
                           l0_collided=f["l0_collided"], l0_violated=f["l0_violated"],
                           min_gap_l0=f["min_gap_l0"])  # fmt: skip

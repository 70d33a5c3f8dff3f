"""The compiled control period under an actuation delay (``shield/_fast_period.py``: the ego carried over the commands
in flight, the others along their worst cases, the new command queued; ``shield/fast_step.Packed.queue``) against the
NumPy stages (``shield.core.stages_step``), field by field — every decision field and the next state, the commands in
flight included — over many periods of random worlds."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from safelane import Params
from safelane.shield import ABORT, Shield, ShieldConfig, fast_step
from safelane.shield import core as shield_core
from safelane.shield import rows as rws
from test_fast_period import advance, proposals, random_world, same, situation_of

pytestmark = [
    pytest.mark.compiled,
    pytest.mark.skipif(fast_step.kernel() is None, reason="numba missing or SAFELANE_NO_NUMBA=1"),
]

_MIXED = ("CV_follow", "CV_all", "RSS", "CV_none", "No_agg_assess", "RSS_V2X_matched")


def _aborts_in_flight(state) -> int:
    """How many aborting rows (with their plan's knots) the commands in flight hold."""
    return sum(int(c.rows.size) for c in state.pending.commands)


@pytest.mark.parametrize(
    ("seed", "n", "m", "periods", "variant", "config", "own"),
    [
        (0, 48, 3, 1, "CV_all", {}, False),
        (1, 40, 1, 2, "CV_all", {}, False),
        (2, 48, 4, 3, "CV_all", {}, True),
        (3, 40, 2, 2, "CV_none", {}, True),
        (4, 1, 3, 1, "CV_all", {}, False),
        (5, 48, 3, 3, _MIXED * 8, {}, True),
        (6, 40, 3, 2, "No_agg_assess", {"completion": "paper_evasion"}, False),
        (7, 48, 2, 1, "CV_all", {"assessment": "slow", "assess_delay_s": 0.5, "assess_miss": 0.1}, True),
        (8, 32, 4, 3, _MIXED * 6, {"assessment": "truth"}, False),
    ],
)
def test_delayed_period_is_the_stages(seed, n, m, periods, variant, config, own):
    params = Params(a_o_d=8.0) if seed % 2 else Params()
    cfg = ShieldConfig(actuation_delay_s=periods * params.dt, **config)
    assert cfg.monitor
    rng = np.random.default_rng(100 + seed)
    world = random_world(rng, n, m, stale=seed % 3 == 0, own=own)
    if isinstance(variant, tuple):
        variant = variant[:n]
    shield = Shield(params, variant=variant, config=cfg)
    start = situation_of(world, 0.0, params)
    shield.reset(start)
    state = shield_core.init(start, params, cfg, variant)
    aborts, queued, left = 0, 0, 0
    for k in range(50):
        s = situation_of(world, k * params.dt, params)
        prop = proposals(rng, n)
        leaving = int(state.pending.commands[0].rows.size)  # the oldest command's aborting rows: popped this period
        fast = shield.step(s, prop)
        assert shield.last_path == "compiled", shield.refusals(s)
        state, ref = shield_core.stages_step(state, s, prop, params, cfg, variant)
        same(fast, ref, f"period {k}: decision")
        same(shield.state, state, f"period {k}: state")
        assert len(state.pending.commands) == periods
        aborts += int((ref.behaviour == ABORT).sum())
        queued = max(queued, _aborts_in_flight(state))
        left += leaving
        advance(world, ref, rng, params.dt)
    if n > 1:  # aborts on the held plan entered the queue with their knots, and left it
        assert aborts > 0 and queued > 0 and left > 0, (aborts, queued, left)


def test_functional_step_runs_the_delay_compiled(monkeypatch):
    """``shield.core.step`` (the simulator's call) runs a delayed period compiled from the functional state (its
    commands in flight packed): the stages' decision and state."""
    params = Params()
    rng = np.random.default_rng(21)
    world = random_world(rng, 16, 3, stale=False, own=True)
    cfg = ShieldConfig(actuation_delay_s=0.2)
    state = ref_state = shield_core.init(situation_of(world, 0.0, params), params, cfg, "CV_all")
    calls = []

    def counted(*args, _step=fast_step.step, **kwargs):
        calls.append(1)
        return _step(*args, **kwargs)

    monkeypatch.setattr(fast_step, "step", counted)
    for k in range(20):
        s = situation_of(world, k * params.dt, params)
        prop = proposals(rng, 16)
        state, decision = shield_core.step(state, s, prop, params, cfg, "CV_all")
        ref_state, ref = shield_core.stages_step(ref_state, s, prop, params, cfg, "CV_all")
        same(decision, ref, f"period {k}: decision")
        same(state, ref_state, f"period {k}: state")
        advance(world, ref, rng, params.dt)
    assert len(calls) == 20


def test_packed_queue_round_trips_and_regroups():
    """``Packed.of`` / ``Packed.state`` give the commands in flight back exactly (aborting rows' knots and segment
    accelerations included), and ``Packed.take`` / ``join`` select and join their rows as :mod:`safelane.shield.rows`
    does on the unpacked state."""
    params = Params()
    rng = np.random.default_rng(5)
    n = 40
    world = random_world(rng, n, 3, stale=False)
    cfg = ShieldConfig(actuation_delay_s=0.3)
    state = shield_core.init(situation_of(world, 0.0, params), params, cfg, "CV_all")
    for k in range(40):
        s = situation_of(world, k * params.dt, params)
        state, ref = shield_core.stages_step(state, s, proposals(rng, n), params, cfg, "CV_all")
        advance(world, ref, rng, params.dt)
        if state.pending.commands[-1].rows.size >= 2:
            break
    aborting = state.pending.commands[-1].rows
    assert aborting.size >= 2
    packed = fast_step.Packed.of(state)
    same(packed.state(params), state, "round trip")
    keep = np.concatenate([aborting[::-1][:3], [i for i in range(n) if i not in aborting][:5]]).astype(np.int64)
    fresh = shield_core.init(rws.take_rows(situation_of(world, 0.0, params), np.arange(4)), params, cfg, "CV_all")
    fresh = dataclasses.replace(fresh, last=state.last and rws.neutral_snapshot(4, 3, params))
    joined = packed.take(keep).join(fast_step.Packed.of(fresh))
    same(joined.state(params), rws.join_rows(rws.take_rows(state, keep), fresh), "take and join")
    # the rows that do not abort alone: their commands are constant (one segment), as the stages' are
    idle = np.array([i for i in range(n) if not any(i in c.rows for c in state.pending.commands)][:4], np.int64)
    same(packed.take(idle).state(params), rws.take_rows(state, idle), "rows without aborts")


def test_regrouping_with_a_delay_keeps_the_packed_state_and_the_stages_decisions():
    """``Shield.regroup`` with an actuation delay: the compiled path's packed state (its commands in flight) selects
    and joins rows, and every period's decision and the state read back are the stages' on the unpacked state
    selected and joined row by row."""
    params = Params()
    cfg = ShieldConfig(actuation_delay_s=0.2)
    rng = np.random.default_rng(41)
    world = random_world(rng, 16, 3, stale=False, own=True)
    active = np.arange(10)
    shield = Shield(params, config=cfg)
    shield.regroup(np.zeros(0, np.int64), rws.take_rows(situation_of(world, 0.0, params), active), 0.0)
    state = shield_core.init(rws.take_rows(situation_of(world, 0.0, params), active), params, cfg, "CV_all")
    changes = {8: ([0, 2, 3, 5, 6, 7, 8, 9], []), 12: ([1, 2, 3, 4, 5, 6, 7], [10, 11, 12]),
               20: ([0, 1, 2, 3, 4, 5, 6, 7, 8, 9], [13, 14, 15])}  # fmt: skip
    aborts = 0
    for k in range(30):
        t = k * params.dt
        full = situation_of(world, t, params)
        if k in changes:
            keep, new = changes[k]
            keep = np.array(keep, np.int64)
            joined = rws.take_rows(full, np.array(new, np.int64)) if new else None
            shield.regroup(keep, joined, t)
            assert shield._state is None  # regrouped packed
            state = rws.take_rows(state, keep)
            if new:
                fresh = shield_core.init(joined, params, cfg, "CV_all")
                fresh = dataclasses.replace(fresh, last=rws.neutral_snapshot(len(new), 3, params))
                state = rws.join_rows(state, fresh)
            state = dataclasses.replace(state, t=t)
            active = np.concatenate([active[keep], new]).astype(np.int64)
        s = rws.take_rows(full, active)
        prop = proposals(rng, len(active))
        fast = shield.step(s, prop)
        assert shield.last_path == "compiled"
        state, ref = shield_core.stages_step(state, s, prop, params, cfg, "CV_all")
        same(fast, ref, f"period {k}")
        aborts += int((ref.behaviour == ABORT).sum())
        a_x, a_y = np.zeros(16), np.zeros(16)
        a_x[active], a_y[active] = ref.a_x, ref.a_y
        advance(world, dataclasses.replace(ref, a_x=a_x, a_y=a_y), rng, params.dt)
    same(shield.state, state, "the state read back")
    assert shield.rows == 13 and aborts > 0


def test_a_delay_without_commands_in_flight_refuses():
    """A state that holds no commands in flight under a delay (not one ``init`` makes) runs the stages."""
    params = Params()
    cfg = ShieldConfig(actuation_delay_s=0.1)
    s = situation_of(random_world(np.random.default_rng(3), 4, 3, stale=False), 0.0, params)
    state = shield_core.init(s, params, cfg, "CV_all")
    assert fast_step.refusals(cfg, "CV_all", 4) == []
    assert fast_step.situation_refusals(s, cfg, state) == []
    bare = dataclasses.replace(state, pending=None)
    assert fast_step.situation_refusals(s, cfg, bare) == ["an actuation delay without commands in flight"]


def test_rss_rows_under_a_delay_decide_from_the_carried_ego_and_the_chain_at_the_periods_start(monkeypatch):
    """What RSS's rows see under the shield's actuation delay (docs/rss.md): the ego carried over the commands in
    flight and F along the frame's worst case (``stages.frame``), the chain as observed at the period's start — not
    carried over the delay, where the paper's rule carries ``L1`` — on the stages' path; the compiled period gives the
    same decisions (:func:`test_delayed_period_is_the_stages`, the closed loop below)."""
    from safelane.shield import stages

    params = Params()
    cfg = ShieldConfig(actuation_delay_s=0.2)
    rng = np.random.default_rng(17)
    world = random_world(rng, 12, 3, stale=False)
    state = shield_core.init(situation_of(world, 0.0, params), params, cfg, "RSS_matched")
    seen = []
    real = stages.RuleInputs
    monkeypatch.setattr(stages, "RuleInputs", lambda *a: seen.append(real(*a)) or seen[-1])
    for k in range(4):
        s = situation_of(world, k * params.dt, params)
        pending = state.pending
        state, ref = shield_core.stages_step(state, s, (np.full(12, 0.5), np.full(12, 0.6)), params, cfg,
                                             "RSS_matched")  # fmt: skip
        inp = seen[-1]
        assert np.array_equal(inp.chain_x, s.chain_x) and np.array_equal(inp.chain_v, s.chain_v), k
        ego = pending.carry(s.ego_x, s.ego_y, s.ego_vx, s.ego_vy, params.dt)
        frame = (inp.ego_x, inp.ego_y, inp.ego_vx, inp.ego_vy)
        assert all(np.array_equal(a, b) for a, b in zip(frame, ego, strict=True)), k
        assert not np.array_equal(inp.ego_x, s.ego_x)  # the commands in flight move the ego: not the period's start
        advance(world, ref, rng, params.dt)
    assert len(seen) == 4


@pytest.mark.parametrize("delay", [0.1, 0.3])
def test_rss_rows_under_the_shields_delay_give_the_numpy_table_in_the_compiled_loop(monkeypatch, delay):
    """RSS's four variants under the shield's delay (the world's) in the compiled closed loop: the NumPy path's table
    (``SAFELANE_NO_NUMBA=1``) bit for bit, RSS's rows proceeding, hesitating and responding; the delay changes the
    table. The chain at the period's start (both paths) decides as the chain carried over the delay at RSS's
    ``brake_max`` would: a vehicle ahead braking at ``brake_max`` keeps its stopping point, which is all RSS's
    longitudinal distance reads of it (docs/rss.md) — the same table with the rule fed the carried chain."""
    from safelane.baselines.rss_rule import RssRule
    from safelane.shield.realworld import carry_worst
    from safelane.sim import ScenarioConfig, SimConfig, concat, paper_scenarios, simulate_batch

    variants = ("RSS", "RSS_V2X", "RSS_matched", "RSS_V2X_matched")
    # wide gaps, N = 1: the chain's positions decide some rows (fed the chain carried at constant speed, 4 rows of
    # 80 differ at 0.3 s)
    spread = ScenarioConfig(follower_connected_share=0.5, gap=(30.0, 40.0), ego_speed=(25.0, 31.0))
    batch = concat([paper_scenarios(v, 1, 6.0, 20, np.random.default_rng(2100 + k), spread, first_id=1000 * k)
                    for k, v in enumerate(variants)])  # fmt: skip
    cfg = SimConfig(actuation_delay_s=delay)
    assert cfg.shield.actuation_delay_s == delay
    for name in ("SAFELANE_NO_NUMBA", "SAFELANE_NO_FUSED"):
        monkeypatch.delenv(name, raising=False)
    fused = simulate_batch(batch, seed=4, config=cfg)
    assert fused.engine == "compiled loop", fused.engine_reasons
    monkeypatch.setenv("SAFELANE_NO_NUMBA", "1")
    table = simulate_batch(batch, seed=4, config=cfg).table
    assert fused.table.equals(table)
    assert (table[["n_proceed", "n_hesitate", "n_abort"]].sum() > 0).all()
    undelayed = simulate_batch(batch, seed=4, config=SimConfig()).table
    assert not undelayed[["n_proceed", "n_hesitate", "n_abort"]].equals(table[["n_proceed", "n_hesitate", "n_abort"]])
    real = RssRule.decide

    def carried(self, inp, params):
        x, v = carry_worst(inp.chain_x, inp.chain_v, self.brake_max(inp, params), delay)
        return real(self, dataclasses.replace(inp, chain_x=x, chain_v=v), params)

    monkeypatch.setattr(RssRule, "decide", carried)
    assert simulate_batch(batch, seed=4, config=cfg).table.equals(table)

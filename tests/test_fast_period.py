"""The compiled control period (``shield/fast_step.py``, ``shield/_fast_period.py``) against the NumPy stages
(``shield.core.stages_step``), field by field, over many periods of random worlds; and its dispatch, which never runs a
setting it does not implement."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from safelane import Params
from safelane.shield import Shield, ShieldConfig, Situation, fast_step
from safelane.shield import core as shield_core

pytestmark = pytest.mark.skipif(fast_step.kernel() is None, reason="numba missing or SAFELANE_NO_NUMBA=1")


def random_world(rng: np.random.Generator, n: int, m: int, *, stale: bool, own: bool = False) -> dict:
    """A batch of lane-change starts: ego in its lane, F behind, a chain of ``m`` ahead (random N, promises, humans)."""
    ego_v = rng.uniform(15.0, 32.0, n)
    gaps = rng.uniform(6.0, 30.0, (n, m))
    world = dict(
        ego=[np.zeros(n), rng.uniform(0.0, 1.5, n), ego_v, rng.uniform(-0.2, 0.8, n)],
        f=[-rng.uniform(5.0, 30.0, n), ego_v + rng.uniform(-4.0, 4.0, n)],
        lead=[np.cumsum(gaps, 1) + rng.uniform(-2.0, 2.0, (n, 1)), ego_v[:, None] + rng.uniform(-5.0, 3.0, (n, m))],
        n_connected=rng.integers(0, m, n),
        promise=rng.uniform(0.5, 4.0, (n, m - 1)),
        human=rng.random((n, m - 1)) < 0.3,
        f_connected=rng.random(n) < 0.5,
        f_collaborative=rng.random(n) < 0.5,
        truth=rng.random(n) < 0.5,
        stale=(rng.random(n) < 0.05) if stale else None,
    )
    world["lead"][1] = np.maximum(world["lead"][1], 0.0)
    if own:
        l0 = np.where(rng.random(n) < 0.6, rng.uniform(8.0, 40.0, n), np.inf)
        l0b = np.where(np.isfinite(l0) & (rng.random(n) < 0.5), l0 + rng.uniform(8.0, 30.0, n), np.inf)
        world["own"] = [np.column_stack([l0, l0b]), np.column_stack([ego_v, ego_v]) + rng.uniform(-6.0, 2.0, (n, 2))]
        world["own"][1] = np.maximum(world["own"][1], 0.0)
        world["own_n"] = (rng.random(n) < 0.5).astype(int)
        world["own_promise"] = rng.uniform(0.5, 4.0, (n, 1))
    return world


def situation_of(world: dict, t: float, params: Params) -> Situation:
    s = Situation.from_arrays(
        t=t, ego=tuple(world["ego"]), follower=tuple(world["f"]), leaders=tuple(world["lead"]),
        n_connected=world["n_connected"], promise_decel=world["promise"], human_driven=world["human"],
        f_connected=world["f_connected"], f_collaborative=world["f_collaborative"], params=params, geometry="ignore",
        own_leaders=None if "own" not in world else tuple(world["own"]), own_n_connected=world.get("own_n", 0),
        own_promise=world.get("own_promise", 0.5),
    )  # fmt: skip
    if world["stale"] is not None:
        s = dataclasses.replace(s, v2x_stale=world["stale"].copy())
    return dataclasses.replace(s, f_aggressive_truth=world["truth"].copy())


def advance(world: dict, decision, rng: np.random.Generator, dt: float) -> None:
    """The ego under the decision's command, the others at random accelerations (some beyond their bounds, so the
    monitor fires), speeds kept at or above zero."""
    ex, ey, evx, evy = world["ego"]
    ax, ay = decision.a_x, decision.a_y
    world["ego"] = [ex + evx * dt + 0.5 * ax * dt * dt, ey + evy * dt + 0.5 * ay * dt * dt,
                    np.maximum(evx + ax * dt, 0.0), evy + ay * dt]  # fmt: skip
    for key in ("f", "lead", "own"):
        if key not in world:
            continue
        x, v = world[key]
        a = rng.uniform(-7.0, 3.0, x.shape)
        world[key] = [x + v * dt + 0.5 * a * dt * dt, np.maximum(v + a * dt, 0.0)]
    if world["stale"] is not None:
        world["stale"] = rng.random(len(ex)) < 0.05


def proposals(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    ax, ay = rng.uniform(-6.0, 4.0, n), rng.uniform(-2.0, 2.0, n)
    bad = rng.random(n) < 0.05
    ax[bad] = np.where(rng.random(bad.sum()) < 0.5, np.nan, 50.0)
    return ax, ay


def same(a, b, where: str) -> None:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        assert a.dtype == b.dtype or (a.dtype.kind in "iu" and b.dtype.kind in "iu"), f"{where}: {a.dtype} {b.dtype}"
        assert a.shape == b.shape, f"{where}: shape {a.shape} vs {b.shape}"
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), f"{where}: {a} vs {b}"
    elif dataclasses.is_dataclass(a):
        for f in dataclasses.fields(a):
            name = "plan" if f.name == "_plan" else f.name  # (a Decision's plan: built when read)
            if name != "params":
                same(getattr(a, name), getattr(b, name), f"{where}.{name}")
    elif isinstance(a, tuple):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            same(x, y, f"{where}[{i}]")
    else:
        assert a == b or (a is None and b is None), f"{where}: {a!r} vs {b!r}"


@pytest.mark.parametrize(
    ("seed", "n", "m", "variant", "config", "own"),
    [
        (0, 64, 3, "CV_all", {}, False),
        (1, 40, 1, "CV_all", {}, False),
        (2, 50, 4, "CV_none", {}, False),
        (6, 50, 3, "No_agg_assess", {}, False),
        (7, 40, 3, ("CV_follow", "CV_all", "CV_none", "No_agg_assess") * 10, {}, False),
        (3, 30, 3, "CV_all", {"monitor": False}, False),
        (4, 1, 3, "CV_all", {}, False),
        (5, 48, 2, "CV_all", {"assess_window": 3, "assess_threshold": 0.1}, False),
        (8, 64, 3, "CV_all", {}, True),
        (9, 48, 2, "CV_none", {}, True),
        (10, 40, 3, "CV_all", {"own_lane": False}, True),
        (11, 48, 3, "CV_all", {"assessment": "truth"}, True),
        (12, 64, 3, "CV_all", {"completion": "paper_evasion"}, False),
        (13, 48, 2, ("CV_follow", "CV_all", "CV_none", "No_agg_assess") * 12, {"completion": "paper_evasion"}, True),
        (14, 64, 3, "CV_all", {"assessment": "slow", "assess_delay_s": 0.5, "assess_miss": 0.1}, False),
        (15, 48, 3, "No_agg_assess", {"assessment": "slow", "assess_delay_s": 3.0, "assess_miss": 0.231}, True),
        # RSS's rule (shield/_fast_rules.py): both parameter sets, with and without V2X, beside the paper's rows
        (16, 64, 3, ("RSS", "RSS_V2X", "RSS_matched", "RSS_V2X_matched"), {}, False),
        (17, 48, 3, ("RSS", "RSS_V2X_matched", "CV_all", "RSS_matched", "RSS_V2X", "No_agg_assess") * 8, {}, True),
        (18, 40, 4, "RSS_V2X", {"completion": "paper_evasion", "monitor": False}, True),
    ],
)
def test_compiled_period_is_the_stages(seed, n, m, variant, config, own):
    params = Params(a_o_d=8.0) if seed % 2 else Params()
    cfg = ShieldConfig(**config)
    rng = np.random.default_rng(seed)
    world = random_world(rng, n, m, stale=seed % 3 == 0, own=own)
    if isinstance(variant, tuple) and len(variant) < n:
        variant = variant * (n // len(variant))
    shield = Shield(params, variant=variant, config=cfg)
    start = situation_of(world, 0.0, params)
    shield.reset(start)
    state = shield_core.init(start, params, cfg, variant)
    behaviours, own_aborts, rss_behaviours = set(), 0, []
    for k in range(60):
        s = situation_of(world, k * params.dt, params)
        prop = proposals(rng, n)
        fast = shield.step(s, prop)
        assert shield.last_path == "compiled"
        held = state.plan.continues
        state, ref = shield_core.stages_step(state, s, prop, params, cfg, variant)
        own_aborts += int((held & (ref.behaviour == 2)).sum())
        same(fast, ref, f"period {k}: decision")
        same(shield.state, state, f"period {k}: state")
        behaviours.update(ref.behaviour.tolist())
        rss_behaviours.append(ref.behaviour)
        advance(world, ref, rng, params.dt)
    if n > 1:  # the worlds reach every behaviour (the conservative variants and L0 rarely complete): every branch ran
        slow = config.get("assessment") == "slow"  # (F stays "aggressive" longer: completions are rare)
        assert behaviours >= ({0, 1, 2, -1} if variant == "CV_all" and not own and not slow else {0, 1, 2}), behaviours
    if config.get("assessment") == "slow":  # the per-scenario draws were compared; they vary (its release: the loop's
        belief = shield.state.belief  # paper-preset case in test_fast_loop.py, where F is found collaborative)
        assert belief.missed.any() and not belief.missed.all() and np.unique(belief.delay_s).size > n // 2
    if "RSS" in str(variant):  # RSS's rows reach every behaviour too; without L0, completion (then following)
        ruled = np.char.startswith(np.asarray(variant if isinstance(variant, tuple) else (variant,) * n), "RSS")
        reached = set(np.unique(np.array(rss_behaviours)[:, ruled]).tolist())
        assert reached >= ({0, 1, 2} if own else {0, 1, 2, -1}), reached
    if own and config.get("own_lane", True):  # aborts on plans made with L0 (the profile that follows it) compared
        assert own_aborts > 0


def test_switching_paths_keeps_the_state(monkeypatch):
    """A period the compiled path refuses (a situation field it does not read appears) runs the stages from the
    unpacked state, and the next compiled period packs the stages' state again: the same decisions as the stages
    throughout."""
    monkeypatch.delitem(fast_step.SITUATION_FIELDS, "f_speed_observed")
    params = Params()
    rng = np.random.default_rng(7)
    world = random_world(rng, 20, 3, stale=False)
    shield = Shield(params)
    start = situation_of(world, 0.0, params)
    shield.reset(start)
    state = shield_core.init(start, params, ShieldConfig(), "CV_all")
    paths = []
    for k in range(60):
        s = situation_of(world, k * params.dt, params)
        if 10 <= k < 15:
            s = dataclasses.replace(s, f_speed_observed=s.f_v + 0.5)
        prop = proposals(rng, 20)
        fast = shield.step(s, prop)
        paths.append(shield.last_path)
        state, ref = shield_core.stages_step(state, s, prop, params, ShieldConfig(), "CV_all")
        same(fast, ref, f"period {k}")
        same(shield.state, state, f"period {k}: state")
        advance(world, ref, rng, params.dt)
    assert paths == ["compiled"] * 10 + ["stages"] * 5 + ["compiled"] * 45, paths


def test_every_config_field_is_classified():
    """The dispatch is built from ShieldConfig's own fields: a new field refuses until someone classifies it."""
    assert set(fast_step.COMPILED) == set(ShieldConfig.model_fields)
    assert fast_step.refusals(ShieldConfig(), "CV_all", 4) == []


@pytest.mark.parametrize(
    ("config", "reason"),
    [
        ({"completion": "paper_body_across"}, "ShieldConfig.completion='paper_body_across'"),
        ({"enabled": False}, "ShieldConfig.enabled=False"),
    ],
)
def test_refused_settings_run_the_stages(config, reason):
    params = Params()
    rng = np.random.default_rng(11)
    world = random_world(rng, 8, 3, stale=False)
    shield = Shield(params, config=ShieldConfig(**config))
    s = situation_of(world, 0.0, params)
    shield.reset(s)
    assert reason in shield.refusals(s)
    shield.step(s, proposals(rng, 8))
    assert shield.last_path == "stages"


def test_functional_step_runs_the_compiled_period(monkeypatch):
    """shield.core.step (the functional API the simulator calls) takes the compiled period where it is implemented:
    the same decisions and states as the stages (with a delay too: tests/test_fast_delay.py), and the stages where it
    is refused (the shield disabled)."""
    params = Params()
    rng = np.random.default_rng(21)
    world = random_world(rng, 16, 3, stale=False)
    s = situation_of(world, 0.0, params)
    for cfg, compiled in ((ShieldConfig(), True), (ShieldConfig(actuation_delay_s=0.1), True),
                          (ShieldConfig(enabled=False), False)):  # fmt: skip
        state = shield_core.init(s, params, cfg, "CV_all")
        prop = proposals(rng, 16)
        calls = []

        def counted(*args, _calls=calls, _step=fast_step.step, **kwargs):
            _calls.append(1)
            return _step(*args, **kwargs)

        with monkeypatch.context() as patch:
            patch.setattr(fast_step, "step", counted)
            new, decision = shield_core.step(state, s, prop, params, cfg, "CV_all")
        ref_state, ref = shield_core.stages_step(state, s, prop, params, cfg, "CV_all")
        assert bool(calls) == compiled
        same(decision, ref, "decision")
        same(new, ref_state, "state")
    # A chain analysis given by the caller is taken as given on both paths (here a deliberately different one).
    state = shield_core.init(s, params, ShieldConfig(), "CV_all")
    given = (np.full((16, 3), 0.25), rng.random(16) < 0.3)
    prop = proposals(rng, 16)
    _, decision = shield_core.step(state, s, prop, params, chain=given)
    _, ref = shield_core.stages_step(state, s, prop, params, chain=given)
    same(decision, ref, "decision with a given chain")
    np.testing.assert_array_equal(decision.l1_decel, np.where(given[1], params.others_decel, 0.25))


def test_unclassified_situation_field_refuses(monkeypatch):
    """A Situation field the compiled period does not read refuses wherever it is set (a new field too)."""
    params = Params()
    s = situation_of(random_world(np.random.default_rng(3), 4, 3, stale=False), 0.0, params)
    monkeypatch.delitem(fast_step.SITUATION_FIELDS, "f_speed_observed")
    assert fast_step.situation_refusals(s, ShieldConfig(), None) == []  # unset: nothing to refuse
    s = dataclasses.replace(s, f_speed_observed=s.f_v.copy())
    assert fast_step.situation_refusals(s, ShieldConfig(), None) == ["Situation.f_speed_observed"]


def test_unclassified_field_refuses(monkeypatch):
    monkeypatch.delitem(fast_step.COMPILED, "monitor")
    assert fast_step.refusals(ShieldConfig(), "CV_all", 4) == ["ShieldConfig.monitor=True (not classified)"]


def test_a_rule_the_period_does_not_implement_refuses(monkeypatch):
    """RSS's rule runs compiled with either parameter set; a rule registered in its place that is not an ``RssRule``
    (a user's own) refuses, naming it, and its rows run the stages (where the rule itself decides them)."""
    from safelane.shield.rules import DECISION_RULES, Coded

    class Mine:
        def __repr__(self):
            return "Mine()"

        def decide(self, inputs, params):
            raise NotImplementedError

    assert fast_step.refusals(ShieldConfig(), ("RSS_matched", "CV_all"), 2) == []
    monkeypatch.setitem(DECISION_RULES, "rss", Coded(Mine()))
    assert fast_step.refusals(ShieldConfig(), ("RSS", "CV_all"), 2) == [
        "rows decided by a rule the compiled period does not implement: Mine()"]
    assert fast_step.refusals(ShieldConfig(), ("RSS_matched", "CV_all"), 2) == []


def test_rss_rows_and_situations_refuse():
    params = Params()
    rng = np.random.default_rng(12)
    world = random_world(rng, 6, 3, stale=False, own=True)
    s = situation_of(world, 0.0, params)
    assert fast_step.refusals(ShieldConfig(), "RSS", 6) == []  # RSS's rule is compiled (shield/_fast_rules.py)
    assert fast_step.situation_refusals(s, ShieldConfig(), None) == []
    s = dataclasses.replace(s, err_f=np.full((6, 2), 0.1))  # sensing bounds run compiled (tests/test_fast_sensing.py)
    assert fast_step.situation_refusals(s, ShieldConfig(), None) == []
    assert fast_step.situation_refusals(s, ShieldConfig(sensing=False), None) == []


def test_a_delay_without_commands_in_flight_is_a_clear_error(monkeypatch):
    """A state without commands in flight (``init`` without a delay) stepped with an actuation delay: the compiled
    period refuses it, and the stages say what is wrong (the state was made with another config)."""
    params = Params()
    rng = np.random.default_rng(41)
    s = situation_of(random_world(rng, 12, 3, stale=False), 0.0, params)
    state = shield_core.init(s, params, ShieldConfig(), "CV_all")
    assert state.pending is None
    cfg = ShieldConfig(actuation_delay_s=0.2)
    assert fast_step.situation_refusals(s, cfg, state) == ["an actuation delay without commands in flight"]
    prop = proposals(rng, 12)
    monkeypatch.setattr(fast_step, "step", lambda *a, **k: pytest.fail("the compiled period ran"))
    with pytest.raises(ValueError, match=r"no commands in flight, but the config has an actuation delay of 0\.2 s"):
        shield_core.step(state, s, prop, params, cfg, "CV_all")


def test_world_model_is_folded_before_the_compiled_period():
    """With the world model's other vehicles (far-lane and other-side entrants, straddlers, a connected one that
    announces), Shield.step and shield.core.step fold them and run compiled; the decisions and states are the
    stages' (which fold them in their observe stage) over 40 periods."""
    from safelane.shield.world import Others, roles

    params = Params()
    rng = np.random.default_rng(31)
    n, k = 24, 4
    world = random_world(rng, n, 3, stale=False)
    lanes = np.array([-1.0, 0.0, 1.0, 2.0])
    ox = rng.uniform(-30.0, 60.0, (n, k))
    oy = lanes * params.lane_width + rng.uniform(-1.2, 1.2, (n, k))
    ovx = world["ego"][2][:, None] + rng.uniform(-5.0, 3.0, (n, k))
    ovy = rng.uniform(-0.8, 0.8, (n, k))
    connected = rng.random((n, k)) < 0.3
    announce = np.where(connected & (rng.random((n, k)) < 0.5), 1, -9)

    def with_others(s, t):
        others = Others.from_arrays(ox + ovx * t, oy + ovy * np.minimum(t, 1.0), np.maximum(ovx, 0.0), ovy,
                                    connected, np.where(announce == 1, 1, Others.empty(1, 1).announce_lane[0, 0]),
                                    np.where(announce == 1, 2.0, np.inf))  # fmt: skip
        return dataclasses.replace(s, others=others)

    shield = Shield(params)
    start = with_others(situation_of(world, 0.0, params), 0.0)
    folded = roles(start, params)  # the others do change the roles in many rows (else this test compares nothing new)
    changed = (folded.f_x != start.f_x) | (folded.chain_x[:, 0] != start.chain_x[:, 0])
    if folded.own_x is not None:
        changed |= np.isfinite(folded.own_x[:, 0])
    assert changed.sum() >= n // 4, changed.sum()
    shield.reset(start)
    state = shield_core.init(start, params, ShieldConfig(), "CV_all")
    functional_state = state  # shield.core.step, the functional API, folds the others itself, then runs compiled too

    def compiled_step(*args):
        calls = []

        def counted(*a, _step=fast_step.step, **kw):
            calls.append(1)
            return _step(*a, **kw)

        saved, fast_step.step = fast_step.step, counted
        try:
            out = shield_core.step(*args)
        finally:
            fast_step.step = saved
        assert calls, "shield.core.step took the stages where the compiled period runs"
        return out

    for step in range(40):
        t = step * params.dt
        s = with_others(situation_of(world, t, params), t)
        prop = proposals(rng, n)
        fast = shield.step(s, prop)
        assert shield.last_path == "compiled"
        functional_state, functional = compiled_step(functional_state, s, prop, params)
        state, ref = shield_core.stages_step(state, s, prop, params)
        same(fast, ref, f"period {step}")
        same(shield.state, state, f"period {step}: state")
        same(functional, ref, f"period {step}: shield.core.step")
        same(functional_state, state, f"period {step}: shield.core.step's state")
        advance(world, ref, rng, params.dt)


def test_the_traffic_pool_goes_on_from_the_packed_state():
    """The traffic layer's pool (safelane.traffic.shielding) keeps the shield's packed state while its rows stay the
    same (it would unpack it to select rows that leave or join): its decisions are the stages' from one init."""
    from safelane.traffic.shielding import ShieldPool

    params = Params()
    rng = np.random.default_rng(21)
    world = random_world(rng, 12, 3, stale=False, own=True)
    pool = ShieldPool(params)
    start = situation_of(world, 0.0, params)
    state = shield_core.init(start, params, ShieldConfig(), "CV_all")
    for k in range(40):
        s = situation_of(world, k * params.dt, params)
        prop = proposals(rng, 12)
        fast = pool.decide(s, prop, np.arange(12) if k else np.zeros(0, np.int64), 0 if k else 12)
        assert pool.shield.last_path == "compiled"
        assert pool.shield._state is None  # the packed state kept, never unpacked by the pool
        state, ref = shield_core.stages_step(state, s, prop, params, ShieldConfig(), "CV_all")
        same(fast, ref, f"period {k}")
        advance(world, ref, rng, params.dt)
    assert pool.calls == 40 and pool.shield.rows == 12


def test_regrouping_rows_that_leave_and_join_keeps_the_packed_state_and_the_stages_decisions():
    """``Shield.regroup`` (vehicles that come and go, the traffic pool's use) on the compiled path's packed state:
    rows leave, new rows join (with a neutral monitor snapshot), and every period's decision and the state read
    back are the stages' on the unpacked state selected and joined row by row (:mod:`safelane.shield.rows`); the
    packed state is never unpacked on the way."""
    from safelane.shield import rows as rws

    params = Params()
    rng = np.random.default_rng(33)
    world = random_world(rng, 16, 3, stale=False, own=True)
    active = np.arange(10)
    shield = Shield(params)
    shield.regroup(np.zeros(0, np.int64), rws.take_rows(situation_of(world, 0.0, params), active), 0.0)
    state = shield_core.init(rws.take_rows(situation_of(world, 0.0, params), active), params, ShieldConfig(), "CV_all")
    changes = {8: ([0, 2, 3, 5, 6, 7, 8, 9], []), 12: ([1, 2, 3, 4, 5, 6, 7], [10, 11, 12]),
               20: ([0, 1, 2, 3, 4, 5, 6, 7, 8, 9], [13, 14, 15])}  # fmt: skip
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
                fresh = shield_core.init(joined, params, ShieldConfig(), "CV_all")
                fresh = dataclasses.replace(fresh, last=rws.neutral_snapshot(len(new), 3, params))
                state = rws.join_rows(state, fresh)
            state = dataclasses.replace(state, t=t)
            active = np.concatenate([active[keep], new]).astype(np.int64)
        s = rws.take_rows(full, active)
        prop = proposals(rng, len(active))
        fast = shield.step(s, prop)
        assert shield.last_path == "compiled"
        state, ref = shield_core.stages_step(state, s, prop, params, ShieldConfig(), "CV_all")
        same(fast, ref, f"period {k}")
        same(shield.completed, state.completed, f"period {k}: completed")
        a_x, a_y = np.zeros(16), np.zeros(16)
        a_x[active], a_y[active] = ref.a_x, ref.a_y
        advance(world, dataclasses.replace(ref, a_x=a_x, a_y=a_y), rng, params.dt)
    same(shield.state, state, "the state read back")
    assert shield.rows == 13

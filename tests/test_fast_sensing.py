"""The compiled control period with sensing-error bounds (``ShieldConfig.sensing``; ``shield/_fast_period.py``'s
corners, each chain link at its own corner, the own lane's bound, the monitor's observed corner and its cumulative
anchor) against the NumPy stages (``shield.core.stages_step``), every Decision field and the next state, over many
periods of random worlds."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from safelane import Params
from safelane.shield import SensingBounds, Shield, ShieldConfig, fast_step
from safelane.shield import core as shield_core
from test_fast_period import advance, proposals, random_world, same, situation_of

pytestmark = [
    pytest.mark.compiled,
    pytest.mark.skipif(fast_step.kernel() is None, reason="numba missing or SAFELANE_NO_NUMBA=1"),
]

#: Which bounds a situation carries: every one, F's alone, the chain's alone, the own lane's alone, the defaults of
#: :class:`SensingBounds` (by connectivity).
BOXES = ("all", "f", "chain", "own", "defaults")


def with_box(s, rng: np.random.Generator, box: str):
    """``s`` with sensing-error bounds of the kind ``box`` (random per vehicle, some zero)."""
    n, m = s.chain_x.shape
    if box == "defaults":
        return SensingBounds().apply(s)
    draw = lambda *shape: np.where(rng.random(shape) < 0.15, 0.0, rng.uniform(0.0, 1.5, shape))  # noqa: E731
    fields = {}
    if box in ("all", "f"):
        fields["err_f"] = draw(n, 2)
    if box in ("all", "chain"):
        fields["err_chain"] = draw(n, m, 2)
    if box in ("all", "own") and s.own_x is not None:
        fields["err_own"] = draw(n, s.own_x.shape[1], 2)
    return dataclasses.replace(s, **fields)


def run_both(seed, n, m, variant, config, own, box, periods=50, gaps=()):
    """``periods`` periods of the stateful Shield (compiled, checked every period) beside the stages from one init;
    ``gaps``: periods whose situation carries no bounds. Returns the stages' decisions and the last state."""
    params = Params(a_o_d=8.0) if seed % 2 else Params()
    cfg = ShieldConfig(**config)
    rng = np.random.default_rng(seed)
    world = random_world(rng, n, m, stale=seed % 3 == 0, own=own)
    if isinstance(variant, tuple) and len(variant) < n:
        variant = variant * (n // len(variant))
    shield = Shield(params, variant=variant, config=cfg)
    box_rng = np.random.default_rng(seed + 1000)
    start = with_box(situation_of(world, 0.0, params), box_rng, box)
    shield.reset(start)
    state = shield_core.init(start, params, cfg, variant)
    decisions = []
    for k in range(periods):
        s = situation_of(world, k * params.dt, params)
        if k not in gaps:
            s = with_box(s, box_rng, box)
        prop = proposals(rng, n)
        fast = shield.step(s, prop)
        assert shield.last_path == "compiled", shield.refusals(s)
        state, ref = shield_core.stages_step(state, s, prop, params, cfg, variant)
        same(fast, ref, f"period {k}: decision")
        same(shield.state, state, f"period {k}: state")
        same(shield_core.observe(shield.state, s, params), shield_core.observe(state, s, params), f"period {k}")
        decisions.append(ref)
        advance(world, ref, rng, params.dt)
    return decisions, state


@pytest.mark.parametrize(
    ("seed", "n", "m", "variant", "config", "own", "box"),
    [
        (0, 64, 3, "CV_all", {}, False, "all"),
        (1, 40, 1, "CV_all", {}, False, "all"),
        (2, 48, 2, "CV_none", {}, True, "all"),
        (3, 48, 4, "CV_all", {}, True, "defaults"),
        (4, 1, 3, "CV_all", {}, True, "all"),
        (5, 48, 3, ("CV_follow", "CV_all", "CV_none", "No_agg_assess") * 12, {}, True, "all"),
        (6, 48, 3, "CV_all", {}, True, "f"),
        (7, 48, 3, "CV_all", {}, True, "chain"),
        (8, 48, 3, "CV_all", {}, True, "own"),
        (9, 48, 2, "No_agg_assess", {"assessment": "slow", "assess_delay_s": 0.5, "assess_miss": 0.1}, True, "all"),
        (10, 40, 3, "CV_all", {"completion": "paper_evasion"}, True, "all"),
        (11, 40, 3, "CV_all", {"own_lane": False}, True, "all"),
        (12, 48, 3, ("RSS", "RSS_V2X", "CV_all", "RSS_matched", "RSS_V2X_matched", "No_agg_assess") * 8, {}, True,
         "all"),
        (13, 40, 4, "RSS_V2X", {"monitor": False}, False, "defaults"),
        (14, 40, 3, "CV_all", {"assessment": "truth"}, True, "all"),
    ],
)
def test_compiled_period_with_sensing_is_the_stages(seed, n, m, variant, config, own, box):
    decisions, state = run_both(seed, n, m, variant, config, own, box)
    flags = np.array([d.breach.flags for d in decisions])
    if n > 1 and box != "own":  # the monitor compares (the anchor too): breaches occur, in some rows and not all
        hit = flags[-1].any(1)
        assert hit.any() and not hit.all(), hit.mean()
    if n > 1 and box != "own" and config.get("monitor", True):  # the cumulative comparison ran (an anchor is held)
        assert state.last.anchor is not None
    behaviours = set(np.concatenate([d.behaviour for d in decisions]).tolist())
    if n > 1:
        assert {0, 1, 2} <= behaviours, behaviours


def test_bounds_that_come_and_go():
    """Periods without bounds between bounded ones: the anchor held is compared and dropped, as the stages do, and a
    new one is made when the bounds return; the chain's box alone, then F's alone."""
    run_both(21, 32, 3, "CV_all", {}, True, "all", periods=40, gaps=(5, 6, 20))
    run_both(22, 32, 3, "CV_all", {}, True, "chain", periods=30, gaps=(3, 10, 11))
    run_both(23, 32, 2, "CV_all", {}, False, "f", periods=30, gaps=(0, 12))


def test_sensing_off_ignores_the_bounds():
    """``ShieldConfig(sensing=False)``: the paper's exact states (the bounds are read and not used), compiled."""
    run_both(24, 32, 3, "CV_all", {"sensing": False}, True, "all", periods=30)


def test_functional_step_with_bounds_runs_compiled(monkeypatch):
    """``shield.core.step`` (the functional API) takes the compiled period for a bounded situation, with the held
    anchor packed from the state: the stages' decisions and states."""
    params = Params()
    rng = np.random.default_rng(25)
    world = random_world(rng, 16, 3, stale=False, own=True)
    box_rng = np.random.default_rng(26)
    s = with_box(situation_of(world, 0.0, params), box_rng, "all")
    cfg = ShieldConfig()
    state = ref_state = shield_core.init(s, params, cfg, "CV_all")
    calls = []

    def counted(*args, _step=fast_step.step, **kwargs):
        calls.append(1)
        return _step(*args, **kwargs)

    monkeypatch.setattr(fast_step, "step", counted)
    for k in range(20):
        s = with_box(situation_of(world, k * params.dt, params), box_rng, "all")
        prop = proposals(rng, 16)
        state, decision = shield_core.step(state, s, prop, params, cfg, "CV_all")
        ref_state, ref = shield_core.stages_step(ref_state, s, prop, params, cfg, "CV_all")
        same(decision, ref, f"period {k}: decision")
        same(state, ref_state, f"period {k}: state")
        advance(world, ref, rng, params.dt)
    assert len(calls) == 20
    assert ref_state.last.anchor is not None


def test_no_sensing_refusal_remains():
    params = Params()
    s = situation_of(random_world(np.random.default_rng(27), 6, 3, stale=False, own=True), 0.0, params)
    s = with_box(s, np.random.default_rng(28), "all")
    assert fast_step.situation_refusals(s, ShieldConfig(), None) == []
    shield = Shield(params)
    shield.reset(s)
    assert shield.refusals(s) == []
    shield.step(s, (0.0, 0.0))
    assert shield.last_path == "compiled"


def test_world_model_with_bounds_is_folded_and_runs_compiled():
    """The world model's other vehicles with sensing-error bounds (an inserted vehicle takes the row's loosest bound,
    ``world.fold``): folded first, then the compiled period with the box; the stages' decisions and states."""
    from safelane.shield.world import Others

    params = Params()
    rng = np.random.default_rng(29)
    n, k = 24, 4
    world = random_world(rng, n, 3, stale=False, own=True)
    lanes = np.array([-1.0, 0.0, 1.0, 2.0])
    ox = rng.uniform(-30.0, 60.0, (n, k))
    oy = lanes * params.lane_width + rng.uniform(-1.2, 1.2, (n, k))
    ovx = world["ego"][2][:, None] + rng.uniform(-5.0, 3.0, (n, k))
    ovy = rng.uniform(-0.8, 0.8, (n, k))
    connected = rng.random((n, k)) < 0.3
    box_rng = np.random.default_rng(30)

    def observed(t):
        others = Others.from_arrays(ox + ovx * t, oy + ovy * np.minimum(t, 1.0), np.maximum(ovx, 0.0), ovy,
                                    connected, np.full((n, k), Others.empty(1, 1).announce_lane[0, 0]),
                                    np.full((n, k), np.inf))  # fmt: skip
        s = with_box(situation_of(world, t, params), box_rng, "all")
        return dataclasses.replace(s, others=others)

    shield = Shield(params)
    start = observed(0.0)
    shield.reset(start)
    state = shield_core.init(start, params, ShieldConfig(), "CV_all")
    for step in range(30):
        s = observed(step * params.dt)
        prop = proposals(rng, n)
        fast = shield.step(s, prop)
        assert shield.last_path == "compiled", shield.refusals(s)
        state, ref = shield_core.stages_step(state, s, prop, params)
        same(fast, ref, f"period {step}")
        same(shield.state, state, f"period {step}: state")
        advance(world, ref, rng, params.dt)
    assert state.last.anchor is not None


def test_a_chain_that_changes_length_renews_the_anchor():
    """The last leader leaves the chain for a while (M 3 → 2 → 3): the anchor's chain is not compared across the
    change and is taken anew (``Anchor.carried``), on both paths alike."""
    params = Params()
    rng = np.random.default_rng(5)
    n = 20
    world = random_world(rng, n, 3, stale=False, own=True)
    box_rng = np.random.default_rng(6)

    def observed(k):
        s = situation_of(world, k * params.dt, params)
        if 5 <= k < 10:
            s = dataclasses.replace(s, chain_x=s.chain_x[:, :2].copy(), chain_v=s.chain_v[:, :2].copy(),
                                    chain_promise=s.chain_promise[:, :1].copy(),
                                    chain_human=s.chain_human[:, :1].copy(), n_connected=np.minimum(s.n_connected, 1))
        return with_box(s, box_rng, "all")

    shield = Shield(params)
    start = observed(0)
    shield.reset(start)
    state = shield_core.init(start, params, ShieldConfig(), "CV_all")
    for k in range(20):
        s = observed(k)
        prop = proposals(rng, n)
        fast = shield.step(s, prop)
        assert shield.last_path == "compiled"
        state, ref = shield_core.stages_step(state, s, prop, params)
        same(fast, ref, f"period {k}")
        same(shield.state, state, f"period {k}: state")
        advance(world, ref, rng, params.dt)


def test_regrouping_keeps_the_packed_anchor():
    """``Shield.regroup`` keeping some rows (the traffic pool's use) takes the packed anchor's rows with the rest of
    the state: the stages' decisions on the unpacked state's rows (:func:`safelane.shield.rows.take_rows`)."""
    from safelane.shield import rows as rws

    params = Params()
    rng = np.random.default_rng(31)
    world = random_world(rng, 16, 3, stale=False, own=True)
    box_rng = np.random.default_rng(32)
    active = np.arange(16)
    start = with_box(situation_of(world, 0.0, params), box_rng, "all")
    shield = Shield(params)
    shield.reset(start)
    state = shield_core.init(start, params, ShieldConfig(), "CV_all")
    for k in range(24):
        t = k * params.dt
        if k in (6, 15):
            keep = np.arange(0, len(active), 2 if k == 6 else 3)
            shield.regroup(keep, None, t)
            assert shield._state is None and shield._packed.anchor is not None  # regrouped packed
            state = dataclasses.replace(rws.take_rows(state, keep), t=t)
            active = active[keep]
        s = with_box(rws.take_rows(situation_of(world, t, params), active), box_rng, "all")
        prop = proposals(rng, len(active))
        fast = shield.step(s, prop)
        assert shield.last_path == "compiled"
        state, ref = shield_core.stages_step(state, s, prop, params, ShieldConfig(), "CV_all")
        same(fast, ref, f"period {k}")
        a_x, a_y = np.zeros(16), np.zeros(16)
        a_x[active], a_y[active] = ref.a_x, ref.a_y
        advance(world, dataclasses.replace(ref, a_x=a_x, a_y=a_y), rng, params.dt)
    same(shield.state, state, "the state read back")


@pytest.mark.parametrize(("seed", "periods", "own", "variant"), [(30, 2, True, "CV_all"), (31, 1, False, "CV_none"),
                                                                  (32, 3, True, ("CV_all", "RSS", "CV_follow"))])
def test_bounds_under_an_actuation_delay_are_the_stages(seed, periods, own, variant):
    """The real world's two shield extensions together: the corners carried over the commands in flight (the frame
    of the analysis' corner), the monitor's anchor from the period's start — the stages' bits."""
    decisions, state = run_both(seed, 48, 3, variant, {"actuation_delay_s": periods * 0.1}, own, "all")
    assert len(state.pending.commands) == periods
    behaviours = np.concatenate([d.behaviour for d in decisions])
    assert {0, 1, 2} <= set(behaviours.tolist())  # proceed, hesitate and abort all ran
    assert np.concatenate([d.breach.flags.any(1) for d in decisions]).any()  # the monitor compared the box

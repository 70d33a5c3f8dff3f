"""The shield's step (``shield/core.py``) as a unit: fast checks on random batches of hand-built situations.

* ``chain_analysis`` against the independent bisection reference of Eqs. 1–3 (``tests/reference.py``), its
  sensing-error path against the exact one (zero bounds: the same; positive bounds: never less conservative);
* ``sensing=False`` takes the measurements as exact (the same decisions as a situation without bounds), and each
  bound alone changes some decision when ``sensing`` is on;
* the staleness record (``stale_v2x``), ``observe`` and the stateful :class:`Shield`'s plumbing;
* the documented meaning of every field of a :class:`Decision` (module docstrings of ``core``, ``decide``,
  ``decision``), checked row by row on random batches for every variant and configuration.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from reference import ref_leader_chain
from safelane import Params
from safelane._motion import advance
from safelane.planners.variants import VARIANTS
from safelane.safety.evasion import plan_evasion
from safelane.safety.responsible import responsible_accel, responsible_bound
from safelane.shield import (
    ABORT,
    BREACH_KINDS,
    COMPLETED,
    HESITATE,
    PROCEED,
    SensingBounds,
    Shield,
    ShieldConfig,
    Situation,
    chain_analysis,
    init,
    step,
)
from safelane.shield.core import observe
from safelane.shield.decide import check_candidate, plan_motion
from safelane.shield.policies import ASSESSMENTS, COMPLETION_RULES
from safelane.shield.proposals import check_proposal
from safelane.shield.realworld import in_flight_checked, own_lane_decel, own_plan, worst_corners
from safelane.shield.rules import DECISION_RULES, RuleInputs

PRM = Params()
STALE = BREACH_KINDS.index("stale_v2x")


def _situations(rng, b, m=3, *, own=False, sensing=None, t=0.0):
    """A random batch around a lane change: the ego anywhere from its own lane to the target lane's centre, L1 and
    F near enough to matter, a partly connected chain (some human-driven links), an own-lane leader on some rows."""
    ego = (np.zeros(b), rng.uniform(-0.2, 3.0, b), rng.uniform(15.0, 30.0, b), rng.uniform(-0.6, 1.0, b))
    gaps = rng.uniform(6.0, 35.0, (b, m))
    lx = np.cumsum(gaps, 1)
    lv = np.clip(ego[2][:, None] + rng.uniform(-6.0, 4.0, (b, m)), 0.0, None)
    follower = (-rng.uniform(6.0, 40.0, b), np.clip(ego[2] + rng.uniform(-4.0, 6.0, b), 0.0, None))
    kw = {}
    if own:
        ox = np.cumsum(rng.uniform(7.5, 40.0, (b, 2)), 1)
        ox[rng.random(b) < 0.3] = np.inf
        kw = dict(own_leaders=(ox, np.clip(ego[2][:, None] + rng.uniform(-5.0, 3.0, (b, 2)), 0.0, None)),
                  own_n_connected=rng.integers(0, 2, b), own_promise=rng.uniform(0.5, 4.0, (b, 1)))  # fmt: skip
    return Situation.from_arrays(
        t=t, ego=ego, follower=follower, leaders=(lx, lv), n_connected=rng.integers(0, m, b),
        promise_decel=rng.uniform(0.3, 6.0, (b, m - 1)), human_driven=rng.random((b, m - 1)) < 0.3,
        f_connected=rng.random(b) < 0.5, f_collaborative=rng.random(b) < 0.6, params=PRM, sensing=sensing, **kw,
    )  # fmt: skip


def _open_road(ego):
    """The ego (``(x, y, v_x, v_y)`` arrays) on an open road: F 40 m behind and L1 60 m ahead, both at 25 m/s, no
    connected chain."""
    return Situation.from_arrays(t=0.0, ego=ego, follower=(-40.0, 25.0), leaders=([60.0], [25.0]), n_connected=0,
                                 params=PRM)  # fmt: skip


def _same_decision(a, b):
    for field in ("behaviour", "a_x", "a_y", "completing", "invalid", "plan_t0", "l1_decel", "f_aggressive"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)
    np.testing.assert_array_equal(a.breach.flags, b.breach.flags)


# --------------------------------------------------------------------------------------------------------------
# chain_analysis
# --------------------------------------------------------------------------------------------------------------


def test_chain_analysis_matches_the_bisection_reference():
    """Promises beyond L_N are a_x_d, human-driven connected links keep p_m_human; rows near the unsafe boundary
    (the reference's z within 1e-6 of a_x_d) are left out."""
    rng = np.random.default_rng(8)
    s = _situations(rng, 300, m=4)
    bounds, unsafe = chain_analysis(s, PRM)
    slots = np.arange(3)[None, :]
    in_chain = slots < s.n_connected[:, None]
    ref = ref_leader_chain(s.chain_x, s.chain_v, np.where(in_chain, s.chain_promise, PRM.a_x_d), PRM,
                           human=s.chain_human & in_chain)  # fmt: skip
    clear = (np.abs(ref.required - PRM.a_x_d) > 1e-6).all(1)
    assert clear.sum() > 250 and 0 < ref.unsafe[clear].sum() < clear.sum()
    np.testing.assert_array_equal(unsafe[clear], ref.unsafe[clear])
    np.testing.assert_allclose(bounds[clear], ref.decel[clear], rtol=1e-6, atol=2e-9)
    # The human margin and the connection limit both matter on this batch.
    assert (s.chain_human & in_chain).any() and (s.chain_human & ~in_chain).any()
    plain = ref_leader_chain(s.chain_x, s.chain_v, np.where(in_chain, s.chain_promise, PRM.a_x_d), PRM)
    assert (np.abs(plain.decel - ref.decel)[clear] > 1e-3).any()


def test_chain_analysis_with_sensing_bounds_is_the_exact_one_at_zero_and_more_conservative_above():
    rng = np.random.default_rng(9)
    s = _situations(rng, 200, m=4)
    exact = chain_analysis(s, PRM)
    zero = chain_analysis(dataclasses.replace(s, err_chain=np.zeros((200, 4, 2))), PRM)
    np.testing.assert_allclose(zero[0], exact[0], rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(zero[1], exact[1])
    noisy = chain_analysis(SensingBounds().apply(s), PRM)
    assert noisy[0].shape == exact[0].shape and noisy[1].shape == (200,)
    assert (noisy[0] >= exact[0] - 1e-12).all() and (noisy[1] | ~exact[1]).all()
    assert (noisy[0] > exact[0] + 1e-3).any() and (noisy[1] & ~exact[1]).any()


# --------------------------------------------------------------------------------------------------------------
# Sensing off, staleness, observe, the stateful Shield
# --------------------------------------------------------------------------------------------------------------


def _run(s_list, proposals, cfg, variant="CV_all", prm=PRM):
    state = init(s_list[0], prm, cfg, variant)
    out = []
    for s, p in zip(s_list, proposals, strict=True):
        state, d = step(state, s, p, prm, cfg, variant)
        out.append(d)
    return state, out


def _trajectory(s0, k):
    """``k`` situations: everyone at constant speed from ``s0`` (the ego too), one period apart."""
    out = []
    for i in range(k):
        h = i * PRM.dt
        rep = dict(t=s0.t + h, ego_x=s0.ego_x + s0.ego_vx * h, ego_y=s0.ego_y + s0.ego_vy * h,
                   f_x=s0.f_x + s0.f_v * h, chain_x=s0.chain_x + s0.chain_v * h)  # fmt: skip
        if s0.own_x is not None:
            rep["own_x"] = s0.own_x + s0.own_v * h
        out.append(dataclasses.replace(s0, **rep))
    return out


@pytest.mark.parametrize("which", ["err_f", "err_chain", "err_own"])
def test_sensing_off_takes_the_measurements_as_exact(which):
    rng = np.random.default_rng(12)
    b = 240
    exact = _situations(rng, b, own=True)
    bounds = SensingBounds(connected_pos_m=1.5, connected_speed_mps=1.0, sensed_pos_m=3.0, sensed_speed_mps=1.5)
    full = bounds.apply(exact)
    one = dataclasses.replace(exact, **{which: getattr(full, which)})
    steps = 3
    proposals = [(np.full(b, 1.0), np.full(b, 1.0))] * steps
    on, off = ShieldConfig(), ShieldConfig(sensing=False)
    _, d_exact = _run(_trajectory(exact, steps), proposals, on)
    _, d_off = _run(_trajectory(one, steps), proposals, off)
    _, d_on = _run(_trajectory(one, steps), proposals, on)
    for a, b_ in zip(d_exact, d_off, strict=True):
        _same_decision(a, b_)
    assert any((a.behaviour != c.behaviour).any() or (a.a_x != c.a_x).any() for a, c in zip(d_exact, d_on, strict=True))


def test_stale_v2x_is_recorded_once_with_its_first_time():
    rng = np.random.default_rng(4)
    b = 6
    s0 = _situations(rng, b)
    cfg = ShieldConfig()
    state = init(s0, PRM, cfg, "CV_all")
    stale_at = [np.array([1, 0, 0, 1, 0, 0], bool), np.array([1, 1, 0, 0, 0, 0], bool), np.zeros(b, bool)]
    zero = (np.zeros(b), np.zeros(b))
    firsts = []
    for k, stale in enumerate(stale_at):
        s = dataclasses.replace(_trajectory(s0, k + 1)[-1], v2x_stale=stale)
        state, d = step(state, s, zero, PRM, cfg, "CV_all")
        firsts.append(d.breach.first_s.copy())
        np.testing.assert_array_equal(d.breach.flags[:, STALE], np.logical_or.reduce(stale_at[: k + 1]))
    t1 = PRM.dt
    np.testing.assert_allclose(firsts[-1], [0.0, t1, np.nan, 0.0, np.nan, np.nan], equal_nan=True)
    np.testing.assert_array_equal(state.breach.flags[:, STALE], [True, True, False, True, False, False])
    # A stale message after an earlier breach of another kind keeps that breach's time.
    flags = state.breach.flags.copy()
    flags[2, 0] = True
    first = state.breach.first_s.copy()
    first[2] = 0.05
    state = dataclasses.replace(state, breach=dataclasses.replace(state.breach, flags=flags, first_s=first))
    s = dataclasses.replace(_trajectory(s0, 4)[-1], v2x_stale=np.array([0, 0, 1, 0, 0, 0], bool))
    state, d = step(state, s, zero, PRM, cfg, "CV_all")
    assert d.breach.flags[2, STALE] and d.breach.first_s[2] == 0.05


def test_stale_v2x_makes_the_shield_assume_the_worst_from_the_next_period():
    rng = np.random.default_rng(5)
    b = 200
    s0 = _situations(rng, b)
    traj = _trajectory(s0, 3)
    cfg = ShieldConfig(assessment="truth")
    s0t = [dataclasses.replace(s, f_aggressive_truth=np.zeros(b, bool)) for s in traj]
    stale = np.zeros(b, bool)
    stale[::2] = True
    state = init(s0t[0], PRM, cfg, "CV_all")
    state, d = step(state, dataclasses.replace(s0t[0], v2x_stale=stale), (np.zeros(b), np.zeros(b)), PRM, cfg)
    state, d = step(state, s0t[1], (np.zeros(b), np.zeros(b)), PRM, cfg)
    assert d.f_aggressive[stale].all() and (d.l1_decel[stale] == PRM.a_x_d).all()
    assert not d.f_aggressive[~stale].all()


def test_observe_records_the_last_period_without_deciding():
    rng = np.random.default_rng(6)
    b = 50
    s0 = _situations(rng, b)
    cfg = ShieldConfig()
    state = init(s0, PRM, cfg)
    assert observe(state, s0, PRM) is state  # nothing to compare yet
    state, _ = step(state, s0, (np.zeros(b), np.zeros(b)), PRM, cfg)
    later = _trajectory(s0, 2)[-1]
    braked = dataclasses.replace(later, chain_x=later.chain_x - 5.0)  # everyone far behind any bound
    seen = observe(state, braked, PRM)
    assert seen.breach.flags[:, 2].any() and (seen.breach.first_s[seen.breach.any] == later.t).all()
    assert seen.t == state.t and seen.plan is state.plan and seen.last is state.last
    # With measurement errors the monitor compares with the favourable corner: a 1 m slip inside a 3 m bound is
    # no breach.
    err = SensingBounds(connected_pos_m=3.0, sensed_pos_m=3.0).apply(later)
    slipped = dataclasses.replace(err, chain_x=later.chain_x - PRM.dt**2 * 0.5 * PRM.a_x_d - 1.0)
    assert not observe(state, slipped, PRM).breach.any.any()
    assert observe(state, dataclasses.replace(slipped, err_chain=None, err_f=None), PRM).breach.any.any()


def test_the_stateful_shield_uses_its_params_config_and_variant():
    rng = np.random.default_rng(7)
    b = 40
    s0 = _situations(rng, b)
    assert Shield().params == Params() and Shield().config == ShieldConfig()
    prm = Params(p_m=9.0)
    cfg = ShieldConfig(assess_window=3, actuation_delay_s=0.2)
    shield = Shield(prm, variant="CV_none", config=cfg)
    assert shield.params is prm and shield.config is cfg and shield.variant == "CV_none"
    shield.reset(s0)
    ref_state = init(s0, prm, cfg, "CV_none")
    assert shield.state.belief.history.shape == (b, 3) and len(shield.state.pending.commands) == 2
    np.testing.assert_array_equal(shield.state.plan.feasible, ref_state.plan.feasible)
    proposal = (np.full(b, 2.0), np.full(b, 1.5))
    got = shield.step(s0, proposal)
    _, want = step(ref_state, s0, proposal, prm, cfg, "CV_none")
    _same_decision(got, want)
    _, default_variant = step(ref_state, s0, proposal, prm, cfg)
    assert (default_variant.l1_decel != got.l1_decel).any()  # CV_all would differ: the variant is passed
    with pytest.raises(ValueError, match="the situation has 3 rows; the shield was reset with 40"):
        shield.step(_situations(rng, 3), (np.zeros(3), np.zeros(3)))
    with pytest.raises(ValueError, match="unknown planner variant"):
        Shield(PRM, variant=np.array(["CV_all", "CV_nope"]))
    with pytest.raises(ValueError, match="variant indices must lie"):
        Shield(PRM, variant=np.array([0, 17]))
    with pytest.raises(ValueError, match=r"Situation.ego_vx must be >= 0"):
        shield.step(dataclasses.replace(s0, ego_vx=-s0.ego_vx), proposal)
    arr = Shield(prm, variant=np.array(["CV_none"] * b), config=cfg)
    arr.reset(s0)
    _same_decision(arr.step(s0, proposal), got)


# --------------------------------------------------------------------------------------------------------------
# The step, row by row
# --------------------------------------------------------------------------------------------------------------


def _plan_row(plan, i):
    return {f.name: getattr(plan, f.name)[i] for f in dataclasses.fields(plan) if f.name != "params"}


def _same_plan_row(got, i, want, j):
    a, b = _plan_row(got, i), _plan_row(want, j)
    for name in a:
        np.testing.assert_allclose(np.asarray(a[name], float), np.asarray(b[name], float), rtol=1e-12, atol=1e-12,
                                   err_msg=name)  # fmt: skip


def _expected(state, s, proposal, prm, cfg, variant, breach_any):
    """The period's decision from the documented rules (module docstrings of ``core``, ``decide``, ``policies``),
    one row at a time: the worst case from the variant's information (the most conservative one after a breach),
    then the proposal, hesitation and the held plan in that order; a completed row follows L1 responsibly and
    centres in the target lane (``a_y = 0.8 (w_l − y) − 1.6 v_y``, clipped). Each row's candidates are checked
    with ``check_candidate`` on that row alone."""
    b = len(s)
    v = VARIANTS[variant]
    bounds, unsafe = chain_analysis(s, prm)
    broken = breach_any if cfg.monitor else np.zeros(b, bool)
    l1_decel = np.where(v.uses_chain & ~unsafe & ~broken, bounds[:, 0], prm.a_x_d)
    model = ASSESSMENTS[cfg.assessment]
    assessed = model.aggressive(model.update(state.belief, s, prm.dt, cfg), s)
    trusted = v.uses_follower_v2x & s.f_connected & s.f_collaborative
    f_aggr = np.where(trusted, False, assessed if v.uses_assessment else True) | broken
    a_x, a_y, invalid = check_proposal("p", proposal, b, prm)
    a_x, a_y = np.clip(a_x, -prm.a_x_d, prm.a_x_a), np.clip(a_y, -prm.a_y_m, prm.a_y_m)
    ex, ey, evx, evy = s.ego_x, s.ego_y, s.ego_vx, s.ego_vy
    l1x, l1v, fx, fv = s.chain_x[:, 0], s.chain_v[:, 0], s.f_x, s.f_v
    own = None
    if cfg.own_lane and s.own_x is not None:
        own = (s.own_x[:, 0], s.own_v[:, 0], own_lane_decel(s, prm, np.full(b, v.uses_chain), broken))
    delay = cfg.actuation_delay_s
    if delay > 0.0:
        ex, ey, evx, evy = state.pending.carry(ex, ey, evx, evy, prm.dt)
        l1x, l1v = advance(l1x, l1v, -l1_decel, delay)
        fx, fv = advance(fx, fv, np.where(f_aggr, prm.a_x_a, -prm.a_x_d), delay)
        if own is not None:
            own = (*advance(own[0], own[1], -own[2], delay), own[2])
    a_yh = np.clip(-evy / prm.dt, -prm.a_y_m, prm.a_y_m)
    out = dict(behaviour=np.zeros(b, int), a_x=np.zeros(b), a_y=np.zeros(b), completing=np.zeros(b, bool),
               plans={})  # fmt: skip
    for i in range(b):
        r = [i]
        if state.completed[i]:
            out["behaviour"][i] = COMPLETED
            out["a_x"][i] = responsible_accel(a_x[i], l1x[i] - ex[i] - prm.p_m, evx[i], l1v[i], l1_decel[i], prm)
            out["a_y"][i] = np.clip(0.8 * (prm.lane_width - ey[i]) - 1.6 * evy[i], -prm.a_y_m, prm.a_y_m)
            continue
        if not cfg.enabled:
            out["behaviour"][i], out["a_x"][i], out["a_y"][i] = PROCEED, a_x[i], a_y[i]
            out["completing"][i] = ey[i] + evy[i] * prm.dt + 0.5 * a_y[i] * prm.dt**2 >= prm.y_boundary
            continue
        for code, lateral in ([] if invalid[i] else [(PROCEED, a_y[i])]) + [(HESITATE, a_yh[i])]:
            verdict = check_candidate(
                ex[r], ey[r], evx[r], evy[r], a_x[r], np.array([lateral]), l1x[r], l1v[r], l1_decel[r], fx[r], fv[r],
                f_aggr[r], prm, completion=COMPLETION_RULES[cfg.completion],
                own=None if own is None else tuple(o[r] for o in own),
            )  # fmt: skip
            if verdict.ok[0]:
                out["behaviour"][i], out["a_x"][i], out["a_y"][i] = code, a_x[i], lateral
                out["completing"][i] = verdict.completing[0]
                out["plans"][i] = next(p for rows, p in verdict.plans if rows.size)
                break
        else:
            out["behaviour"][i] = ABORT
            age = np.array([max(s.t + delay - state.plan_t0[i], 0.0)])
            knots, _, vx, _, vy = plan_motion(state.plan.take(r), age, prm.dt)
            seg = np.flatnonzero(np.diff(knots[0]) > 0.0)[0]  # the segment acting at the period's start
            h = knots[0, seg + 1] - knots[0, seg]
            out["a_x"][i] = (vx[0, seg + 1] - vx[0, seg]) / h
            out["a_y"][i] = (vy[0, seg + 1] - vy[0, seg]) / h
    out.update(l1_decel=l1_decel, f_aggr=f_aggr, invalid=invalid, nominal=check_proposal("p", proposal, b, prm))
    return out


def _world(s, d, prm, rng, push_f):
    """The next situation: the ego executes the decision exactly (the abort rows their plan), everyone else holds
    its speed, except that some F accelerate (``push_f``) to make the monitor see something."""
    dt = prm.dt
    ex, evx = advance(s.ego_x, s.ego_vx, d.a_x, dt)
    ey, evy = s.ego_y + s.ego_vy * dt + 0.5 * d.a_y * dt * dt, s.ego_vy + d.a_y * dt
    rows, _, px, vx, py, vy = d.abort_motion()
    if rows.size:
        ex[rows], evx[rows], ey[rows], evy[rows] = px[:, -1], vx[:, -1], py[:, -1], vy[:, -1]
    fx, fv = advance(s.f_x, s.f_v, np.where(push_f, prm.a_x_a, 0.0), dt)
    rep = dict(t=s.t + dt, ego_x=ex, ego_y=ey, ego_vx=evx, ego_vy=evy, f_x=fx, f_v=fv,
               chain_x=s.chain_x + s.chain_v * dt)  # fmt: skip
    if s.own_x is not None:
        rep["own_x"] = s.own_x + s.own_v * dt
    return dataclasses.replace(s, **rep)


CONFIGS = {
    "default": ({}, "CV_all"),
    "cv_none": ({}, "CV_none"),
    "follow_truth": ({"assessment": "truth"}, "CV_follow"),
    "no_agg": ({}, "No_agg_assess"),
    "slow_paper_rule": ({"assessment": "slow", "completion": "paper_evasion", "assess_delay_s": 0.2}, "CV_none"),
    "monitor_off": ({"monitor": False}, "CV_all"),
    "monitor_off_own": ({"monitor": False}, "CV_all"),
    "own_lane": ({}, "CV_all"),
    "own_lane_off": ({"own_lane": False}, "CV_all"),
    "delay": ({"actuation_delay_s": 0.2}, "CV_all"),
    "delay_own": ({"actuation_delay_s": 0.1}, "CV_none"),
    "disabled": ({"enabled": False}, "CV_all"),
}


@pytest.mark.parametrize("name", list(CONFIGS))
def test_step_makes_the_documented_decision_row_by_row(name):
    """Random batches stepped for a few periods; every period's decision and new state are checked against
    :func:`_expected` from the state the shield held."""
    kw, variant = CONFIGS[name]
    cfg = ShieldConfig(**kw)
    prm = PRM
    rng = np.random.default_rng(sum(map(ord, name)))
    b = 36
    s = _situations(rng, b, own=name in ("own_lane", "own_lane_off", "delay_own", "monitor_off_own"), t=1.0)
    s = dataclasses.replace(s, f_aggressive_truth=rng.random(b) < 0.5)
    state = init(s, prm, cfg, variant)
    push_f = rng.random(b) < 0.3
    seen = set()
    for k in range(7):
        # Proposals: the expert's wish to move over, with some out-of-range, non-finite and braking ones.
        a_x = rng.choice([0.0, 1.0, prm.a_x_a, -3.0, 30.0, np.nan], b, p=[0.3, 0.2, 0.2, 0.1, 0.1, 0.1])
        a_y = rng.choice([prm.a_y_m, 0.5, 0.0, -prm.a_y_m, 5.0], b, p=[0.4, 0.2, 0.2, 0.1, 0.1])
        proposal = (a_x, a_y)
        new, d = step(state, s, proposal, prm, cfg, variant)
        want = _expected(state, s, proposal, prm, cfg, variant, d.breach.any)
        np.testing.assert_array_equal(d.behaviour, want["behaviour"])
        np.testing.assert_array_equal(d.l1_decel, want["l1_decel"])
        np.testing.assert_array_equal(d.f_aggressive, want["f_aggr"])
        np.testing.assert_array_equal(d.invalid, want["invalid"] & ~state.completed)
        np.testing.assert_array_equal(d.nominal_x, want["nominal"][0])
        np.testing.assert_array_equal(d.nominal_y, want["nominal"][1])
        np.testing.assert_allclose(d.a_x, want["a_x"], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(d.a_y, want["a_y"], rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(d.completing, want["completing"] & ~state.completed)
        replanned = np.isin(d.behaviour, [PROCEED, HESITATE]) & (cfg.enabled | state.completed)
        replanned &= ~state.completed
        if cfg.enabled:
            assert sorted(want["plans"]) == np.flatnonzero(replanned).tolist()
        for i, plan in want["plans"].items():
            _same_plan_row(d.plan, i, plan, 0)
        for i in np.flatnonzero(~replanned):
            _same_plan_row(d.plan, i, state.plan, i)
        t0 = np.where(replanned | (~cfg.enabled & ~state.completed), s.t + cfg.actuation_delay_s + prm.dt,
                      state.plan_t0)  # fmt: skip
        np.testing.assert_allclose(d.plan_t0, t0, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(new.plan_t0, d.plan_t0)
        assert new.plan is d.plan and new.t == pytest.approx(s.t + prm.dt)
        np.testing.assert_array_equal(new.completed, state.completed | d.completing)
        aggr = state.plan_f_aggr.copy()
        aggr[np.flatnonzero(replanned) if cfg.enabled else []] = d.f_aggressive[replanned] if cfg.enabled else []
        np.testing.assert_array_equal(new.plan_f_aggr, aggr)
        np.testing.assert_array_equal(new.last.active, ~state.completed)
        np.testing.assert_array_equal(new.last.plan_f_aggr, aggr)
        np.testing.assert_array_equal(new.last.plan_l1_decel, d.plan.l1_decel)
        np.testing.assert_array_equal(new.last.n_connected, s.n_connected)
        np.testing.assert_array_equal(new.last.bounds, chain_analysis(s, prm)[0])
        np.testing.assert_array_equal(new.last.f_x, s.f_x)
        np.testing.assert_array_equal(new.last.chain_x, s.chain_x)
        assert getattr(new.belief, "inner", new.belief).count.tolist() == [k + 1] * b
        # F is watched only where the held plan takes it for collaborative and the ego is ahead of it; its limit
        # is what a responsible follower of the ego may do, never below -a_x_d.
        watch = ~state.completed & ~aggr & (s.ego_x - s.f_x > 0.0)
        limit = np.maximum(responsible_bound(s.ego_x - s.f_x - prm.p_m, s.f_v, s.ego_vx, np.full(b, prm.a_x_d), prm),
                           -prm.a_x_d)  # fmt: skip
        np.testing.assert_allclose(new.last.f_limit, np.where(watch, limit, np.inf), rtol=1e-12, atol=1e-12)
        if cfg.actuation_delay_s:
            assert len(new.pending.commands) == len(state.pending.commands)
            dur, ax, ay = new.pending.commands[-1].piece(prm.dt)
            np.testing.assert_allclose(dur.sum(1), prm.dt, rtol=0, atol=1e-12)
            front = np.argmax(dur > 0.0, axis=1)
            np.testing.assert_allclose(ax[np.arange(b), front], d.a_x, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(ay[np.arange(b), front], d.a_y, rtol=1e-12, atol=1e-12)
            if len(state.pending.commands) > 1:  # the queue moved on by one (the compiled period rebuilds it)
                moved, was = new.pending.commands[0], state.pending.commands[1]
                for field in dataclasses.fields(was):
                    a, w = getattr(moved, field.name), getattr(was, field.name)
                    assert (a is None) == (w is None) and (w is None or np.array_equal(a, w)), field.name
            np.testing.assert_array_equal(new.pending.commands[-1].completing, d.completing)
        else:
            assert new.pending is None
        seen |= set(d.behaviour.tolist())
        state, s = new, _world(s, d, prm, rng, push_f)
    if cfg.enabled:
        assert {PROCEED, HESITATE, ABORT} <= seen, seen


def test_an_aborting_rows_command_is_the_held_plans_acceleration_at_the_periods_start():
    """Regression (found while testing the step): the reported ``a_x, a_y`` of an aborting row were 0 whenever a
    switch of the plan lay at or before the period's start (a zero-length first segment), e.g. a plan braking at
    ``a_x_d`` from its start. They are the plan's accelerations just after the period's start (finite difference of
    the plan's own velocity)."""
    rng = np.random.default_rng(1)
    b = 300
    s = _situations(rng, b)
    cfg = ShieldConfig()
    state = init(s, PRM, cfg)
    checked = 0
    for _ in range(4):
        new, d = step(state, s, (np.full(b, PRM.a_x_a), np.full(b, PRM.a_y_m)), PRM, cfg, "No_agg_assess")
        rows = np.flatnonzero(d.behaviour == ABORT)
        age = np.maximum(s.t - state.plan_t0[rows], 0.0)
        plan = state.plan.take(rows)
        eps = 1e-7
        _, _, vx0, vy0 = plan.state(age)
        _, _, vx1, vy1 = plan.state(age + eps)
        np.testing.assert_allclose(d.a_x[rows], (vx1 - vx0) / eps, rtol=0, atol=1e-5)
        np.testing.assert_allclose(d.a_y[rows], (vy1 - vy0) / eps, rtol=0, atol=1e-5)
        checked += (np.abs(d.a_x[rows]) > 1.0).sum()
        state, s = new, _world(s, d, PRM, rng, np.zeros(b, bool))
    assert checked > 50


def test_rows_of_other_rules_are_decided_by_their_rule_and_a_row_never_depends_on_the_others():
    """A batch mixing the paper's variants with the RSS baselines: each row decides as it would in a batch of its
    own variant alone, and an RSS row's decision is its registered rule's on the row's inputs (rules.py)."""
    rng = np.random.default_rng(21)
    b = 48
    names = np.array(["CV_all", "RSS", "CV_none", "RSS_V2X", "No_agg_assess", "RSS_matched", "RSS_V2X_matched",
                      "CV_follow"] * (b // 8))  # fmt: skip
    s = _situations(rng, b, t=0.5)
    cfg = ShieldConfig()
    state = init(s, PRM, cfg, names)
    for _ in range(4):
        a_x = rng.choice([0.0, 1.0, PRM.a_x_a, -3.0, np.nan], b)
        a_y = rng.choice([PRM.a_y_m, 0.5, 0.0, -PRM.a_y_m], b)
        new, d = step(state, s, (a_x, a_y), PRM, cfg, names)
        for name in np.unique(names):
            rows = np.flatnonzero(names == name)
            sub_s = _take_rows(s, rows)
            sub_state = _take_state(state, rows)
            _, alone = step(sub_state, sub_s, (a_x[rows], a_y[rows]), PRM, cfg, name)
            for field in ("behaviour", "a_x", "a_y", "completing", "invalid", "plan_t0", "l1_decel", "f_aggressive"):
                np.testing.assert_array_equal(getattr(d, field)[rows], getattr(alone, field), err_msg=f"{name} {field}")
            rule = VARIANTS[name].rule
            if rule == "paper":
                continue
            bounds, unsafe = chain_analysis(sub_s, PRM)
            chained = VARIANTS[name].uses_chain & ~unsafe
            l1_decel = np.where(chained & ~d.breach.any[rows], bounds[:, 0], PRM.a_x_d)
            px, py, invalid = check_proposal("p", (a_x[rows], a_y[rows]), rows.size, PRM)
            px, py = np.clip(px, -PRM.a_x_d, PRM.a_x_a), np.clip(py, -PRM.a_y_m, PRM.a_y_m)
            inputs = RuleInputs(
                ego_x=sub_s.ego_x, ego_y=sub_s.ego_y, ego_vx=sub_s.ego_vx, ego_vy=sub_s.ego_vy, chain_x=sub_s.chain_x,
                chain_v=sub_s.chain_v, f_x=sub_s.f_x, f_v=sub_s.f_v, a_x=px, a_y=py,
                a_y_hesitate=np.clip(-sub_s.ego_vy / PRM.dt, -PRM.a_y_m, PRM.a_y_m), invalid=invalid,
                l1_decel=l1_decel, uses_chain=chained, completed=sub_state.completed, chain_bounds=bounds,
                n_connected=sub_s.n_connected,
                a_y_keep=np.clip(0.8 * (PRM.lane_width - sub_s.ego_y) - 1.6 * sub_s.ego_vy, -PRM.a_y_m, PRM.a_y_m),
            )  # fmt: skip
            behaviour, rx, ry, completing = DECISION_RULES[rule].decide(inputs, PRM)
            np.testing.assert_array_equal(d.behaviour[rows], behaviour)
            np.testing.assert_array_equal(d.a_x[rows], rx)
            np.testing.assert_array_equal(d.a_y[rows], ry)
            np.testing.assert_array_equal(d.completing[rows], completing & ~sub_state.completed)
            np.testing.assert_array_equal(new.completed[rows], sub_state.completed | completing)
            # The paper's rule never decides these rows: no plan is checked or accepted for them.
            for i in rows:
                _same_plan_row(d.plan, i, state.plan, i)
            np.testing.assert_array_equal(new.plan_f_aggr[rows], state.plan_f_aggr[rows])
        state, s = new, _world(s, d, PRM, rng, np.zeros(b, bool))
    assert new.completed.any()


def _take_rows(s, rows):
    out = {}
    for f in dataclasses.fields(s):
        v = getattr(s, f.name)
        out[f.name] = v[rows] if isinstance(v, np.ndarray) else v
    return Situation(**out)


def _take_state(state, rows):
    def sub(obj):
        if obj is None or isinstance(obj, (int, float)):
            return obj
        if isinstance(obj, np.ndarray):
            return obj[rows]
        if isinstance(obj, tuple):
            return tuple(sub(o) for o in obj)
        if hasattr(obj, "take") and hasattr(obj, "feasible"):
            return obj.take(rows)
        return dataclasses.replace(obj, **{f.name: sub(getattr(obj, f.name)) for f in dataclasses.fields(obj)})

    return sub(state)


@pytest.mark.parametrize(
    ("own", "kw"),
    [(False, {}), (True, {}), (False, {"actuation_delay_s": 0.2}), (True, {"actuation_delay_s": 0.1}),
     (True, {"own_lane": False}), (True, {"sensing": False})],
)  # fmt: skip
def test_init_holds_the_most_conservative_plan_from_where_the_commands_in_flight_leave_the_ego(own, kw):
    """The plan held at the start (core.init's docstring): L1 braking at ``a_x_d``, F aggressive, from the states at
    the end of the actuation delay (the ego cruising meanwhile, L1 and F carried along those worst cases), replanned
    with the own-lane leader where there is one, and refused where the cruise itself breaks a gap in the delay."""
    rng = np.random.default_rng(30 + len(kw) + own)
    b = 60
    cfg = ShieldConfig(**kw)
    exact = _situations(rng, b, own=own, t=2.0)
    s_in = SensingBounds().apply(exact)
    state = init(s_in, PRM, cfg, "CV_none")
    s = worst_corners(s_in)[0] if cfg.sensing else exact
    delay = cfg.actuation_delay_s
    ex, ey = s.ego_x + s.ego_vx * delay, s.ego_y + s.ego_vy * delay
    l1x, l1v = advance(s.chain_x[:, 0], s.chain_v[:, 0], np.full(b, -PRM.a_x_d), delay)
    fx, fv = advance(s.f_x, s.f_v, np.full(b, PRM.a_x_a), delay)
    plan = plan_evasion(ex, ey, s.ego_vx, s.ego_vy, l1x, l1v, PRM.a_x_d, fx, fv, True, PRM)
    own_now = None
    if own and cfg.own_lane:
        o_decel = own_lane_decel(s, PRM, np.zeros(b, bool), np.ones(b, bool))
        assert (o_decel == PRM.a_x_d).all()
        own_now = (s.own_x[:, 0], s.own_v[:, 0], o_decel)
        ox, ov = advance(own_now[0], own_now[1], -o_decel, delay)
        args = (ex, ey, s.ego_vx, s.ego_vy, l1x, l1v, np.full(b, PRM.a_x_d), fx, fv, np.ones(b, bool))
        plan = own_plan(plan, args, (ox, ov, o_decel), PRM)
    if delay:
        plan = in_flight_checked(plan, s, own_now, delay, PRM)
        assert len(state.pending.commands) == round(delay / PRM.dt)
        for dur, ax, ay in (command.piece(PRM.dt) for command in state.pending.commands):
            assert (dur == PRM.dt).all() and not ax.any() and not ay.any()
    else:
        assert state.pending is None
    for i in range(b):
        _same_plan_row(state.plan, i, plan, i)
    assert 0 < state.plan.feasible.sum() < b
    np.testing.assert_allclose(state.plan_t0, 2.0 + delay, rtol=0, atol=1e-12)
    assert state.plan_f_aggr.all() and state.plan_f_aggr.shape == (b,)
    assert state.t == 2.0 and state.last is None and not state.completed.any() and state.completed.shape == (b,)
    assert not state.breach.flags.any() and state.breach.flags.shape == (b, len(BREACH_KINDS))
    assert state.belief.history.shape == (b, cfg.assess_window) and state.belief.aggressive.all()


def test_a_bad_proposal_names_the_planner_and_a_given_chain_analysis_is_used():
    rng = np.random.default_rng(40)
    s = _situations(rng, 4)
    state = init(s, PRM, ShieldConfig())
    with pytest.raises(TypeError, match=r"^the nominal planner must return a pair"):
        step(state, s, np.zeros((2, 4)), PRM)
    with pytest.raises(ValueError, match=r"nominal planner expert returned a_x of shape \(3,\)"):
        step(state, s, (np.zeros(3), np.zeros(4)), PRM, planner_name="expert")
    # chain: the caller's analysis of this very situation is taken as given (here: a deliberately different one).
    bounds, unsafe = chain_analysis(s, PRM)
    other = np.full_like(bounds, 0.25)
    _, d = step(state, s, (np.zeros(4), np.zeros(4)), PRM, chain=(other, np.zeros(4, bool)))
    _, plain = step(state, s, (np.zeros(4), np.zeros(4)), PRM)
    np.testing.assert_array_equal(d.l1_decel, 0.25)
    np.testing.assert_array_equal(plain.l1_decel, np.where(unsafe, PRM.a_x_d, bounds[:, 0]))


def test_chain_analysis_of_l1_alone_is_the_mechanical_worst_case():
    rng = np.random.default_rng(41)
    s = _situations(rng, 5, m=1)
    bounds, unsafe = chain_analysis(s, PRM)
    assert bounds.shape == (5, 1) and (bounds == PRM.a_x_d).all()
    assert unsafe.shape == (5,) and unsafe.dtype == bool and not unsafe.any()
    state = init(s, PRM, ShieldConfig(), "CV_all")
    _, d = step(state, s, (np.zeros(5), np.zeros(5)), PRM, ShieldConfig(), "CV_all")
    assert (d.l1_decel == PRM.a_x_d).all()


def test_a_disabled_shield_passes_the_proposal_and_counts_a_step_ending_on_the_boundary_as_completing():
    """``enabled=False``: the (clipped) proposal goes through unfiltered; a step whose end is exactly on the lane
    boundary (``y = w_l / 2``, as check_candidate's ``ey >= level``) completes, one ending a hair short does not."""
    b = 3
    y0 = np.array([PRM.y_boundary, np.nextafter(PRM.y_boundary, 0.0), 0.5])
    ego = (np.zeros(b), y0, np.full(b, 25.0), np.zeros(b))
    s = Situation.from_arrays(
        t=0.0, ego=ego, follower=(-20.0, 25.0), leaders=([20.0], [25.0]), n_connected=0, params=PRM
    )
    cfg = ShieldConfig(enabled=False)
    _, d = step(init(s, PRM, cfg), s, (np.array([9.0, 1.0, 1.0]), np.zeros(b)), PRM, cfg)
    assert d.completing.tolist() == [True, False, False]
    assert (d.behaviour == PROCEED).all() and d.a_x.tolist() == [0.0, 1.0, 1.0] and d.invalid.tolist()[0]


def test_only_an_f_strictly_behind_the_ego_is_watched():
    """The monitor's follower limit is set only where the held plan takes F for collaborative and the ego is ahead
    of F (``x_ego − x_F > 0``): F half a metre behind is watched, F level with the ego or ahead of it is not."""
    b = 4
    ego = (np.full(b, 100.0), np.zeros(b), np.full(b, 25.0), np.zeros(b))
    f_x = np.array([99.5, 100.0, 101.0, 80.0])
    s = Situation.from_arrays(t=0.0, ego=ego, follower=(f_x, np.full(b, 25.0)), leaders=([150.0], [25.0]),
                              n_connected=0, f_connected=True, f_collaborative=True, params=PRM)  # fmt: skip
    state = dataclasses.replace(init(s, PRM, ShieldConfig()), plan_f_aggr=np.zeros(b, bool))
    new, _ = step(state, s, (np.zeros(b), np.zeros(b)), PRM, ShieldConfig(), "CV_all")
    assert np.isfinite(new.last.f_limit).tolist() == [True, False, False, True]


def test_init_refuses_the_plan_where_the_commands_in_flight_break_a_gap_inside_the_delay():
    """Actuation delay 0.2 s: an ego just out of its lane, drifting back in within the delay, 5 m behind L1 (inside
    p_m) — from the end of the delay there is nothing to evade, but the cruise acting meanwhile is in the conflict
    zone with L1 too close: no verified plan. The same ego 12 m behind L1 holds one."""
    ego = (np.zeros(2), np.full(2, PRM.y_safe + 0.05), np.full(2, 20.0), np.full(2, -1.0))
    s = Situation.from_arrays(t=0.0, ego=ego, follower=(-30.0, 20.0), leaders=(np.array([[5.0], [12.0]]), [[20.0]] * 2),
                              n_connected=0, params=PRM)  # fmt: skip
    state = init(s, PRM, ShieldConfig(actuation_delay_s=0.2))
    assert state.plan.feasible.tolist() == [False, True]


def test_init_checks_the_own_lane_leader_during_the_delay_too():
    """Delay 0.2 s, the ego in its own lane 6.9 m behind a faster L0 (inside p_m now, outside it once the delay has
    passed): the cruise acting meanwhile breaks the margin to L0, so no plan is verified; 7.5 m behind, one is."""
    ego = (np.zeros(2), np.zeros(2), np.full(2, 20.0), np.zeros(2))
    s = Situation.from_arrays(t=0.0, ego=ego, follower=(-60.0, 20.0), leaders=([100.0], [20.0]), n_connected=0,
                              own_leaders=(np.array([[6.9], [7.5]]), np.full((2, 1), 30.0)), params=PRM)  # fmt: skip
    state = init(s, PRM, ShieldConfig(actuation_delay_s=0.2))
    assert state.plan.feasible.tolist() == [False, True]


def test_a_proposal_inside_the_tolerance_is_clipped_to_the_mechanical_limits():
    """A proposal up to 1e-9 m/s² beyond a limit is valid (proposals.py) and executed at the limit itself (the
    shield's 'clipped, checked' proposal): exactly -a_x_d, a_x_a, ±a_y_m."""
    b = 4
    ego = (np.zeros(b), np.zeros(b), np.full(b, 25.0), np.zeros(b))
    s = _open_road(ego)
    a_x = np.array([-PRM.a_x_d - 1e-9, PRM.a_x_a + 1e-9, 0.0, 0.0])
    a_y = np.array([0.0, 0.0, PRM.a_y_m + 1e-9, -(PRM.a_y_m + 1e-9)])
    for cfg in (ShieldConfig(enabled=False), ShieldConfig()):
        _, d = step(init(s, PRM, cfg), s, (a_x, a_y), PRM, cfg)
        assert not d.invalid.any() and (d.behaviour == PROCEED).all()
        assert d.a_x.tolist() == [-PRM.a_x_d, PRM.a_x_a, 0.0, 0.0]
        assert d.a_y.tolist() == [0.0, 0.0, PRM.a_y_m, -PRM.a_y_m]
        np.testing.assert_array_equal(d.nominal_x, a_x)


def test_a_disabled_shield_completes_where_the_steps_exact_lateral_end_reaches_the_boundary():
    """``enabled=False``: a step completes where ``y + v_y dt + ½ a_y dt²`` (constant ``a_y`` over the period)
    reaches the boundary. With ``a_y = 1`` and ``v_y = 0`` the step moves 0.005 m: from 0.004 m short it arrives, from
    0.01 m short it does not; with ``v_y = 0.45``, ``a_y = 0`` it moves 0.045 m: 0.05 m short stays short."""
    short = np.array([0.004, 0.01, 0.05])
    b = short.size
    ego = (np.zeros(b), PRM.y_boundary - short, np.full(b, 25.0), np.array([0.0, 0.0, 0.45]))
    s = _open_road(ego)
    cfg = ShieldConfig(enabled=False)
    a_y = np.array([1.0, 1.0, 0.0])
    _, d = step(init(s, PRM, cfg), s, (np.zeros(b), a_y), PRM, cfg)
    assert PRM.dt == 0.1 and PRM.a_y_m >= 1.0
    assert d.completing.tolist() == [True, False, False]
    assert (d.behaviour == PROCEED).all()


def test_where_every_proposal_is_invalid_no_row_proceeds():
    """Every row's proposal invalid (NaN, out of range): none is executed — each row is checked at hesitation and
    hesitates or aborts, in a batch where no row could proceed at all."""
    b = 3
    ego = (np.zeros(b), np.array([0.0, 1.0, 2.0]), np.full(b, 25.0), np.zeros(b))
    s = _open_road(ego)
    bad = (np.array([np.nan, 50.0, 0.0]), np.array([0.0, 0.0, np.inf]))
    _, d = step(init(s, PRM, ShieldConfig()), s, bad, PRM)
    assert d.invalid.all()
    assert np.isin(d.behaviour, [HESITATE, ABORT]).all()
    assert (d.behaviour == HESITATE).all()  # far from L1 and F: hesitating is safe everywhere


def test_another_rules_rows_see_the_chain_only_where_their_variant_uses_it_and_no_link_is_unsafe(monkeypatch):
    """``RuleInputs.uses_chain`` (rules.py): the variant uses the connected chain *and* the chain analysis found no
    unsafe link on the row — recorded from what the RSS rule is handed, on a batch with unsafe chains on some rows."""
    rng = np.random.default_rng(44)
    b = 64
    s = _situations(rng, b)
    _, unsafe = chain_analysis(s, PRM)
    names = np.array(["RSS", "RSS_V2X"] * (b // 2))
    uses = np.array([VARIANTS[n].uses_chain for n in names])
    assert (uses & unsafe).any() and (uses & ~unsafe).any() and (~uses & ~unsafe).any()
    seen = []

    class Recorder:
        def __init__(self, inner):
            self.inner = inner

        def decide(self, inputs, params):
            seen.append(inputs)
            return self.inner.decide(inputs, params)

    monkeypatch.setitem(DECISION_RULES, "rss", Recorder(DECISION_RULES["rss"]))
    step(init(s, PRM, ShieldConfig(), names), s, (np.zeros(b), np.zeros(b)), PRM, ShieldConfig(), names)
    assert len(seen) == 1
    np.testing.assert_array_equal(seen[0].uses_chain, uses & ~unsafe)


def test_after_completion_the_lateral_command_is_clipped_to_a_y_m_both_ways():
    """A completed row keeps its lane with ``a_y = 0.8 (w_l − y) − 1.6 v_y`` clipped to ``±a_y_m``: far above the
    target lane's centre and drifting up (``y = 4.5``, ``v_y = 1``: −2.4) it is ``−a_y_m``; far below and drifting
    down (``y = 2``, ``v_y = −1``: +2.8) it is ``+a_y_m``; near the centre (``y = 3.4``, ``v_y = 0``: 0.08) as is."""
    y, vy = np.array([4.5, 2.0, 3.4]), np.array([1.0, -1.0, 0.0])
    b = y.size
    ego = (np.zeros(b), y, np.full(b, 25.0), vy)
    s = _open_road(ego)
    state = dataclasses.replace(init(s, PRM, ShieldConfig()), completed=np.ones(b, bool))
    _, d = step(state, s, (np.zeros(b), np.zeros(b)), PRM)
    assert PRM.lane_width == 3.5
    assert (d.behaviour == COMPLETED).all()
    np.testing.assert_allclose(d.a_y, [-PRM.a_y_m, PRM.a_y_m, 0.8 * 0.1], rtol=0, atol=1e-12)

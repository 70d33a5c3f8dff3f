"""The envs in the realistic world on the compiled period (``envs/_fast.py``) against the NumPy env period by period
(``SAFELANE_NO_FUSED=1``: :class:`~safelane.sim.step.ClosedLoop`, the reference): the own lane's leader ``L0``,
sensing error and the actuation delay — the world's side, and the shield's (its sensing box and monitor's anchor,
its delay where it is the world's). Observations, rewards, flags and every info key bit for bit over many steps
with resets, for the single env and for the vector env's sub-envs (each against the NumPy single env on its seed,
every episode: the compiled rows keep their own clocks, and the spliced rows carry their own ``L0`` profile, world
key and sensing bounds), an own lane of three (``L0`` connected) among them; and the settings matter there:
collisions and costs with ``L0``, a delayed command, a completion the world reaches periods after the shield's flag,
the shield's box and delay."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("gymnasium", reason="the Gymnasium environments need the gym extra: pip install -e '.[gym]'")
pytest.importorskip("numba", reason="the compiled period needs the fast extra")

from safelane.envs import LaneChangeEnv, LaneChangeVectorEnv
from safelane.envs.core import BEHAVIOUR_NAMES
from safelane.params import Params
from safelane.sim._stepper import Stepper
from safelane.sim.step import ClosedLoop
from test_env_compiled import KW, actions, assert_same

CODES = {name: code for code, name in BEHAVIOUR_NAMES.items()}
#: ``L0`` near and braking early: the ego meets it in most episodes.
NEAR_L0 = dict(own_lane=True, l0_gap_min_m=6.0, l0_gap_max_m=30.0, l0_brake_window_s=2.0)
#: The world's sensing error and actuation delay, the shield's sides off.
SENSING = dict(sensing_error=True, sensing_edge_share=0.2, shield_sensing=False)
DELAY = dict(actuation_delay_s=0.2, shield_delay=False)
#: The shield's sides on: its sensing box (wide bounds: its corners and anchor matter) and its delay (the world's).
WIDE = dict(sensing_error=True, sense_sensed_pos_m=2.0, sense_sensed_speed_mps=1.0, sense_connected_pos_m=1.0,
            sense_connected_speed_mps=0.5)  # fmt: skip
SHIELD_SIDES = dict(NEAR_L0, sensing_error=True, sensing_edge_share=0.2, actuation_delay_s=0.2)
CASES = {
    "L0, the shield blind to it": dict(NEAR_L0, shield_own_lane=False),
    "L0, sensing error, delay": dict(NEAR_L0, **SENSING, **DELAY),
    "delay alone": dict(actuation_delay_s=0.3, shield_delay=False),
    "the shield's sensing and delay on, with L0, sensing error, delay": SHIELD_SIDES,
    "wide sensing error, the shield's sensing on": WIDE,
    "delay alone, the shield's delay on": dict(actuation_delay_s=0.3),
    "a connected own lane (L0 and two vehicles ahead of it), the shield's sensing and delay on": dict(
        SHIELD_SIDES, own_lane_connected=2),
}
#: Each case's seed.
SEEDS = (6, 2, 13, 6, 2, 13, 6)


def lane_changes(steps: int, rows: int, seed: int) -> np.ndarray:
    """:func:`~test_env_compiled.actions` (random, wider than the box, invalid ones among them) leaning toward the
    target lane (``a_y`` uniform in ``[-0.5, 1.5]·a_y_m``): lane changes complete, against ``L0`` too."""
    a = actions(steps, rows, seed)
    a[..., 1] = np.random.default_rng(seed + 1).uniform(-0.5, 1.5, a.shape[:-1]) * Params().a_y_m
    return a


def run_single(seed: int, steps: int, **kw):
    """The single env's outputs (the first observation, then ``(obs, reward, terminated, truncated, info)`` per step
    and each reset's observation) and, on the compiled period, what its state says after each step: ``L0``'s
    collision and violation flags, the world's completion and the shield's."""
    env = LaneChangeEnv(**kw)
    obs, _ = env.reset(seed=seed)
    out, flags = [obs], []
    for a in lane_changes(steps, 1, seed)[:, 0]:
        obs, reward, terminated, truncated, info = env.step(a)
        out.append((obs, reward, terminated, truncated, info))
        if isinstance(env.task.loop, Stepper):
            rows = env.task.state.rows
            flags.append((rows.rb[0, 5], rows.rb[0, 6], rows.rb[0, 7], rows.sk[0, 3]))
        if terminated or truncated:
            obs, _ = env.reset()
            out.append(obs)
    return out, type(env.task.loop), np.array(flags, bool).reshape(-1, 4)


@pytest.mark.parametrize(("case", "seed"), [(case, seed) for case, seed in zip(CASES, SEEDS, strict=True)])
def test_single_env_in_the_realistic_world_is_the_numpy_env_bit_for_bit(case, seed, monkeypatch):
    kw = dict(KW, sim_config=CASES[case])
    compiled, kind, flags = run_single(seed, 400, **kw)
    assert kind is Stepper
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    reference, kind, _ = run_single(seed, 400, **kw)
    assert kind is ClosedLoop
    assert_same(compiled, reference)
    steps = [step for step in compiled if isinstance(step, tuple)]
    assert sum(isinstance(step, np.ndarray) for step in compiled) >= 5  # many episodes
    l0_collided, l0_violated, world_done, shield_done = flags.T
    if case.startswith("L0"):  # collisions (the shield blind to L0) or p_m violations with L0 cost
        ended = np.array([s[2] or s[3] for s in steps])
        on = {name: np.flatnonzero(flag & ~np.r_[False, flag[:-1] & ~ended[:-1]])  # the flag turned on this period
              for name, flag in (("collided", l0_collided), ("violated", l0_violated))}  # fmt: skip
        assert on["violated"].size >= 2, "L0 was not met"
        assert any(steps[i][4]["cost"] == 1.0 for i in on["violated"])
        if "blind" in case:  # collisions with L0 end episodes as crashes
            assert on["collided"].size >= 2
            assert all(steps[i][4]["crashed"] and steps[i][2] for i in on["collided"])
    if "delay" in case:  # the world completes the lane change after the shield issued its completing command
        assert (shield_done & ~world_done).any()
        start = [i for i, s in enumerate(steps) if i == 0 or steps[i - 1][2] or steps[i - 1][3]]
        # an episode's first periods execute the idle commands in flight (cruise), whatever the agent proposes
        assert all(np.array_equal(steps[i][4]["executed_action"], [0.0, 0.0]) for i in start)
        assert any(np.isfinite(steps[i][4]["nominal_action"]).all() and steps[i][4]["nominal_action"].any()
                   for i in start)  # fmt: skip


@pytest.mark.parametrize("side", ["sensing", "delay"])
def test_the_shields_sides_change_the_episodes(side):
    """The shield's sensing box and its delay reach the episodes: without either (the world as it is), they differ."""
    cfg = dict(SHIELD_SIDES, shield_sensing=side != "sensing", shield_delay=side != "delay")
    on, kind, _ = run_single(6, 200, **dict(KW, sim_config=SHIELD_SIDES))
    off, kind_off, _ = run_single(6, 200, **dict(KW, sim_config=cfg))
    assert kind is Stepper and kind_off is Stepper
    with pytest.raises(AssertionError):
        assert_same(on, off)


def test_sensing_error_changes_the_episodes():
    """The world's sensing error reaches the shield's decisions (the shield takes the measurements as exact)."""
    kw = dict(KW, sim_config=dict(NEAR_L0, **DELAY))
    plain, _, _ = run_single(7, 200, **kw)
    sensed, kind, _ = run_single(7, 200, **dict(kw, sim_config=dict(NEAR_L0, **DELAY, **SENSING)))
    assert kind is Stepper
    with pytest.raises(AssertionError):
        assert_same(plain, sensed)


@pytest.mark.parametrize(("n", "steps", "seed", "world"), [(12, 150, 3, "world"), (12, 150, 5, "shield sides"),
                                                           (12, 150, 4, "chain")])
def test_vector_env_sub_envs_are_numpy_single_envs_in_the_realistic_world(n, steps, seed, world, monkeypatch):
    """Every episode of each compiled sub-env, resets spliced into the running batch, is the NumPy single env's on its
    seed bit for bit: observation, reward, flags and every info key; the world's side alone, with the shield's
    sensing box and delay (each row's anchor and commands in flight its own across the splices), and with an own lane
    of three (``L0`` connected, each row's chain its own across the splices)."""
    cfg = {"world": dict(NEAR_L0, **SENSING, **DELAY), "shield sides": SHIELD_SIDES,
           "chain": dict(SHIELD_SIDES, own_lane_connected=2)}[world]  # fmt: skip
    acts = lane_changes(steps, n, seed)
    venv = LaneChangeVectorEnv(n, **dict(KW, sim_config=cfg))
    vobs, _ = venv.reset(seed=seed)
    assert type(venv.task.loop) is Stepper
    rows, l0_events = [[vobs[i]] for i in range(n)], 0
    for t in range(steps):
        vobs, reward, terminated, truncated, info = venv.step(acts[t])
        l0_events += int(venv.task.state.rows.rb[:, 6].sum())
        for i in range(n):
            done = terminated[i] or truncated[i]
            rows[i].append(((info["final_obs"][i] if done else vobs[i]), reward[i], terminated[i], truncated[i],
                            {key: info[key][i] for key in info if not key.startswith(("_", "final"))}))  # fmt: skip
            if done:
                rows[i].append(vobs[i])
    assert venv.task.loop.spliced
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    resets = 0
    for i in range(n):
        env = LaneChangeEnv(**dict(KW, sim_config=cfg))
        obs, _ = env.reset(seed=seed + i)
        assert type(env.task.loop) is ClosedLoop
        single = [obs]
        for t in range(steps):
            obs, reward, terminated, truncated, info = env.step(acts[t, i])
            info = dict(info, behaviour_code=CODES[info["behaviour"]])
            single.append((obs, reward, terminated, truncated, info))
            if terminated or truncated:
                obs, _ = env.reset()
                single.append(obs)
                resets += 1
        assert_same(rows[i], single)
    assert resets >= n  # later episodes (spliced rows) are compared too
    assert l0_events  # L0 was met


@pytest.mark.parametrize("cfg", [NEAR_L0, DELAY, dict(actuation_delay_s=0.1), dict(actuation_delay_s=0.2,
                                                                                    shield={"actuation_delay_s": 0.1})])
def test_vector_env_refuses_l0_and_the_delay_period_by_period(cfg, monkeypatch):
    """Period by period the sub-envs share one clock and restarted rows are overwritten in the state: L0's braking
    instant and the commands in flight would be another episode's. The vector env refuses them there, naming why
    (``SAFELANE_NO_FUSED=1``; the shield's delay where it is the world's — the default — runs compiled, another one
    has no compiled step at all)."""
    if cfg.get("shield"):  # a shield's delay other than the world's: no compiled step at all
        with pytest.raises(ValueError, match=r"shield\.actuation_delay_s=0\.1"):
            LaneChangeVectorEnv(4, sim_config=cfg)
        return
    LaneChangeVectorEnv(4, sim_config=cfg)
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    with pytest.raises(ValueError, match=r"compiled period only.*SAFELANE_NO_FUSED=1"):
        LaneChangeVectorEnv(4, sim_config=cfg)
    LaneChangeVectorEnv(4, sim_config=SENSING)  # (sensing error: the draws keyed by the shared clock's step)


def test_a_part_with_another_l0_profile_length_is_not_spliced():
    """The spliced rows' ``L0`` profiles, world keys and sensing bounds are theirs (the vector test above); a part
    whose ``L0`` profile has another number of knots is refused, naming it."""
    from dataclasses import replace

    venv = LaneChangeVectorEnv(4, **dict(KW, sim_config=dict(NEAR_L0, **SENSING)))
    venv.reset(seed=1)
    task = venv.task
    fresh = task.sampler.draw_many([np.random.default_rng(9)])
    knots = np.array([[0.0, 1.0, 2.0]])
    fresh = replace(fresh, l0_x=fresh.ego_x + 20.0, l0_v=fresh.ego_vx, l0_profile_t=knots, l0_profile_a=-knots)
    part = Stepper(ClosedLoop(fresh, task.seed, task.params, task.config, task.planner))
    with pytest.raises(ValueError, match="L0's profiles"):
        task.loop.splice(np.array([0]), part)

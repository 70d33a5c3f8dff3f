"""The envs on the compiled period (``sim/_stepper.Stepper``, ``sim/_fast_loop.step_kernel``) against the same envs
period by period in NumPy (``SAFELANE_NO_FUSED=1``: :class:`~safelane.sim.step.ClosedLoop`, the reference): the same
observations, rewards, flags and info, bit for bit, over several episodes with resets, invalid actions, hesitations
and aborts; the vector env's sub-envs the single env's exactly (each row keeps its own clock); the dispatch."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("gymnasium", reason="the Gymnasium environments need the gym extra: pip install -e '.[gym]'")
pytest.importorskip("numba", reason="the compiled period needs the fast extra")

from safelane.envs import LaneChangeEnv, LaneChangeVectorEnv
from safelane.params import Params
from safelane.sim._stepper import Stepper
from safelane.sim.step import ClosedLoop

KW = dict(n_leaders=(0, 1, 3), decel=(2.0, 8.0), reward={"time": 0.01, "intervention": 0.1, "cost": 1.0})


def actions(steps: int, rows: int, seed: int) -> np.ndarray:
    """Random actions, wider than the box (the env clips), every 17th row-period a NaN proposal (invalid)."""
    prm = Params()
    rng = np.random.default_rng(seed)
    a = np.stack([rng.uniform(-1.5 * prm.a_x_d, 1.5 * prm.a_x_a, (steps, rows)),
                  rng.uniform(-1.5 * prm.a_y_m, 1.5 * prm.a_y_m, (steps, rows))], -1)  # fmt: skip
    a.reshape(-1, 2)[::17, 0] = np.nan
    return a


def run_single(seed: int, steps: int, **kw) -> tuple[list, type]:
    env = LaneChangeEnv(**kw)
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for a in actions(steps, 1, seed)[:, 0]:
        obs, reward, terminated, truncated, info = env.step(a)
        out.append((obs, reward, terminated, truncated, info))
        if terminated or truncated:
            obs, _ = env.reset()
            out.append(obs)
    return out, type(env.task.loop)


def assert_same(a, b):
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        if isinstance(x, np.ndarray):
            np.testing.assert_array_equal(x, y)
            continue
        np.testing.assert_array_equal(x[0], y[0])
        assert x[1:4] == y[1:4]
        assert x[4].keys() == y[4].keys()
        for key in x[4]:
            np.testing.assert_array_equal(x[4][key], y[4][key], err_msg=key)


PAPER_SETTINGS = {"leader_rule": "reactive", "assessment": "slow", "assess_delay_s": 3.0, "assess_miss": 0.231,
                  "completion": "paper_evasion", "monitor": False}  # (the paper preset's settings)


@pytest.mark.parametrize(("seed", "settings", "variant"), [(3, {}, "CV_all"), (12, {}, "CV_all"),
                                                        (5, PAPER_SETTINGS, "CV_all"), (8, {}, "RSS_V2X_matched"),
                                                        (9, {"follower_ignores_ego": True}, "RSS")])  # fmt: skip
def test_single_env_compiled_is_the_numpy_env_bit_for_bit(seed, settings, variant, monkeypatch):
    kw = dict(KW, sim_config=settings, variant=variant)
    compiled, kind = run_single(seed, 400, **kw)
    assert kind is Stepper
    monkeypatch.setenv("SAFELANE_NO_FUSED", "1")
    reference, kind = run_single(seed, 400, **kw)
    assert kind is ClosedLoop
    assert_same(compiled, reference)
    behaviours = {step[4]["behaviour"] for step in compiled if isinstance(step, tuple)}
    assert {"proceed", "hesitate"} <= behaviours  # the shield acted (aborts too for these seeds, not required)
    assert sum(isinstance(step, np.ndarray) for step in compiled) >= 4  # several episodes


@pytest.mark.parametrize(("n", "steps", "seed"), [(6, 150, 5), (24, 150, 17), (8, 320, 3)])
def test_vector_env_sub_envs_are_single_envs_exactly(n, steps, seed):
    """Each sub-env keeps its own clock in the compiled loop: every episode, not only the first, is the single env's
    bit for bit (the NumPy vector env shares one clock: later episodes agree to its rounding, test_envs.py); the
    restarted rows are spliced into the running batch (Stepper.splice), several in one step in the larger case, from
    the episodes the reserve prepared ahead (envs/reserve.py: prepared again as sub-envs run out, the same scenarios);
    the task's batch holds each sub-env's running scenario."""
    acts = actions(steps, n, seed)
    venv = LaneChangeVectorEnv(n, **KW)
    assert type(venv.task.loop) is not ClosedLoop
    vobs, _ = venv.reset(seed=seed)
    assert type(venv.task.loop) is Stepper
    rows = [[vobs[i]] for i in range(n)]
    for t in range(steps):
        vobs, reward, terminated, truncated, info = venv.step(acts[t])
        for i in range(n):
            done = terminated[i] or truncated[i]
            rows[i].append(((info["final_obs"][i] if done else vobs[i]), reward[i], terminated[i], truncated[i],
                            info["behaviour"][i]))  # fmt: skip
            if done:
                rows[i].append(vobs[i])
    resets = 0
    for i in range(n):
        env = LaneChangeEnv(**KW)
        obs, _ = env.reset(seed=seed + i)
        single = [obs]
        for t in range(steps):
            obs, reward, terminated, truncated, info = env.step(acts[t, i])
            single.append((obs, reward, terminated, truncated, info["behaviour"]))
            if terminated or truncated:
                obs, _ = env.reset()
                single.append(obs)
                resets += 1
        assert len(single) == len(rows[i])
        for field in ("scenario_id", "decel_last", "x", "n_connected"):
            np.testing.assert_array_equal(getattr(venv.task.batch, field)[i], getattr(env.task.batch, field)[0])
        for x, y in zip(rows[i], single, strict=True):
            if isinstance(y, np.ndarray):
                np.testing.assert_array_equal(x, y)
            else:
                np.testing.assert_array_equal(x[0], y[0])
                assert x[1:] == y[1:]
    assert resets >= n  # later episodes are compared too
    # over 300 steps (3 horizons) every sub-env runs out of prepared episodes: the reserve is prepared again
    assert venv.task._reserve.preparations >= (2 if steps > 300 else 1)


@pytest.mark.parametrize(
    "kwargs",
    [dict(shield=False), dict(sim_config={"sensor_noise_std": 0.1}), dict(sim_config={"v2x_loss": 0.2}),
     dict(sim_config={"actuation_delay_s": 0.2, "shield": {"actuation_delay_s": 0.1}})],
)  # fmt: skip
def test_settings_the_compiled_period_does_not_cover_step_in_numpy(kwargs):
    """(The realistic world runs compiled, its shield's sensing and its delay where it is the world's included, and a
    connected own lane, tests/test_env_realworld.py; a shield's delay other than the world's does not.)"""
    env = LaneChangeEnv(**kwargs)
    env.reset(seed=0)
    env.step(np.zeros(2))
    assert type(env.task.loop) is ClosedLoop


def test_a_non_finite_state_is_an_error_naming_the_scenario():
    env = LaneChangeEnv()
    env.reset(seed=0)
    task = env.task
    rows = task.state.rows
    x = rows.x.copy()
    x[0, 1] = np.inf
    task.state = dataclasses.replace(task.state, rows=rows._replace(x=x))
    with pytest.raises(FloatingPointError, match=str(task.batch.scenario_id[0])):
        env.step(np.zeros(2))


def test_a_spliced_stepper_refuses_what_reads_its_closed_loop():
    """After a reset splices fresh rows into the vector env's batch, the Stepper's ClosedLoop describes the batch
    before: what reads it refuses; a part with another number of vehicle slots is refused."""
    from safelane.envs.core import ScenarioSampler

    venv = LaneChangeVectorEnv(4, **KW)
    venv.reset(seed=1)
    task = venv.task
    task.restart(np.array([2]))
    loop = task.loop
    assert loop.spliced
    for call in (lambda: loop.observe(task.state), lambda: loop.finish(task.state), loop.initial_state):
        with pytest.raises(RuntimeError, match="spliced"):
            call()
    wider = ScenarioSampler.build(n_leaders=5).draw_many([np.random.default_rng(0)])
    part = Stepper(ClosedLoop(wider, task.seed, task.params, task.config, task.planner))
    with pytest.raises(ValueError, match="vehicle slots"):
        loop.splice(np.array([0]), part)

"""Throughput of the Gymnasium environments, compiled and period by period in NumPy, measured in the same run.

*Vector*: :class:`safelane.envs.LaneChangeVectorEnv` with ``--envs`` sub-envs (default 1,024) — one batched closed
loop, the shield on, same-step auto-reset of finished sub-envs included. *Single*: one
``gymnasium.make("safelane/LaneChange-v0")`` env (Gymnasium's own wrappers included) stepped ``--single-steps``
times, resetting when an episode ends; the time inside ``step`` and ``reset`` counts, not the policy's. Each twice:
compiled (the default: the envs' step kernel ``envs/_fast.py``, the closed loop's period with the observation and
the reward) and on the NumPy path (``SAFELANE_NO_FUSED=1``: :class:`safelane.sim.step.ClosedLoop`, the baseline).

Two action streams: *expert* (the rule-based expert planner's law computed from the observation: lane changes
that complete in about 3 s, so many resets) and *random* (uniform in the action box: long, hesitant episodes).
The scenario distribution is the environment's default (``CV_all``, N = 3, ``a_x_N+1_d ~ U[2, 6]``). The vector
time is the best of ``--repeat`` runs of ``--steps`` steps after ``--warmup`` steps, the time inside ``step`` only
(auto-resets included, the policy's own time left out, as for the single env; until 2026-11-29 the vector figure also
counted the policy's, 30–50 µs of a 1,024-row step), on the wall clock and in CPU time of this process (on a busy
machine the wall clock also counts the time other processes held the core).
Targets: vector >= 1,000,000 env-steps/s at 1,024 sub-envs, single >= 10,000 steps/s. Run with
``python benchmarks/bench_env.py [--envs 1024] [--quick] [--world]``; it prints, never asserts.

``--world``: the realistic world (:data:`WORLD`: the own lane's leader ``L0``, sensing error, an actuation delay of
0.2 s, the shield's sensing box and its delay on, as they follow the world's by default; ``--world-only``: the
shield's sensing and delay off, the world's side alone). The vector env refuses
``L0`` and the delay period by period (its sub-envs share one clock there, so a restarted row would run another
episode); its NumPy row here is the same env built on the compiled path and switched to the NumPy path before its
first reset (:func:`time_vector`): the work per step is the NumPy path's, its episodes after a reset are not the
single env's.
"""

from __future__ import annotations

import argparse
import os
import time

import gymnasium as gym
import numpy as np
from threadpoolctl import threadpool_limits

from safelane import Params
from safelane.envs import LaneChangeVectorEnv

TARGET_VECTOR = 1_000_000  # env-steps/s at 1,024 sub-envs
TARGET_SINGLE = 10_000  # steps/s of one env
#: ``--world``'s settings (``sim_config``): the shield's sensing and delay follow the world's.
WORLD = dict(own_lane=True, sensing_error=True, actuation_delay_s=0.2)
#: ``--world-only``'s: the world's side alone (the shield's sensing and delay off).
WORLD_ONLY = dict(WORLD, shield_sensing=False, shield_delay=False)


def expert_actions(obs: np.ndarray, rng: np.random.Generator, prm: Params) -> np.ndarray:
    """The expert planner's law (:class:`safelane.planners.ExpertPlanner`) on the feature map ``(B, 12)``."""
    obs = np.atleast_2d(obs)
    p_y, v_y, gap_l, gap_f, dv_l = obs[:, 0], obs[:, 1], obs[:, 3], obs[:, 4], obs[:, 5]
    a_x = 0.3 * 0.5 * (gap_l - gap_f) + 0.8 * dv_l
    a_y = 0.65**2 * (prm.lane_width - p_y) - 2 * 0.65 * v_y
    return np.stack([np.clip(a_x, -prm.a_x_d, prm.a_x_a), np.clip(a_y, -prm.a_y_m, prm.a_y_m)], 1)


def random_actions(obs: np.ndarray, rng: np.random.Generator, prm: Params) -> np.ndarray:
    n = len(np.atleast_2d(obs))
    return np.stack([rng.uniform(-prm.a_x_d, prm.a_x_a, n), rng.uniform(-prm.a_y_m, prm.a_y_m, n)], 1)


def time_vector(policy, envs: int, steps: int, warmup: int, repeat: int, prm: Params, **kwargs):
    """Env-steps/s of the vector env, wall and CPU: the time inside ``step`` only (the policy's own time left out, as
    :func:`time_single` leaves it out), each clock read around each call; the best of ``repeat`` runs."""
    best, best_cpu, episodes = np.inf, np.inf, 0
    for r in range(repeat):
        numpy_path = os.environ.get("SAFELANE_NO_FUSED") == "1"
        if numpy_path and kwargs:  # built on the compiled path, stepped on the NumPy one (see the module docstring)
            os.environ["SAFELANE_NO_FUSED"] = "0"
        venv = LaneChangeVectorEnv(envs, **kwargs)
        os.environ["SAFELANE_NO_FUSED"] = "1" if numpy_path else "0"
        rng = np.random.default_rng(r)
        obs, _ = venv.reset(seed=r)
        if (type(venv.task.loop).__name__ == "ClosedLoop") != numpy_path:
            raise RuntimeError(f"the vector env stepped on {type(venv.task.loop).__name__}, not the path asked for")
        for _ in range(warmup):
            obs, *_ = venv.step(policy(obs, rng, prm))
        done, elapsed, cpu = 0, 0.0, 0.0
        for _ in range(steps):
            action = policy(obs, rng, prm)
            t, c = time.perf_counter(), time.process_time()
            obs, _, terminated, truncated, _ = venv.step(action)
            elapsed, cpu = elapsed + time.perf_counter() - t, cpu + time.process_time() - c
            done += int((terminated | truncated).sum())
        best_cpu = min(best_cpu, cpu)
        if elapsed < best:
            best, episodes = elapsed, done
    return envs * steps / best, envs * steps / best_cpu, episodes


def time_single(policy, steps: int, prm: Params, **kwargs):
    """Steps/s of one env: the time inside ``env.step`` and ``env.reset`` only (the policy's own time left out),
    on the wall clock around each call and in CPU time of the whole loop minus the policy's share of the wall."""
    env = gym.make("safelane/LaneChange-v0", **kwargs)
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=0)
    for _ in range(20):  # (compiles on first use)
        obs, _, terminated, truncated, _ = env.step(policy(obs, rng, prm)[0])
        if terminated or truncated:
            obs, _ = env.reset()
    inside, clock = 0.0, time.perf_counter
    t0, c0 = clock(), time.process_time()
    for _ in range(steps):
        action = policy(obs, rng, prm)[0]
        t = clock()
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            obs, _ = env.reset()
        inside += clock() - t
    wall, cpu = clock() - t0, time.process_time() - c0
    return steps / inside, steps / (cpu - (wall - inside))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--envs", type=int, default=1024, help="sub-envs of the vector env")
    ap.add_argument("--steps", type=int, default=200, help="timed vector steps per run")
    ap.add_argument("--warmup", type=int, default=50, help="untimed vector steps first (episodes in flight)")
    ap.add_argument("--repeat", type=int, default=3, help="vector runs (the best counts)")
    ap.add_argument("--single-steps", type=int, default=5000, help="timed steps of the single env (NumPy: a tenth)")
    ap.add_argument("--quick", action="store_true", help="128 envs, 20 steps, 1 run, 500 single steps (a smoke run)")
    ap.add_argument("--world", action="store_true", help="the realistic world (WORLD: L0, sensing error, delay)")
    ap.add_argument("--world-only", action="store_true", help="its world's side alone (WORLD_ONLY: the shield's "
                    "sensing and delay off)")  # fmt: skip
    args = ap.parse_args(argv)
    if args.quick:
        args.envs, args.steps, args.warmup, args.repeat, args.single_steps = 128, 20, 5, 1, 500
    prm = Params()
    world = WORLD_ONLY if args.world_only else WORLD if args.world else None
    kwargs = dict(sim_config=world) if world else {}
    print(
        f"bench_env: safelane/LaneChange-v0 defaults (CV_all, N = 3, decel U[2, 6], shield on)"
        f"{f', sim_config={world}' if world else ''}; vector: {args.envs} "
        f"sub-envs, {args.steps} steps after {args.warmup} (best of {args.repeat}); single: gymnasium.make, "
        f"{args.single_steps} steps"
    )
    print(f"targets: vector >= {TARGET_VECTOR:,} env-steps/s at 1,024 sub-envs, single >= {TARGET_SINGLE:,} steps/s\n")
    print("env-steps/s of wall-clock time (and per CPU-second of this process, in brackets: on a busy machine the")
    print("wall clock also counts the time other processes held the core)\n")
    print(f"{'path':<9} {'actions':<8} {'vector':>22} {'episodes':>9} {'single env':>20}")
    rows = {}
    with threadpool_limits(limits=1, user_api="blas"):
        for path, flag in (("compiled", "0"), ("NumPy", "1")):
            os.environ["SAFELANE_NO_FUSED"] = flag  # read at every env's (re)build of its loop
            scale = 1 if flag == "0" else 10
            for name, policy in (("expert", expert_actions), ("random", random_actions)):
                vec, vec_cpu, episodes = time_vector(policy, args.envs, max(2, args.steps // scale), args.warmup,
                                                     args.repeat, prm, **kwargs)  # fmt: skip
                one, one_cpu = time_single(policy, max(50, args.single_steps // scale), prm, **kwargs)
                rows[path, name] = vec_cpu, one_cpu
                print(f"{path:<9} {name:<8} {vec:>10,.0f} ({vec_cpu:>9,.0f}) {episodes:>9} {one:>8,.0f} "
                      f"({one_cpu:>8,.0f})")  # fmt: skip
    os.environ.pop("SAFELANE_NO_FUSED")
    print("\ncompiled / NumPy per CPU-second, and the targets (per CPU-second, the best action stream):")
    for j, (what, target) in enumerate((("vector", TARGET_VECTOR), ("single", TARGET_SINGLE))):
        ratio = "  ".join(f"{name} {rows['compiled', name][j] / rows['NumPy', name][j]:.1f}x"
                          for name in ("expert", "random"))  # fmt: skip
        best = max(rows["compiled", name][j] for name in ("expert", "random"))
        print(f"  {what:<7} {ratio}   target >= {target:,}: {'pass' if best >= target else 'MISS'} ({best:,.0f})")


if __name__ == "__main__":
    main()

"""PPO on ``safelane/LaneChange-v0`` with the shield on and off, for the same budget (extra ``rl``).

Both runs train Stable-Baselines3's PPO in the native vector env (:class:`safelane.envs.sb3.SB3VecEnv`, observations
normalised by ``VecNormalize``) on the same scenario distribution, seed and number of environment steps; the two
runs go in parallel, one process (and one PyTorch thread) each. The policy is a residual on a fixed lane-change
command (``NOMINAL``; see ``docs/envs.md`` for why). During training every ended episode is counted
from ``info``: success, cost (Safety-Gymnasium convention: 1.0 in a period with a collision or a ``p_m`` violation)
and collisions. After training each policy is evaluated (deterministic actions, fresh seeds) with and without the
shield. Outputs (``--out``, default ``docs/results/rl``): ``ppo_shield_curves.csv`` (one row per PPO iteration and
run), ``ppo_shield_summary.json`` and ``ppo_shield.png`` (learning curves of success and of cost).

    python examples/ppo_shield.py                      # the documented run: 2 x 500,000 steps, 320 s of CPU
    python examples/ppo_shield.py --steps 2000 --smoke # seconds
    python examples/ppo_shield.py --plot-only          # redraw the figure from the CSV
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

#: The scenario distribution of the example: N in {1, 3}, L(N+1) braking U[2, 6] m/s², half the followers
#: non-connected (half of those aggressive), so the shield's assessment and worst cases matter.
ENV_KWARGS = {"n_leaders": (1, 3), "decel": (2.0, 6.0), "scenario": {"follower_connected_share": 0.5}}


#: The nominal command the residual policy corrects: no longitudinal acceleration, 1 m/s² toward the target lane.
NOMINAL = np.array([0.0, 1.0], dtype=np.float32)

#: PPO's settings (SB3 defaults otherwise): short rollouts of many envs, so 500k steps give ~500 updates.
PPO_SETTINGS = {"n_steps": 16, "batch_size": 256, "n_epochs": 10, "learning_rate": 3e-4, "gamma": 0.99}


def train(
    shield: bool,
    steps: int,
    envs: int,
    seed: int,
    eval_episodes: int,
    reward: dict | None = None,
    log_std: float = 0.0,
    ppo: dict | None = None,
) -> dict:
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import VecNormalize

    from safelane.envs.sb3 import SB3VecEnv

    torch.set_num_threads(1)
    venv = VecNormalize(
        Residual(SB3VecEnv(envs, seed=seed, shield=shield, reward=reward, **ENV_KWARGS)), norm_reward=False
    )
    rows: list[dict] = []

    class Counter(BaseCallback):
        """Counts every ended episode's outcome and the cost of every step, per PPO iteration."""

        def _on_training_start(self) -> None:
            self.episode_cost = np.zeros(envs)
            self.totals = {"episodes": 0, "successes": 0, "cost": 0.0, "collisions": 0}
            self._reset_iteration()

        def _reset_iteration(self) -> None:
            self.it = {"episodes": 0, "successes": 0, "cost_episodes": 0, "cost": 0.0, "collisions": 0}

        def _on_step(self) -> bool:
            infos, dones = self.locals["infos"], self.locals["dones"]
            cost = np.array([info["cost"] for info in infos])
            self.episode_cost += cost
            self.it["cost"] += cost.sum()
            self.it["collisions"] += sum(info["crashed"] for info in infos)
            for i in np.flatnonzero(dones):
                self.it["episodes"] += 1
                self.it["successes"] += infos[i]["success"]
                self.it["cost_episodes"] += self.episode_cost[i] > 0
                self.episode_cost[i] = 0.0
            return True

        def _on_rollout_end(self) -> None:
            it = self.it
            for key in ("episodes", "successes", "collisions"):
                self.totals[key] += int(it[key])
            self.totals["cost"] += float(it["cost"])
            n = max(it["episodes"], 1)
            rows.append(
                {
                    "shield": shield,
                    "timesteps": self.num_timesteps,
                    "episodes": it["episodes"],
                    "success_rate": it["successes"] / n,
                    "cost_per_episode": it["cost"] / n,
                    "cost_episode_rate": it["cost_episodes"] / n,
                    "collisions": int(it["collisions"]),
                    "cumulative_cost": self.totals["cost"],
                    "cumulative_collisions": self.totals["collisions"],
                }
            )
            self._reset_iteration()

    counter = Counter()
    settings = {**PPO_SETTINGS, **(ppo or {})}
    model = PPO(
        "MlpPolicy", venv, seed=seed, device="cpu", verbose=0, policy_kwargs={"log_std_init": log_std}, **settings
    )
    t0, c0 = time.perf_counter(), time.process_time()
    model.learn(total_timesteps=steps, callback=counter)
    train_s, train_cpu_s = time.perf_counter() - t0, time.process_time() - c0
    evaluation = {
        f"shield_{'on' if on else 'off'}": evaluate(model, venv, on, seed + 10_000, eval_episodes)
        for on in (True, False)
    }
    return {
        "shield": shield,
        "timesteps": int(model.num_timesteps),
        "train_seconds": round(train_s, 1),
        "train_cpu_seconds": round(train_cpu_s, 1),
        "training": counter.totals,
        "evaluation": evaluation,
        "curve": rows,
    }


def Residual(venv):
    """The policy's output is a correction to a fixed nominal command ``NOMINAL`` (a residual policy): PPO's
    initial Gaussian (mean 0) then explores around a lane change that goes somewhere, rather than around standing
    still. The same for both runs."""
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class _Residual(VecEnvWrapper):
        def reset(self):
            return self.venv.reset()

        def step_async(self, actions):
            self.venv.step_async(np.asarray(actions) + NOMINAL)

        def step_wait(self):
            return self.venv.step_wait()

    return _Residual(venv)


def evaluate(model, train_venv, shield: bool, seed: int, episodes: int) -> dict:
    """Deterministic actions on fresh seeds (512 sub-envs), with the training run's observation normalisation."""
    from stable_baselines3.common.vec_env import VecNormalize

    from safelane.envs.sb3 import SB3VecEnv

    venv = VecNormalize(
        Residual(SB3VecEnv(512, seed=seed, shield=shield, **ENV_KWARGS)), training=False, norm_reward=False
    )
    venv.obs_rms = train_venv.obs_rms
    obs = venv.reset()
    done_eps, successes, cost_eps, collisions = 0, 0, 0, 0
    episode_cost = np.zeros(512)
    while done_eps < episodes:
        action, _ = model.predict(obs, deterministic=True)
        obs, _, dones, infos = venv.step(action)
        episode_cost += [info["cost"] for info in infos]
        collisions += sum(info["crashed"] for info in infos)
        for i in np.flatnonzero(dones):
            done_eps += 1
            successes += infos[i]["success"]
            cost_eps += episode_cost[i] > 0
            episode_cost[i] = 0.0
    return {
        "episodes": done_eps,
        "success_rate": round(successes / done_eps, 4),
        "cost_episode_rate": round(cost_eps / done_eps, 4),
        "collisions": int(collisions),
    }


def smooth(rows: list[dict], key: str, window: int = 10) -> np.ndarray:
    """``key`` over the last ``window`` PPO iterations, weighted by their ended episodes (iterations where no
    episode ended carry no weight)."""
    episodes = np.array([r["episodes"] for r in rows], float)
    values = np.array([r[key] for r in rows], float) * episodes
    kernel = np.ones(window)
    num, den = np.convolve(values, kernel)[: len(rows)], np.convolve(episodes, kernel)[: len(rows)]
    with np.errstate(invalid="ignore"):
        return num / den


def plot(curves: dict[bool, list[dict]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    for shield, rows in curves.items():
        label = "shield on" if shield else "shield off"
        colour = "tab:blue" if shield else "tab:red"
        t = np.array([r["timesteps"] for r in rows]) / 1e3
        axes[0].plot(t, smooth(rows, "success_rate"), color=colour, label=label)
        axes[1].plot(t, smooth(rows, "cost_episode_rate"), color=colour, label=label)
        axes[2].plot(t, [r["cumulative_collisions"] for r in rows], color=colour, label=label)
    axes[0].set(title="success rate (episodes ended, last 10 iterations)", xlabel="environment steps [k]")
    axes[1].set(title="share of episodes with cost > 0", xlabel="environment steps [k]")
    axes[2].set(title="collisions during training (cumulative)", xlabel="environment steps [k]")
    for ax in axes[:2]:
        ax.set_ylim(-0.02, 1.02)
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[0].legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def read_curves(path: Path) -> dict[bool, list[dict]]:
    curves: dict[bool, list[dict]] = {True: [], False: []}
    with open(path, newline="") as fh:
        for row in csv.DictReader(fh):
            shield = row.pop("shield") == "True"
            curves[shield].append({k: float(v) for k, v in row.items()})
    return curves


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=500_000, help="environment steps per run (the same for both)")
    ap.add_argument("--envs", type=int, default=64, help="sub-envs of the vector env")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--eval-episodes", type=int, default=2000, help="evaluation episodes per policy and shield")
    ap.add_argument("--out", type=Path, default=Path("docs/results/rl"))
    ap.add_argument("--serial", action="store_true", help="one run after the other (default: in parallel)")
    ap.add_argument("--smoke", action="store_true", help="16 envs, 200 evaluation episodes, no figure")
    ap.add_argument("--plot-only", action="store_true", help="redraw the figure from --out's CSV, no training")
    args = ap.parse_args(argv)
    if args.plot_only:
        plot(read_curves(args.out / "ppo_shield_curves.csv"), args.out / "ppo_shield.png")
        return
    if args.smoke:
        args.envs, args.eval_episodes = 16, 200
    jobs = [(shield, args.steps, args.envs, args.seed, args.eval_episodes) for shield in (True, False)]
    t0 = time.perf_counter()
    if args.serial:
        results = [train(*job) for job in jobs]
    else:
        with ProcessPoolExecutor(max_workers=2) as pool:
            results = list(pool.map(train, *zip(*jobs, strict=True)))
    wall = time.perf_counter() - t0
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "ppo_shield_curves.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(results[0]["curve"][0]))
        writer.writeheader()
        for res in results:
            writer.writerows(res["curve"])
    summary = {
        "env": "safelane/LaneChange-v0",
        "env_kwargs": ENV_KWARGS,
        "ppo": {"n_envs": args.envs, **PPO_SETTINGS, "seed": args.seed},
        "wall_seconds": round(wall, 1),
        "runs": [{k: v for k, v in res.items() if k != "curve"} for res in results],
    }
    (args.out / "ppo_shield_summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    if not args.smoke:
        plot({res["shield"]: res["curve"] for res in results}, args.out / "ppo_shield.png")
    for res in results:
        tr, ev = res["training"], res["evaluation"]
        print(
            f"shield {'on ' if res['shield'] else 'off'}: {res['timesteps']} steps in {res['train_seconds']} s "
            f"({res['train_cpu_seconds']} s CPU); "
            f"training: {tr['episodes']} episodes, {tr['collisions']} collisions, cost {tr['cost']:g}; "
            f"evaluation success (shield on/off) {ev['shield_on']['success_rate']:.3f}/"
            f"{ev['shield_off']['success_rate']:.3f}, cost-episode rate {ev['shield_on']['cost_episode_rate']:.3f}/"
            f"{ev['shield_off']['cost_episode_rate']:.3f}"
        )
    print(f"wall clock {wall:.0f} s; outputs in {args.out}/")


if __name__ == "__main__":
    main()

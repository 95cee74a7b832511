#!/usr/bin/env python3
"""Train a shared PPO policy for the followers, and compare it with the paper's four methods.

The formation environment (``bioform_mj.envs``, MuJoCo robots or ``--plant ideal``, ``action = "velocity"``: the
policy gives ``(υ_cmd, ω_cmd)``, the paper's sliding-mode torque law with its online learner
turns them into wheel torques) is trained with Stable-Baselines3's PPO, one network shared by
every follower (parameter sharing: each follower of each environment copy is one slot of an SB3
``VecEnv``). Seeded: the same command gives the same policy on the same machine. Then the
trained policy and the paper's four methods run the same scenario and seeds, and the script
writes, in ``bioform table1``'s format, the Table I metric and the formation errors of each:

    .venv/bin/pip install -e '.[rl,train]'        # stable-baselines3 and the CPU build of torch
    .venv/bin/python examples/train_ppo.py --timesteps 200000 --out runs/ppo

Outputs in ``--out``: ``learning_curve.png`` (mean episode return per rollout), ``table.md``,
``results.json`` and the policy (``policy.zip`` and the observation normaliser ``vecnormalize.pkl``).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from bioform_mj.control.stack import METHODS
from bioform_mj.envs import ControllerPolicy, parallel_env, run_episode


def make_vec_env(make_env, copies: int, seed: int):
    """An SB3 ``VecEnv`` whose slots are every follower of ``copies`` environments (parameter
    sharing); actions in [-1, 1]² are scaled to the environment's velocity bounds (in float64,
    so a float32 action at ±1 never leaves the space)."""
    from gymnasium import spaces
    from stable_baselines3.common.vec_env import VecEnv

    class SharedPolicyVecEnv(VecEnv):
        def __init__(self) -> None:
            self.envs = [make_env() for _ in range(copies)]
            e0 = self.envs[0]
            self.names = list(e0.possible_agents)
            a0 = e0.action_space(self.names[0])
            self.low, self.high = a0.low.astype(np.float64), a0.high.astype(np.float64)
            obs_space = spaces.Box(-np.inf, np.inf, e0.observation_space(self.names[0]).shape, np.float32)
            super().__init__(copies * len(self.names), obs_space, spaces.Box(-1.0, 1.0, (2,), np.float32))
            self._episode = 0
            self._actions = None
            self._ret = np.zeros(self.num_envs)
            self.episode_returns: list[float] = []

        def _obs(self, e, obs):
            return [np.asarray(obs[a], dtype=np.float32) for a in self.names]

        def reset(self):
            out = []
            for c, e in enumerate(self.envs):
                obs, _ = e.reset(seed=seed * 1000 + self._episode * copies + c)
                out += self._obs(e, obs)
            self._episode += 1
            return np.stack(out)

        def step_async(self, actions):
            self._actions = np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0)

        def step_wait(self):
            obs_all, rew_all, done_all, infos = [], [], [], []
            m = len(self.names)
            for c, e in enumerate(self.envs):
                u = self._actions[c * m : (c + 1) * m]
                act = {a: self.low + (u[q] + 1.0) * 0.5 * (self.high - self.low) for q, a in enumerate(self.names)}
                obs, rew, term, trunc, _ = e.step(act)
                r = np.array([rew[a] for a in self.names], dtype=np.float32)
                done = bool(term[self.names[0]] or trunc[self.names[0]])
                self._ret[c * m : (c + 1) * m] += r
                o = self._obs(e, obs)
                info = [{} for _ in self.names]
                if done:
                    self.episode_returns.append(float(self._ret[c * m : (c + 1) * m].mean()))
                    self._ret[c * m : (c + 1) * m] = 0.0
                    for q in range(m):
                        info[q]["terminal_observation"] = o[q]
                        info[q]["TimeLimit.truncated"] = bool(trunc[self.names[0]] and not term[self.names[0]])
                    obs, _ = e.reset(seed=seed * 1000 + self._episode * copies + c)
                    self._episode += 1
                    o = self._obs(e, obs)
                obs_all += o
                rew_all.append(r)
                done_all += [done] * m
                infos += info
            return np.stack(obs_all), np.concatenate(rew_all), np.array(done_all), infos

        def close(self):
            for e in self.envs:
                e.close()

        def get_attr(self, name, indices=None):
            return [getattr(self, name, None)] * self.num_envs

        def set_attr(self, name, value, indices=None):
            setattr(self, name, value)

        def env_method(self, name, *args, indices=None, **kwargs):
            return [None] * self.num_envs

        def env_is_wrapped(self, wrapper_class, indices=None):
            return [False] * self.num_envs

    return SharedPolicyVecEnv()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="paper")
    ap.add_argument("--plant", choices=("ideal", "mujoco"), default="mujoco", help="the plant (plant.kind)")
    ap.add_argument("--timesteps", type=int, default=200_000, help="samples (agent-steps) of training")
    ap.add_argument("--duration", type=float, default=10.0, help="episode length (s)")
    ap.add_argument("--control-dt", type=float, default=0.01)
    ap.add_argument("--jitter", type=float, default=0.3, help="formation.init_jitter (m, rad): seeds matter")
    ap.add_argument("--copies", type=int, default=2, help="environment copies in the vectorised env")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--collision-weight", type=float, default=1.0, help="the reward's w_collision (0: as first measured)"
    )
    ap.add_argument("--eval-seeds", type=int, default=5)
    ap.add_argument("--out", type=Path, default=Path("runs/ppo"))
    a = ap.parse_args()

    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    torch.manual_seed(a.seed)
    torch.set_num_threads(1)
    os.environ.setdefault("SB3_LOGDIR", str(a.out / "sb3"))  # SB3's logger writes /tmp/SB3-DATE/ otherwise
    ov = [
        f"sim.duration={a.duration}",
        f"sim.control_dt={a.control_dt}",
        f"plant.kind={a.plant}",
        f"formation.init_jitter={a.jitter}",
    ]
    rw = {"collision": a.collision_weight}
    mk = lambda: parallel_env(a.scenario, action="velocity", reward=rw, overrides=ov)  # noqa: E731
    venv = make_vec_env(mk, a.copies, a.seed)
    norm = VecNormalize(venv, norm_obs=True, norm_reward=True, gamma=0.99)
    model = PPO("MlpPolicy", norm, seed=a.seed, n_steps=500, batch_size=500, n_epochs=5, learning_rate=3e-4,
                gamma=0.99, policy_kwargs={"net_arch": [64, 64]}, verbose=0, device="cpu")  # fmt: skip
    t0 = time.perf_counter()
    model.learn(total_timesteps=a.timesteps)
    train_s = time.perf_counter() - t0
    a.out.mkdir(parents=True, exist_ok=True)
    model.save(a.out / "policy.zip")
    norm.save(str(a.out / "vecnormalize.pkl"))

    # evaluation: the same scenario and seeds for the learned policy and the paper's four methods
    norm.training = False
    low, high = venv.low, venv.high

    def learned(obs):
        o = np.stack([np.asarray(obs[ag], dtype=np.float32) for ag in env.agents])
        u, _ = model.predict(norm.normalize_obs(o), deterministic=True)
        u = np.clip(np.asarray(u, dtype=np.float64), -1.0, 1.0)
        return {ag: low + (u[q] + 1.0) * 0.5 * (high - low) for q, ag in enumerate(env.agents)}

    seeds = range(1000, 1000 + a.eval_seeds)  # not seen in training
    rows: dict[str, list[dict]] = {"ppo (shared, velocity)": []}
    env = mk()
    for s in seeds:
        rows["ppo (shared, velocity)"].append(run_episode(env, learned, seed=s))
    tenv = parallel_env(a.scenario, action="torque", overrides=ov)
    for method in METHODS:
        rows[method] = []
        menv = parallel_env(a.scenario, action="torque", overrides=[*ov, f"method={method}"])
        for s in seeds:
            rows[method].append(run_episode(menv, ControllerPolicy(menv), seed=s))
    del tenv

    def stat(eps, key):
        v = np.array([[f[key] for f in e["followers"]] for e in eps])  # (seeds, followers)
        return v.mean(axis=0)

    lines = [
        f"# PPO against the paper's methods: {a.scenario}, {a.plant} plant, {a.duration:g} s, "
        f"control {a.control_dt:g} s, "
        f"jitter {a.jitter:g}, seeds {seeds.start}..{seeds.stop - 1} (trained {a.timesteps} samples, {train_s:.0f} s)",
        "",
        "| method | total velocity error (F1, F2, F3) | final formation error m (F1, F2, F3) | RMS formation error m | "
        "outcomes |",
        "|---|---|---|---|---|",
    ]
    results = {}
    for name, eps in rows.items():
        tv, ff, rf = (
            stat(eps, k) for k in ("total_velocity_error", "final_formation_error_m", "rms_formation_error_m")
        )
        bad = sorted({f["outcome"] for e in eps for f in e["followers"]} - {"ok"})
        lines.append(
            f"| {name} | {', '.join(f'{x:.3f}' for x in tv)} | {', '.join(f'{x:.3f}' for x in ff)} | "
            f"{', '.join(f'{x:.3f}' for x in rf)} | {', '.join(bad) or 'ok'} |"
        )
        results[name] = {"total_velocity_error": tv.tolist(), "final_formation_error_m": ff.tolist(),
                         "rms_formation_error_m": rf.tolist(), "episodes": eps}  # fmt: skip
    table = "\n".join(lines) + "\n"
    (a.out / "table.md").write_text(table)
    (a.out / "results.json").write_text(json.dumps({"train_s": train_s, "returns": venv.episode_returns,
                                                     "results": results}, indent=1, default=float))  # fmt: skip
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot(np.arange(1, len(venv.episode_returns) + 1), venv.episode_returns, ".-")
    ax.set_xlabel("training episode (per environment copy)")
    ax.set_ylabel("mean return per follower")
    ax.set_title(f"PPO, shared policy: {a.scenario}, {a.plant} plant")
    fig.tight_layout()
    fig.savefig(a.out / "learning_curve.png", dpi=120)
    print(table)
    print(f"outputs in {a.out}/")


if __name__ == "__main__":
    main()

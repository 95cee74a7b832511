#!/usr/bin/env python3
"""The formation environment as a BenchMARL task (MAPPO, one shared policy), a minimal run.

BenchMARL builds its PettingZoo tasks on TorchRL's ``PettingZooWrapper``; this task class hands it
``bioform_mj.envs.parallel_env`` (continuous ``(υ_cmd, ω_cmd)`` actions, one group ``follower``).
Needs the ``marl`` extra (benchmarl 1.5.2, which requires torchrl < 0.12: torchrl 0.11.1 and tensordict 0.11.0,
beside the train extra's torch, SB3 and SuperSuit: one set that installs together, docs/envs.md):

    .venv/bin/pip install -e '.[marl]'
    python examples/benchmarl_formation.py --iters 2 --out runs/benchmarl
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

from benchmarl.algorithms import MappoConfig
from benchmarl.environments.pettingzoo.common import PettingZooClass
from benchmarl.experiment import Experiment, ExperimentConfig
from benchmarl.models.mlp import MlpConfig
from torchrl.envs import EnvBase
from torchrl.envs.libs.pettingzoo import PettingZooWrapper

from bioform_mj.envs import parallel_env

OVERRIDES = ["plant.kind=mujoco", "sim.control_dt=0.01", "sim.duration=5", "formation.init_jitter=0.3"]


class FormationTask(PettingZooClass):
    """The paper scenario's followers as a BenchMARL task (``config``: ``max_cycles`` control steps)."""

    def get_env_fun(self, num_envs: int, continuous_actions: bool, seed: int | None, device) -> Callable[[], EnvBase]:
        return lambda: PettingZooWrapper(
            parallel_env("paper", overrides=OVERRIDES, dtype="float32"),
            use_mask=False,
            seed=seed,
            device=device,
            return_state=self.has_state(),  # env.state(): MAPPO's centralised critic takes it
        )

    def supports_continuous_actions(self) -> bool:
        return True

    def supports_discrete_actions(self) -> bool:
        return False

    def has_state(self) -> bool:
        return True  # the environment's state_space: every follower's true pose and velocity

    def has_render(self, env: EnvBase) -> bool:
        return False

    def max_steps(self, env: EnvBase) -> int:
        return int(self.config["max_cycles"])

    @staticmethod
    def env_name() -> str:
        return "bioform"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iters", type=int, default=2)
    ap.add_argument("--out", default="runs/benchmarl", help="BenchMARL's experiment folder (made if missing)")
    a = ap.parse_args()
    import torch

    torch.set_num_threads(1)  # small networks: 5x faster than torch's default threads here (issue 30)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    task = FormationTask(name="FORMATION", config={"max_cycles": 500})
    cfg = ExperimentConfig.get_from_yaml()
    cfg.max_n_iters = a.iters
    cfg.on_policy_collected_frames_per_batch = 1000
    cfg.on_policy_n_envs_per_worker = 1
    cfg.on_policy_n_minibatch_iters = 1
    cfg.on_policy_minibatch_size = 250
    cfg.evaluation = False
    cfg.loggers = []
    cfg.create_json = False
    cfg.save_folder = str(out)  # not the working directory
    cfg.checkpoint_interval = 0
    cfg.train_device = cfg.sampling_device = "cpu"
    exp = Experiment(task=task, algorithm_config=MappoConfig.get_from_yaml(), model_config=MlpConfig.get_from_yaml(),
                     critic_model_config=MlpConfig.get_from_yaml(), seed=0, config=cfg)  # fmt: skip
    exp.run()
    print(f"BenchMARL MAPPO: {exp.n_iters_performed} iterations, {exp.total_frames} frames")


if __name__ == "__main__":
    main()

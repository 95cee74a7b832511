"""The formation environment under TorchRL and BenchMARL, in the one set of versions the ``marl`` extra pins
(torchrl 0.11.1, tensordict 0.11.0, benchmarl 1.5.2 beside the train extra's torch: issue 30, item 7). Marked
``train``: ``make test-train`` installs the extras and runs them; without torchrl they are skipped."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pettingzoo")
torch = pytest.importorskip("torch")
pytest.importorskip("torchrl")
tensordict = pytest.importorskip("tensordict")

from bioform_mj.envs import parallel_env, vector_env  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SHORT = ["sim.duration=0.3", "sim.control_dt=0.01"]

pytestmark = pytest.mark.train


def _saturated(env, sign: float):
    """A policy whose float32 ``tanh`` is saturated (1.0f) times the action bound: float32(2π) > 2π."""

    def policy(td):
        for key in env.action_keys:
            spec = env.full_action_spec[key]
            high = spec.space.high.to(torch.float32)
            td.set(key, torch.tanh(torch.full(spec.shape, 50.0 * sign)) * high)
        return td

    return policy


@pytest.mark.parametrize("plant", ["ideal", "mujoco"])
def test_torchrl_pettingzoo_wrapper_checks_and_rolls_out_as_the_env_steps(plant):
    """TorchRL's ``PettingZooWrapper``: ``check_env_specs`` passes; a 70-step rollout of a saturated float32
    policy crosses two episode ends (30 steps each) without stopping, and its observations are the parallel
    environment's own, bit for bit, for the same seed and actions (stepped here without TorchRL)."""
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper
    from torchrl.envs.utils import check_env_specs

    ov = [*SHORT, f"plant.kind={plant}"]
    wrapped = PettingZooWrapper(parallel_env("paper", overrides=ov, dtype="float32"), use_mask=True, seed=3)
    check_env_specs(wrapped)
    wrapped = PettingZooWrapper(parallel_env("paper", overrides=ov, dtype="float32"), use_mask=True, seed=3)
    roll = wrapped.rollout(70, _saturated(wrapped, 1.0), break_when_any_done=False)
    obs = roll["follower", "observation"]
    assert tuple(obs.shape) == (70, 3, 25) and obs.dtype == torch.float32
    assert int(roll["next", "done"].sum()) == 2
    act = roll["follower", "action"][0].numpy()
    assert act.dtype == np.float32 and float(act[0, 1]) > 2 * np.pi  # the bound as float32 rounds it: taken
    env = parallel_env("paper", overrides=ov, dtype="float32")
    first, _ = env.reset(seed=3)
    nxt, *_ = env.step({a: act[i] for i, a in enumerate(env.possible_agents)})
    agents = env.possible_agents
    assert np.array_equal(obs[0].numpy(), np.stack([first[a] for a in agents]))
    assert np.array_equal(roll["next", "follower", "observation"][0].numpy(), np.stack([nxt[a] for a in agents]))


def test_torchrl_style_output_is_a_tensordict_batch():
    """``TorchRLStyle(vector_env, torch=True)`` output goes into ``TensorDict(..., batch_size=[W])`` as it is:
    TorchRL's keys and shapes; both worlds end at 30 periods, and a ``_reset`` mask restarts only its world."""
    from tensordict import TensorDict

    from bioform_mj.envs.tdict import TorchRLStyle

    W = 2
    td_env = TorchRLStyle(vector_env("paper", worlds=W, threads=1, overrides=[*SHORT, "plant.kind=mujoco"]), torch=True)
    td = TensorDict(td_env.reset(seed=[4, 9]), batch_size=[W])
    assert tuple(td["agents", "observation"].shape) == (W, 3, 25)
    act = torch.zeros(W, 3, 2)
    for _ in range(30):
        out = TensorDict(td_env.step({"agents": {"action": act}}), batch_size=[W])
    assert out["done"].all() and tuple(out["agents", "reward"].shape) == (W, 3, 1)
    again = TensorDict(td_env.reset({"_reset": torch.tensor([[True], [False]])}), batch_size=[W])
    assert not again["done"][0] and again["done"][1]  # world 0 restarted, world 1 still ended
    assert torch.equal(again["agents", "observation"][1], out["agents", "observation"][1])


def test_benchmarl_example_trains_one_iteration_into_its_out_folder(tmp_path):
    """``examples/benchmarl_formation.py --iters 1``: MAPPO runs one iteration (1,000 frames), one torch thread,
    and BenchMARL's experiment folder lands under ``--out``, nothing in the working directory."""
    pytest.importorskip("benchmarl")
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    out = tmp_path / "bm"
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    res = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "benchmarl_formation.py"), "--iters", "1", "--out", str(out)],
        cwd=cwd, env=env, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr[-2000:]
    assert "BenchMARL MAPPO: 1 iterations, 1000 frames" in res.stdout
    assert [p.name.split("_")[0] for p in out.iterdir()] == ["mappo"]
    assert list(cwd.iterdir()) == []

"""One follower of the formation as a Gymnasium environment (design §20; docs/envs.md).

:class:`FollowerEnv` hands one agent of :class:`~.parallel.FormationParallelEnv` to a
single-agent trainer (Stable-Baselines3, Gymnasium's vector environments); the other followers
are driven by ``others`` (default: the paper's controller of the scenario's method,
:class:`~.policy.ControllerPolicy`, in the environment's action mode). Its action is the
agent's, normalised to ``[-1, 1]²`` (float32, what Gymnasium's and SB3's checkers ask for) and
scaled onto ``±[v_max, w_max]`` (m/s, rad/s) or ``±τ_max`` (N·m); its observation, reward,
termination and truncation are the agent's own. Gymnasium's ``check_env`` and SB3's pass without
a warning (``tests/test_envs_training.py``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.envs.registration import EnvSpec

from bioform_mj.envs.parallel import FormationParallelEnv, parallel_env
from bioform_mj.envs.policy import ControllerPolicy


class FollowerEnv(gymnasium.Env):
    """Follower ``agent`` of ``scenario`` as a Gymnasium ``Env`` (``options``: those of
    :class:`~.parallel.FormationParallelEnv`; observations default to float32 here).

    ``others``: a callable ``obs dict -> action dict`` for the other followers (it may have
    ``reset()``), or None for the paper's controller."""

    # "rgb_array" only: Gymnasium's check_env makes the environment in every listed mode ("human" would
    # want a display); the formation environment itself also has "human"
    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(
        self,
        scenario: str | Path | Any = "paper",
        agent: str = "follower_1",
        others: Callable[[Mapping[str, np.ndarray]], Mapping[str, Any]] | None = None,
        **options: Any,
    ) -> None:
        options.setdefault("dtype", "float32")
        if options.get("render_mode") not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"unknown render_mode {options['render_mode']!r} (expected None or one of: rgb_array)")
        self.par: FormationParallelEnv = parallel_env(scenario, **options)
        if agent not in self.par.possible_agents:
            raise ValueError(f"unknown agent {agent!r} (agents: {', '.join(self.par.possible_agents)})")
        self.agent = agent
        self._i = self.par.possible_agents.index(agent)
        self.others = ControllerPolicy(self.par) if others is None else others
        self.render_mode = self.par.render_mode
        self.observation_space = self.par.observation_space(agent)
        self.action_space = spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self._scale = self.par._high[self._i].copy()  # action ±1 → ± this bound
        # its Gymnasium spec (gymnasium.make sets its own): check_env makes it again in each render mode
        kwargs = {"scenario": scenario, "agent": agent, "others": others, **options}
        self.spec = EnvSpec(GYMNASIUM_ID, entry_point="bioform_mj.envs.single:FollowerEnv", kwargs=kwargs)

    def reset(self, *, seed: int | None = None, options: Mapping[str, Any] | None = None):
        """Start an episode (``seed``: :meth:`FormationParallelEnv.reset`); ``(observation, info)``."""
        obs, infos = self.par.reset(seed=seed, options=options)
        self._np_random = self.par.np_random  # one random stream: the formation environment's
        self._obs = obs
        if hasattr(self.others, "reset"):
            self.others.reset()
        return obs[self.agent], infos[self.agent]

    def step(self, action: Any):
        """One control period: ``(observation, reward, terminated, truncated, info)`` of the agent."""
        a = np.asarray(action)
        if a.dtype.kind not in "fiu":  # a string "1", True, 1j were taken as numbers (issue 28)
            raise ValueError(f"action must be 2 real numbers, got {action!r}")
        a = a.astype(float, copy=False)
        if a.shape != (2,):
            raise ValueError(f"action must have shape (2,), got {a.shape}")
        if not np.isfinite(a).all() or np.abs(a).max() > 1.0 + 2.0**-23:  # float32 rounding of ±1 taken
            raise ValueError(f"action {a.tolist()} is outside the action space [-1, 1]² (or not finite)")
        acts = dict(self.others(self._obs)) if len(self.par.possible_agents) > 1 else {}
        acts[self.agent] = np.clip(a, -1.0, 1.0) * self._scale
        obs, rew, term, trunc, info = self.par.step(acts)
        self._obs = obs
        return obs[self.agent], rew[self.agent], bool(term[self.agent]), bool(trunc[self.agent]), info[self.agent]

    def render(self) -> np.ndarray | None:
        """The formation's frame, or None in ``"human"`` mode (:meth:`FormationParallelEnv.render`)."""
        return self.par.render()

    def close(self) -> None:
        self.par.close()


#: Gymnasium's id of :class:`FollowerEnv`: ``gymnasium.make(GYMNASIUM_ID, scenario=..., **options)`` (what
#: Gymnasium's ``check_env`` wants to test every render mode, and ``gymnasium.make_vec`` takes)
GYMNASIUM_ID = "bioform_mj/Follower-v0"
if GYMNASIUM_ID not in gymnasium.registry:
    gymnasium.register(id=GYMNASIUM_ID, entry_point="bioform_mj.envs.single:FollowerEnv")


def follower_env(scenario: str | Path | Any = "paper", **options: Any) -> FollowerEnv:
    """:class:`FollowerEnv` of ``scenario`` (``options``: its own and the formation environment's)."""
    return FollowerEnv(scenario, **options)

"""A TorchRL-style batched interface for the batched environments (design §20; issue 30, item 5).

:class:`TorchRLStyle` wraps the CPU-vectorised :class:`~.vector.VectorEnv` or the Warp-batched
:class:`~.batched.BatchEnv` with the conventions TorchRL's and BenchMARL's vectorised multi-agent
environments use (VMAS's layout): nested dicts of arrays with a leading world (batch) axis,
``("agents", "observation")`` (W, n, obs_size), ``("agents", "action")`` (W, n, 2), ``("agents", "reward")``
(W, n, 1), and per world ``"done"``, ``"terminated"``, ``"truncated"`` (W, 1) booleans; ``reset`` takes a
``"_reset"`` (W, 1) mask (the worlds to reset: TorchRL's partial reset) and seeds per world. Plain numpy
(``tensordict.TensorDict(out, batch_size=[W])`` takes it as it is); ``torch=True`` returns torch tensors
(torch is imported only then: an optional dependency).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np


class TorchRLStyle:
    """``env`` (a :class:`~.vector.VectorEnv` or :class:`~.batched.BatchEnv`) with TorchRL's batched keys.

    ``torch``: return torch tensors (on ``device``) instead of numpy arrays (needs torch)."""

    def __init__(self, env: Any, torch: bool = False, device: str = "cpu") -> None:
        self.env = env
        self.nworld = int(env.nworld)
        self.n = int(env.n)
        self._warp = not hasattr(env, "envs")
        self._torch = None
        if torch:
            try:
                import torch as _torch
            except ImportError as exc:
                raise ImportError("TorchRLStyle(torch=True) needs torch: pip install torch") from exc
            self._torch = _torch
        self.device = device
        self._term = np.zeros(self.nworld, dtype=bool)
        self._trunc = np.zeros(self.nworld, dtype=bool)

    def __getstate__(self) -> dict[str, Any]:
        """Picklable (the torch module is not): the wrapped environment pickles as it does."""
        return {**self.__dict__, "_torch": self._torch is not None}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        if state["_torch"]:
            import torch as _torch

            self._torch = _torch
        else:
            self._torch = None

    @property
    def batch_size(self) -> tuple[int]:
        """``(W,)``: TorchRL's batch size of this environment."""
        return (self.nworld,)

    def reset(self, tensordict: Mapping[str, Any] | None = None, seed: Any = None) -> dict[str, Any]:
        """Reset the worlds of ``tensordict["_reset"]`` ((W, 1) or (W,) booleans; no ``_reset``: all) and
        return every world's observation and flags. ``seed``: as :meth:`.vector.VectorEnv.reset` (an int,
        one per world reset, or None: each world's own stream); the Warp-batched environment's seeds are
        fixed when it is built (``batch_env(seeds=...)``), so a seed there is refused."""
        mask = None
        if tensordict is not None and "_reset" in tensordict:
            mask = np.asarray(_numpy(tensordict["_reset"]), dtype=bool).reshape(-1)
            if mask.shape != (self.nworld,):
                raise ValueError(f"_reset must have {self.nworld} entries (one per world), got {mask.shape}")
        if self._warp:
            if seed is not None:
                raise ValueError(
                    "the Warp-batched environment's seeds are fixed when it is built: batch_env(..., seeds=[...])"
                )
            obs = self.env.reset(mask).numpy()
        else:
            obs = self.env.reset(seed=seed, mask=mask)
        sel = np.ones(self.nworld, dtype=bool) if mask is None else mask
        self._term[sel] = False
        self._trunc[sel] = False
        return self._out({"observation": np.array(obs)})

    def step(self, tensordict: Mapping[str, Any]) -> dict[str, Any]:
        """One period of every running world with ``tensordict["agents"]["action"]`` (W, n, 2); returns the
        next observations, rewards (W, n, 1) and flags (W, 1)."""
        try:
            act = tensordict["agents"]["action"]
        except (KeyError, TypeError) as exc:
            raise ValueError('step() needs the actions at ("agents", "action"), shape (W, n, 2)') from exc
        obs, rew, term, trunc = self.env.step(np.asarray(_numpy(act), dtype=float))
        if self._warp:
            obs, rew = obs.numpy(), rew.numpy()
        self._term |= np.asarray(term, dtype=bool)
        self._trunc |= np.asarray(trunc, dtype=bool)
        return self._out({"observation": np.array(obs), "reward": np.array(rew)[..., None]})

    def _out(self, agents: dict[str, np.ndarray]) -> dict[str, Any]:
        term, trunc = self._term[:, None].copy(), self._trunc[:, None].copy()
        out = {"agents": agents, "done": term | trunc, "terminated": term, "truncated": trunc}
        return out if self._torch is None else _to_torch(out, self._torch, self.device)


def _numpy(x: Any) -> Any:
    """A torch tensor as numpy (through the CPU); anything else as it is."""
    if hasattr(x, "detach") and hasattr(x, "cpu"):
        return x.detach().cpu().numpy()
    return x


def _to_torch(d: dict[str, Any], torch: Any, device: str) -> dict[str, Any]:
    return {k: _to_torch(v, torch, device) if isinstance(v, dict) else torch.as_tensor(v, device=device)
            for k, v in d.items()}  # fmt: skip

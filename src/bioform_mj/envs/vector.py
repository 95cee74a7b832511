"""Many formations on the CPU, stepped by compiled code on threads over worlds (design §20; issue 30, item 5).

:class:`VectorEnv` holds ``W`` worlds of one scenario on the MuJoCo plant, each a
:class:`~.parallel.FormationParallelEnv` (its own ``MjModel``/``MjData`` and control stack), and steps
them with the layout of the Warp-batched environment (``envs.batched``: arrays with a leading world axis,
observations (W, n, obs_size), rewards (W, n), flags (W,)). A period of every world is
:func:`~.fast.mujoco_period` (the single environment's compiled period, the same bits); ``threads``
Python threads each run one compiled call over a block of worlds (numba's code releases the GIL), as
``mujoco.rollout`` splits its batch over a thread pool. World ``w``'s episode is the single
environment's episode of the same seed and actions, bit for bit (``tests/test_envs_vector.py``).

The TorchRL-style dict-of-arrays interface for this and the Warp-batched environment is
:mod:`.tdict`. What it needs of a scenario is what the compiled period needs (``envs.fast_plant``)
and no events (a payload's period runs in Python in the single environment).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from bioform_mj.core.equations import njit
from bioform_mj.envs.fast import (
    BAD_ACTION,
    FAST,
    GUARD,
    TIPPED,
    WARNED,
    FastPeriod,
    fast_plant,
    period,
    warning_message,
)
from bioform_mj.envs.parallel import FormationParallelEnv, parallel_env
from bioform_mj.scenario.config import Scenario

#: at most this share of the memory available now may be taken by the worlds (estimated before building them)
MEMORY_SHARE = 0.5


@njit
def periods(args, lo, hi, U, pose, vel, new_pose, new_vel, O, k, step_count, status, running):
    """Worlds ``lo … hi−1`` that are ``running``: one :func:`~.fast.mujoco_period` each (``args`` a typed
    list of the worlds' :class:`~.fast.PeriodArgs`, ``U`` (W, n, 2) their actions); a world's new state is
    copied into ``pose``, ``vel`` (unless MuJoCo warned: the plant is not observed then) and its step
    counters ``k`` (control) and ``step_count`` (the plant's) advance. ``status`` (W,): the period's bits."""
    for w in range(lo, hi):
        if not running[w]:
            continue
        st = period(args[w], U[w], pose[w], vel[w], new_pose[w], new_vel[w], O[w], k[w], step_count[w])
        status[w] = st
        if st & BAD_ACTION:
            continue
        step_count[w] += 1
        if st & WARNED:
            continue
        k[w] += 1
        pose[w, :, :] = new_pose[w]
        vel[w, :, :] = new_vel[w]


def _world_bytes(env: FormationParallelEnv) -> int:
    """Bytes one world holds (its MuJoCo model and data buffers, its arrays over the episode), estimated
    from a built one: ``MjModel.nbuffer + MjData.nbuffer`` + the leader's trajectory + ~64 KiB of the stack."""
    p = env._plant
    return int(p.model.nbuffer + p.data.nbuffer + env.L_pose.nbytes + env.L_vel.nbytes + 65536)


class VectorEnv:
    """``worlds`` formations of ``scenario`` on the CPU (see the module docstring).

    Parameters
    ----------
    scenario : a preset name, a TOML path or a :class:`~bioform_mj.scenario.config.Scenario` (its plant:
        MuJoCo; ``overrides`` as :func:`~.parallel_env`).
    worlds : the number of worlds ``W``.
    threads : threads stepping them (default: the machine's CPUs, at most ``W``).
    max_bytes : refuse (``ValueError``) when the worlds' estimated memory exceeds this (default:
        :data:`MEMORY_SHARE` of the memory available now).
    options : :class:`~.parallel.FormationParallelEnv`'s (``action``, ``reward``, ``v_max``, ``w_max``,
        ``overrides``, ``dtype``, ``randomize``, ``max_cycles``).
    """

    def __init__(
        self,
        scenario: str | Path | Scenario = "paper",
        worlds: int = 8,
        threads: int | None = None,
        *,
        max_bytes: float | None = None,
        **options: Any,
    ) -> None:
        if isinstance(worlds, bool) or not isinstance(worlds, (int, np.integer)) or worlds < 1:
            raise ValueError(f"worlds must be an integer >= 1, got {worlds!r}")
        W = int(worlds)
        import os

        cpus = os.cpu_count() or 1
        T = min(W, cpus) if threads is None else threads
        if isinstance(T, bool) or not isinstance(T, (int, np.integer)) or T < 1:
            raise ValueError(f"threads must be an integer >= 1, got {threads!r}")
        if not FAST:
            raise ValueError("the CPU-vectorised environment needs numba with its JIT on")
        env0 = parallel_env(scenario, **options)
        sc = env0.base_scenario
        if sc.plant.kind != "mujoco":
            raise ValueError(
                f"the CPU-vectorised environment runs the MuJoCo plant, not plant.kind = '{sc.plant.kind}'"
            )
        if sc.events:
            raise ValueError("the CPU-vectorised environment cannot run scenario events (payloads): use parallel_env")
        env0.reset(seed=0)  # builds the plant: one world, to measure a world's memory before the others
        if not fast_plant(env0):
            raise ValueError(
                "the CPU-vectorised environment cannot run this scenario (it needs sensing = 'truth', no DC-motor "
                "feed, a harmonic disturbance, no per-step faults): use parallel_env"
            )
        per = _world_bytes(env0)
        need = W * per
        if max_bytes is None:
            avail = _available_bytes()
            bound = None if avail is None else MEMORY_SHARE * avail
        else:
            bound = float(max_bytes)
        if bound is not None and need > bound:
            raise ValueError(
                f"VectorEnv: {W} worlds need ~{need / 2**30:.2f} GiB ({per / 2**20:.2f} MiB a world), over the "
                f"bound of {bound / 2**30:.2f} GiB: fewer worlds"
            )
        self.envs = [env0] + [parallel_env(scenario, **options) for _ in range(W - 1)]
        self.nworld, self.n, self.threads = W, env0.n, int(T)
        self.obs_size, self.N, self.dt = env0.obs_size, env0.N, env0.dt
        self.possible_agents = list(env0.possible_agents)
        self.weights = env0.weights
        self.low, self.high = env0._low, env0._high
        self.dtype = env0._dtype
        n = self.n
        self.pose = np.zeros((W, n, 3))
        self.vel = np.zeros((W, n, 2))
        self._new_pose = np.zeros((W, n, 3))
        self._new_vel = np.zeros((W, n, 2))
        self.obs = np.zeros((W, n, self.obs_size))
        self.reward = np.zeros((W, n))
        self._fe = np.zeros((W, n))
        self._hits = np.zeros((W, n))
        self.k = np.zeros(W, dtype=np.int64)
        self._sc = np.zeros(W, dtype=np.int64)
        self._status = np.zeros(W, dtype=np.int64)
        self.running = np.zeros(W, dtype=np.bool_)
        self.seeds = np.zeros(W, dtype=np.int64)
        from numba.typed import List

        self._args: Any = List()
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None
        self._blocks = [(W * t // self.threads, W * (t + 1) // self.threads) for t in range(self.threads)]
        self._started = False

    # ------------------------------------------------------------------ reset
    def reset(self, seed: Any = None, mask: Any = None) -> np.ndarray:
        """Start the episodes of the worlds in ``mask`` ((W,) booleans or world indices; None: all); returns
        the observations (W, n, obs_size) (the other worlds' rows unchanged). ``seed``: None (each world
        continues its own random stream, as ``FormationParallelEnv.reset``), an int (world ``w`` gets
        ``seed + w``) or one seed per world reset, in world order."""
        sel = self._worlds(mask)
        if seed is None:
            seeds = [None] * len(sel)
        elif np.ndim(seed) == 0:
            if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or int(seed) < 0:
                raise ValueError(f"seed must be an integer >= 0, a list of them or None, got {seed!r}")
            seeds = [int(seed) + int(w) for w in sel]
        else:
            seeds = [int(s) for s in seed]
            if len(seeds) != len(sel):
                raise ValueError(f"{len(seeds)} seeds for the {len(sel)} worlds being reset")
            if any(s < 0 for s in seeds):
                raise ValueError(f"seeds must be >= 0, got {seeds}")
        for w, s in zip(sel, seeds):
            self._reset_world(int(w), s)
        self._started = True
        return self._out_obs()

    def _reset_world(self, w: int, seed: int | None) -> None:
        env = self.envs[w]
        obs, info = env.reset(seed=seed)
        self.seeds[w] = info[self.possible_agents[0]]["seed"]
        self.pose[w], self.vel[w] = env._pose, env._vel
        for i, a in enumerate(self.possible_agents):
            self.obs[w, i] = obs[a]
        self.reward[w] = 0.0
        self.k[w] = 0
        self._sc[w] = env._plant._step_count
        self.running[w] = True
        fp = FastPeriod(env, r=self.reward[w], fe=self._fe[w], hits=self._hits[w])
        if len(self._args) < self.nworld:
            while len(self._args) <= w:
                self._args.append(fp.args)
        self._args[w] = fp.args
        env._fastp = fp

    def _worlds(self, mask: Any) -> np.ndarray:
        W = self.nworld
        if mask is None:
            return np.arange(W)
        m = np.asarray(mask)
        if m.dtype == bool:
            m = m.reshape(-1)
            if m.shape != (W,):
                raise ValueError(f"a world mask must have {W} entries, got shape {np.shape(mask)}")
            return np.flatnonzero(m)
        if m.size and (not np.issubdtype(m.dtype, np.integer) or m.min() < 0 or m.max() >= W):
            raise ValueError(f"world indices must be integers in 0..{W - 1}, got {m.tolist()}")
        return m.reshape(-1).astype(np.int64)

    # ------------------------------------------------------------------ step
    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One control period of every running world; returns ``(obs (W, n, obs_size), reward (W, n),
        terminated (W,), truncated (W,))``. ``actions`` (W, n, 2), float32 or float64, in the action space
        of every world's agents (rows of worlds not running are ignored). A world that ended stays ended
        (its rows keep their last values) until :meth:`reset` names it."""
        if not self._started or not self.running.any():
            raise RuntimeError("step() with no world running: call reset() first")
        U = np.array(actions, dtype=float)
        if U.shape != (self.nworld, self.n, 2):
            raise ValueError(f"actions must have shape ({self.nworld}, {self.n}, 2), got {U.shape}")
        run = self.running
        e0 = self.envs[0]
        ok = np.isfinite(U) & (U >= e0._acc_low) & (U <= e0._acc_high)
        bad = run & ~ok.all(axis=(1, 2))
        if bad.any():  # before any world steps: the single environment's message for the first bad world
            w = int(np.flatnonzero(bad)[0])
            try:
                self.envs[w]._actions({ag: U[w, i] for i, ag in enumerate(self.possible_agents)})
            except ValueError as exc:
                raise ValueError(f"world {w}: {exc}") from exc
        st = self._status
        st[:] = 0
        a = (self._args, U, self.pose, self.vel, self._new_pose, self._new_vel, self.obs, self.k, self._sc, st, run)
        if self._pool is None:
            periods(a[0], 0, self.nworld, *a[1:])
        else:
            futs = [self._pool.submit(periods, a[0], lo, hi, *a[1:]) for lo, hi in self._blocks]
            for f in futs:
                f.result()
        term = run & ((st & (GUARD | TIPPED | WARNED)) > 0)
        for w in np.flatnonzero(term):  # the terminal reward; a MuJoCo warning: the period's tail in Python
            if st[w] & WARNED:
                self._warned(int(w))
            else:
                self.reward[w] -= self.weights["terminal"] * max(0.0, (self.N - int(self.k[w])) * self.dt)
        self.obs[run & ((st & (GUARD | WARNED)) > 0)] = 0.0
        trunc = run & ~term & (self.k >= self.N)
        self.running = run & ~(term | trunc)
        return self._out_obs(), self.reward, term, trunc

    def _warned(self, w: int) -> None:
        """World ``w``'s MuJoCo warning: the single environment's step-by-step tail (the state not observed)."""
        env = self.envs[w]
        p = env._plant
        p._step_count = int(self._sc[w])
        env.k, env._pose, env._vel = int(self.k[w]), self.pose[w].copy(), self.vel[w].copy()
        tau = env._fastp.tau.copy()
        r = env._advance_tail(tau, warning_message(p))[0]
        self.reward[w] = r
        self.k[w] = env.k

    def _out_obs(self) -> np.ndarray:
        return self.obs if self.dtype == self.obs.dtype else self.obs.astype(self.dtype)

    def close(self) -> None:
        """Stop the threads (the worlds stay: :meth:`reset` may start them again)."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None


def _available_bytes() -> float | None:
    """``MemAvailable`` of /proc/meminfo (bytes), or None where it cannot be read."""
    try:
        with open("/proc/meminfo") as fh:
            return float(next(int(line.split()[1]) * 1024 for line in fh if line.startswith("MemAvailable")))
    except (OSError, StopIteration, ValueError):
        return None


def vector_env(scenario: str | Path | Scenario = "paper", worlds: int = 8, threads: int | None = None, **options):
    """:class:`VectorEnv` of ``scenario`` (a bad scenario: a ``ValueError`` naming it)."""
    from bioform_mj.core.errors import InputError

    try:
        return VectorEnv(scenario, worlds, threads, **options)
    except InputError as exc:
        raise ValueError(str(exc)) from exc

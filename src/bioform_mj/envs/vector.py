"""Many formations on the CPU, stepped by compiled code on threads over worlds (design §20; issue 30, item 5).

:class:`VectorEnv` holds ``W`` worlds of one scenario on the MuJoCo plant, each a
:class:`~.parallel.FormationParallelEnv` (its own ``MjModel``/``MjData`` and control stack), and steps
them with the layout of the Warp-batched environment (``envs.batched``: arrays with a leading world axis,
observations (W, n, obs_size), rewards (W, n), flags (W,)). A period of every world is
:func:`~.fast.mujoco_period` (the single environment's compiled period, the same bits); the worlds are
split into ``threads`` blocks, as ``mujoco.rollout`` splits its batch over a thread pool: a step is one
compiled call (:func:`~.worlds.dispatch`) in which the calling thread releases the other threads, steps its
block and then claims what is left of the others' (a thread held up by other processes holds nothing up but
the world it is stepping) and waits until every world is done; the others stay in compiled code between
periods (:func:`~.worlds.serve`, ``envs.team``, ``envs.worlds``).
World ``w``'s episode is the single environment's episode of the same seed and actions, bit for bit
(``tests/test_envs_vector.py``).

The worlds' physics steps with one shared ``MjModel`` wherever a world's physics is the built scene's
(:meth:`VectorEnv._share_init`): at a 1 ms control period each world is visited for one physics step,
and W copies of the model's hot arrays did not stay in the cache (32 worlds: 1.2-1.5x the steps/s).
Likewise each thread steps its worlds on one warm ``MjData``, each world's MuJoCo state copied in and out
every period, as ``mujoco.rollout`` does (:meth:`VectorEnv._warm_init`; 32 worlds, 1 ms: 1.2-1.4x).
A period's Python is a few calls for all worlds together: the ends of the period (terminal rewards,
zeroed observations, truncation, the observations' dtype) are computed in the compiled call.

The TorchRL-style dict-of-arrays interface for this and the Warp-batched environment is
:mod:`.tdict`. What it needs of a scenario is what the compiled period needs (``envs.fast_plant``)
and no events (a payload's period runs in Python in the single environment; a drawn ``payload`` is
refused too).
"""

from __future__ import annotations

import os
import threading
import weakref
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from bioform_mj.envs.fast import FAST, WARNED, Compiled, FastPeriod, fast_plant, warning_message
from bioform_mj.envs.parallel import FormationParallelEnv, parallel_env
from bioform_mj.envs.team import HAVE_TEAM
from bioform_mj.envs.team import control as team_control
from bioform_mj.envs.team import stop as team_stop
from bioform_mj.envs.worlds import block, check, claims, count_warned, dispatch, make_vargs, serve, start
from bioform_mj.scenario.config import Scenario

#: at most this share of the memory available now may be taken by the worlds (estimated before building them)
MEMORY_SHARE = 0.5
#: bytes of one world's :class:`~.fast.PeriodArgs` on one thread, counted in the memory estimate once per world and
#: thread (``envs.worlds``: any thread steps any world, so each world has one a thread; measured 14.5 KB each, RSS
#: over 4,000 of them): the worlds' memory grows with worlds × threads
ARGS_BYTES = 16 * 1024
#: ``VectorEnv._ep_start`` of a world whose ended episode's actions were moved out of the history (``_trim``)
ENDED = -2
#: ns a thread of the team spins (atomic loads) before it sleeps, waiting for the next period or for the
#: other threads' blocks (``envs.team``); 0 where the threads outnumber the CPUs this process may use
SPIN_NS = 200_000


def _pinned(cpu: int | None, fn: Any, *args: Any) -> None:
    """A worker thread's life: pinned to ``cpu`` (None: not pinned), then ``fn(*args)`` (:func:`~.worlds.serve`)."""
    if cpu is not None:
        os.sched_setaffinity(0, {cpu})
    fn(*args)


def _stop_team(ctl: np.ndarray, workers: list, caller: tuple | None) -> None:
    """Stop and join a team's workers (:meth:`VectorEnv.close`, or the environment's collection or the
    interpreter's exit through ``weakref.finalize``); ``caller``: the pinned calling thread's ``(native id,
    CPUs it had)``, given back."""
    if caller is not None:
        try:
            os.sched_setaffinity(caller[0], caller[1])
        except OSError:  # that thread has ended
            pass
    team_stop(ctl)
    for th in workers:
        th.join()


def _world_bytes(env: FormationParallelEnv) -> int:
    """Bytes one world holds (its MuJoCo model and data buffers, its arrays over the episode), estimated
    from a built one: ``MjModel.nbuffer + MjData.nbuffer`` + the leader's trajectory + ~64 KiB of the stack +
    its share of the replay history's bound (``VectorEnv._trim``: ``(3·N + 2)·(16·n + 1)`` bytes)."""
    p = env._plant
    hist = (3 * int(env.N) + 2) * (16 * env.n + 1)
    return int(p.model.nbuffer + p.data.nbuffer + env.L_pose.nbytes + env.L_vel.nbytes + 65536 + hist)


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
    warm : step each thread's worlds on one ``MjData`` of that thread, each world's MuJoCo state
        (``mjSTATE_INTEGRATION``) copied in and out of it every period, as ``mujoco.rollout`` does (default); False:
        every world steps its own ``MjData`` (the same bits, slower: see :meth:`_warm_init`).
    pin : pin each thread to one CPU (Linux: ``sched_setaffinity``): the calling thread, from its first
        :meth:`step` to :meth:`close` (which gives it back the CPUs it had when the environment was made), to
        the first of those CPUs, thread ``t`` to the ``t``-th; a thread's worlds then stay in its CPU's cache
        (2 threads, 1 ms: 1.3x the world-steps/s in one run). For a machine given to the training; default
        False. ``threads`` at most those CPUs.
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
        warm: bool = True,
        pin: bool = False,
        **options: Any,
    ) -> None:
        if isinstance(worlds, bool) or not isinstance(worlds, (int, np.integer)) or worlds < 1:
            raise ValueError(f"worlds must be an integer >= 1, got {worlds!r}")
        W = int(worlds)
        cpus = os.cpu_count() or 1
        T = min(W, cpus) if threads is None else threads
        if isinstance(T, bool) or not isinstance(T, (int, np.integer)) or T < 1:
            raise ValueError(f"threads must be an integer >= 1, got {threads!r}")
        if not FAST:
            raise ValueError("the CPU-vectorised environment needs numba with its JIT on")
        if not isinstance(pin, bool):
            raise ValueError(f"pin must be True or False, got {pin!r}")
        if pin and (not HAVE_TEAM or T > _usable_cpus()):
            raise ValueError(f"pin=True needs Linux and a CPU per thread: {T} threads, {_usable_cpus()} CPUs usable")
        if T > W:  # each thread holds an MjData: threads=10**6 was MuJoCo's "Could not allocate memory" (issue 28)
            raise ValueError(f"threads must be at most worlds = {W} (a thread steps a block of worlds), got {T}")
        env0 = parallel_env(scenario, **options)
        sc = env0.base_scenario
        if sc.plant.kind != "mujoco":
            raise ValueError(
                f"the CPU-vectorised environment runs the MuJoCo plant, not plant.kind = '{sc.plant.kind}'"
            )
        if sc.events:
            raise ValueError("the CPU-vectorised environment cannot run scenario events (payloads): use parallel_env")
        if env0._rand and "payload" in env0._rand.ranges:  # drawn payloads are events at t = 0
            raise ValueError("the CPU-vectorised environment cannot run payload events: randomize 'payload' needs "
                             "parallel_env")  # fmt: skip
        env0.reset(seed=0)  # builds the plant: one world, to measure a world's memory before the others
        if not fast_plant(env0):
            raise ValueError(
                "the CPU-vectorised environment cannot run this scenario (it needs sensing = 'truth', no DC-motor "
                "feed, a harmonic disturbance, no per-step faults): use parallel_env"
            )
        per = _world_bytes(env0) + int(T) * ARGS_BYTES  # its own memory, and its PeriodArgs on each thread
        need = W * per
        if max_bytes is None:
            avail = _available_bytes()
            bound = None if avail is None else MEMORY_SHARE * avail
        else:
            bound = float(max_bytes)
        if bound is not None and need > bound:
            raise ValueError(
                f"VectorEnv: {W} worlds need ~{need / 2**30:.2f} GiB ({per / 2**20:.2f} MiB a world on {T} "
                f"threads), over the bound of {bound / 2**30:.2f} GiB: fewer worlds (or threads)"
            )
        self.envs = [env0] + [parallel_env(scenario, **options) for _ in range(W - 1)]
        #: what rebuilds it (pickle, deepcopy: :meth:`__getstate__`)
        opts = dict(max_bytes=max_bytes, warm=warm, pin=pin, **env0._init_kwargs)
        self._init = (env0.base_scenario, W, threads, opts)
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
        self._obs_out = np.zeros((W, n, self.obs_size), dtype=self.dtype)
        self._term = np.zeros(W, dtype=np.bool_)
        self._trunc = np.zeros(W, dtype=np.bool_)
        self._acc_low = np.ascontiguousarray(env0._acc_low, dtype=float)
        self._acc_high = np.ascontiguousarray(env0._acc_high, dtype=float)
        self._w_terminal = float(env0.weights["terminal"])
        self._call: Any = None
        self._check: Any = None
        #: (W,) whether world w's physics steps with the shared model (:meth:`_share_init`) this episode
        self.shared = np.zeros(W, dtype=np.bool_)
        self._share_init(env0)
        self.seeds = np.zeros(W, dtype=np.int64)
        from numba.typed import List

        self._args: Any = List()
        self._blocks = [(W * t // self.threads, W * (t + 1) // self.threads) for t in range(self.threads)]
        self._warm_init(env0, bool(warm))
        self._started = False
        #: the actions of the period being stepped (the period clips them in place)
        self._U = np.zeros((W, n, 2))
        #: the periods stepped since the oldest running episode began: (actions as clipped, running) each, and
        #: the index in it at which each world's episode began (-1: none yet; :data:`ENDED`: its episode ended and
        #: its actions were moved to :attr:`_ended`): what a copy replays (:meth:`_trim` bounds it)
        self._hist: list[tuple[np.ndarray, np.ndarray]] = []
        self._ep_start = np.full(W, -1, dtype=np.int64)
        #: world -> its ended episode's actions (periods, n, 2), for a world that ended and was not reset since
        self._ended: dict[int, np.ndarray] = {}
        #: :meth:`step` trims the history past this many periods (a running episode is at most N periods long)
        self._hist_cap = 2 * int(self.N) + 2
        #: one VecArgs per thread, built at the first step (the worlds' arguments are typed then)
        self._v: Any = None
        #: the team of threads (envs.team): (control array, worker threads, the process id that started them)
        self._team: tuple | None = None
        self._stopper: Any = None
        self._pool: ThreadPoolExecutor | None = None  # where envs.team is not available
        self._spin_ns = SPIN_NS if self.threads <= _usable_cpus() else 0
        self._pin = pin
        self._cpus = sorted(os.sched_getaffinity(0)) if pin else []  # the calling thread's CPUs, before pinning

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
            self._ended.pop(int(w), None)
        self._ep_start[sel] = len(self._hist)
        self._trim()
        self._started = True
        return self._out_obs()

    def _trim(self) -> None:
        """Drop the periods no world's replay needs (:meth:`__setstate__`): a world whose episode ended and was
        not reset has its episode's actions moved to :attr:`_ended` (at most ``N`` periods), so the history
        goes back to the oldest *running* episode's start only: at most ``N`` periods, where a world that ended
        and was never reset kept every later period (one entry a :meth:`step`, without bound). :meth:`step` trims
        past ``2·N + 2`` periods, so with ``n`` followers :attr:`history_bytes` <= ``(3·N + 2)·W·(16·n + 1)``
        bytes (the history's ``2·N + 2`` periods and the ended episodes' ``N`` each; :func:`_world_bytes` counts it
        in the memory estimate)."""
        ep = self._ep_start
        for w in np.flatnonzero((ep >= 0) & ~self.running):
            s = int(ep[w])
            rows = [u[w] for u, r in self._hist[s:] if r[w]]  # its episode: contiguous from its start
            self._ended[int(w)] = np.array(rows).reshape(len(rows), self.n, 2)
            ep[w] = ENDED
        live = ep[ep >= 0]
        drop = int(live.min()) if live.size else len(self._hist)  # periods no running episode needs
        if drop:
            del self._hist[:drop]
            ep[ep >= 0] -= drop

    @property
    def history_bytes(self) -> int:
        """Bytes of what a copy replays (:meth:`_trim`): the periods since the oldest running episode began (each
        ``(W, n, 2)`` actions and ``(W,)`` flags) and the ended episodes' actions."""
        per = self.nworld * (self.n * 2 * 8 + 1)
        return len(self._hist) * per + sum(int(a.nbytes) for a in self._ended.values())

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
        self.shared[w] = self._shares(env)
        model = self._model if self.shared[w] else None
        p = env._plant
        self.warm[w] = self._warmable(env)
        self._own[w] = p.data._address
        self._xmat[w] = p.data.xmat
        warm = None
        if self.warm[w]:
            import mujoco

            mujoco.mj_getState(p.model, p.data, self._X[w], self._sig)
            warm = [(d, v[0], v[1], self._xmat[w]) for d, v in zip(self._wdata, self._wviews)]
        fp = FastPeriod(env, r=self.reward[w], fe=self._fe[w], hits=self._hits[w], model=model,
                        warm=None if warm is None else warm[0])  # fmt: skip
        W = self.nworld
        while len(self._args) < self.threads * W:  # placeholders until each world's first reset
            self._args.append(fp.args)
        for t in range(self.threads):  # any thread may step it (envs.worlds): one PeriodArgs on each one's MjData
            self._args[t * W + w] = fp.args if warm is None or t == 0 else fp.args_on(warm[t])
        env._fastp = fp

    def _share_init(self, env0: FormationParallelEnv) -> None:
        """The one ``MjModel`` the worlds' physics steps with (:attr:`_model`): a copy of world 0's as built
        (its start ``qpos0``, nominal friction). ``mj_step`` only reads a model, and the worlds' models are
        compilations of the same scene, which an episode changes in two places only: the free joints' ``qpos0``
        (the start, :func:`~.randomize.set_start`; ``mj_resetData`` reads it, with the world's own model, and
        the free joints' kinematics do not) and the friction (:func:`~.randomize.scale_friction`). One model
        read by every world stays in the cache, where W copies of it did not (issue 30: W = 32 at 1 ms)."""
        import copy

        import mujoco

        p = env0._plant
        m = self._model = copy.copy(p.model)
        m.qpos0[:] = env0._built_qpos0
        m.geom_friction[:, 0] = env0._nominal_friction[0]
        if m.npair:
            m.pair_friction[:, :2] = env0._nominal_friction[1]
        free = np.zeros(m.nq, dtype=bool)
        for j in np.flatnonzero(m.jnt_type == mujoco.mjtJoint.mjJNT_FREE):
            free[m.jnt_qposadr[j] : m.jnt_qposadr[j] + 7] = True
        self._fixed_q = ~free  # qpos0 entries an episode does not move
        self._model_bytes: np.ndarray | None = None
        self._same_build: dict[int, bool] = {}

    def _shares(self, env: FormationParallelEnv) -> bool:
        """True when world ``env``'s physics is :attr:`_model`'s: its friction and its ``qpos0`` but the free
        joints' equal, and (checked once per world, at its first episode) its model, those fields aside,
        byte for byte the same (``mj_saveModel``). Otherwise the world steps with its own model."""
        import mujoco

        m, s = env._plant.model, self._model
        if not (
            np.array_equal(m.geom_friction, s.geom_friction)
            and np.array_equal(m.pair_friction, s.pair_friction)
            and np.array_equal(m.qpos0[self._fixed_q], s.qpos0[self._fixed_q])
        ):
            return False
        key = id(env)
        if key not in self._same_build:
            if self._model_bytes is None:
                self._model_bytes = np.empty(mujoco.mj_sizeModel(s), dtype=np.uint8)
                mujoco.mj_saveModel(s, None, self._model_bytes)
            q = m.qpos0.copy()
            m.qpos0[:] = s.qpos0
            mine = np.empty(mujoco.mj_sizeModel(m), dtype=np.uint8)
            mujoco.mj_saveModel(m, None, mine)
            m.qpos0[:] = q
            self._same_build[key] = bool(np.array_equal(mine, self._model_bytes))
        return self._same_build[key]

    def _warm_init(self, env0: FormationParallelEnv, on: bool) -> None:
        """One ``MjData`` of :attr:`_model` per thread (:attr:`_wdata`), and each world's MuJoCo state between
        periods (:attr:`_X` (W, ``mj_stateSize(mjSTATE_INTEGRATION)``), the chassis' ``xmat`` rows :attr:`_xmat`).
        At a 1 ms control period a world is visited for one physics step; stepping its own ``MjData`` (the paper's
        scene: 33 KB of buffers and the part of its arena a step uses, read and written by ``mj_step``) brought it
        from memory each visit, where one ``MjData`` per thread stays in the cache and a world's state is 1.8 KB
        (issue 30: W = 32). What the period reads of an ``MjData`` after the step (the contact list,
        ``mj_contactForce``, ``mj_geomDistance``, qpos/qvel, the warning counters) it reads from the thread's
        while that holds the world; ``xmat`` (the disturbance's heading, from the previous step) from the
        world's own rows. A world whose ``MjData`` has other sizes, or a scene that sleeps or has flexes (their
        state is not in that state), steps its own (:meth:`_warmable`)."""
        import mujoco

        from bioform_mj.plants.mujoco.contacts import ContactReader

        W, p, m = self.nworld, env0._plant, self._model
        #: the MuJoCo state a world carries between periods: ``mjSTATE_INTEGRATION`` (time, qpos, qvel, act,
        #: history, plastic and plugin state, the inputs, the solver's warm start: what ``mj_step`` reads of an
        #: ``MjData``, as ``mujoco.rollout`` carries it)
        self._sig = sig = int(mujoco.mjtState.mjSTATE_INTEGRATION)
        self._warm_on = on and not (m.opt.enableflags & int(mujoco.mjtEnableBit.mjENBL_SLEEP)) and m.nflex == 0
        #: (W,) whether world w steps its thread's warm ``MjData`` this episode
        self.warm = np.zeros(W, dtype=np.bool_)
        self._own = np.zeros(W, dtype=np.int64)
        self._X = np.zeros((W, mujoco.mj_stateSize(m, sig)))
        self._xmat = np.zeros((W, m.nbody, 9))
        self._wdata, self._wviews = [], []
        c = p.contacts
        for _ in range(self.threads):
            d = mujoco.MjData(m)
            r = ContactReader(m, d, c.contacts.owner, p.contact_geoms, p._obstacle_geoms, c.proximity.rad,
                              float(c.proximity.ranges[2]), p.control_dt, p._q7[:, 2])  # fmt: skip
            if not np.array_equal(r.contacts.meta, c.contacts.meta):
                self._warm_on = False  # the contact list is not where the worlds' is: each steps its own
            self._wdata.append(d)
            self._wviews.append((r.contacts.ncon, r.contacts.con, d.xmat, d.warning.number))
        self._sizes = (d.nbuffer, d.narena, mujoco.mj_stateSize(m, sig))

    def _warmable(self, env: FormationParallelEnv) -> bool:
        """True when world ``env`` can step its thread's warm ``MjData`` (see :meth:`_warm_init`): warm data on,
        and the world's ``MjData`` and state of the same sizes."""
        import mujoco

        if not self._warm_on:
            return False
        p = env._plant
        return (p.data.nbuffer, p.data.narena, mujoco.mj_stateSize(p.model, self._sig)) == self._sizes

    def world_state(self, w: int, sig: int) -> np.ndarray:
        """World ``w``'s MuJoCo state after its last period, the components ``sig`` in ``mj_getState``'s
        layout (from :attr:`_X` where it steps warm, else from its own ``MjData``)."""
        import mujoco

        p = self.envs[w]._plant
        out = np.empty(mujoco.mj_stateSize(p.model, sig))
        if self.warm[w]:
            mujoco.mj_extractState(p.model, self._X[w], self._sig, out, sig)
        else:
            mujoco.mj_getState(p.model, p.data, out, sig)
        return out

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
        terminated (W,), truncated (W,))``, new arrays each step. ``actions`` (W, n, 2), float32 or float64,
        in the action space of every world's agents (rows of worlds not running are ignored). A world that
        ended stays ended (its rows keep their last values) until :meth:`reset` names it.

        The period's Python is one copy of the actions and one compiled call (:func:`~.worlds.dispatch`: the
        check of the actions, then the worlds' periods and their ends, :func:`~.worlds.periods`), in which the
        calling thread releases the team's threads, steps its block of worlds, claims what the others have not
        yet taken of theirs and waits until every world is done (``envs.team``: no Python, no GIL and, at a
        short period, no sleep between periods): no per-world Python and no numpy reductions unless a world
        warned."""
        if not self._started or not self.running.any():
            raise RuntimeError("step() with no world running: call reset() first")
        U = np.asarray(actions)
        if U.dtype.kind not in "fiu":  # strings, booleans, complex were taken as numbers (issue 28)
            raise ValueError(f"actions must be real numbers, got an array of dtype {U.dtype}")
        if U.shape != (self.nworld, self.n, 2):
            raise ValueError(f"actions must have shape ({self.nworld}, {self.n}, 2), got {U.shape}")
        self._U[...] = U  # a copy: the period clips it in place
        running = self.running.copy()
        if self._v is None:
            self._compile()
        if HAVE_TEAM:
            if (self.threads > 1 or self._pin) and (self._team is None or self._team[2] != os.getpid()):
                self._start_team()
            ctl = self._team[0] if self._team is not None else self._ctl1
            warned = self._dispatch(self._v[0], ctl, self._spin_ns)
        else:  # a thread pool where there are no futexes (envs.team)
            bad = self._check(self._v[0])
            if bad >= 0:
                warned = -(bad + 1)
            else:
                self._start(self._v[0])
                futs = []
                if self.threads > 1:
                    if self._pool is None:
                        self._pool = ThreadPoolExecutor(self.threads - 1)
                    futs = [self._pool.submit(self._block, self._v[t], t) for t in range(1, self.threads)]
                self._block(self._v[0], 0)
                for f in futs:
                    f.result()
                warned = self._count_warned(self._v[0])
        if warned < 0:  # before any world steps: the single environment's message for the first bad world
            bad = -(warned + 1)
            try:
                self.envs[bad]._actions({ag: U[bad, i] for i, ag in enumerate(self.possible_agents)})
            except ValueError as exc:
                raise ValueError(f"world {bad}: {exc}") from exc
        self._hist.append((self._U.copy(), running))
        if len(self._hist) > self._hist_cap:  # worlds ended and not reset: their episodes moved out (bounded)
            self._trim()
        if warned > 0:  # a MuJoCo warning: the single environment's period tail in Python (the state not observed)
            for w in np.flatnonzero(self._status & WARNED):
                self._warned(int(w))
        return self._obs_out.copy(), self.reward.copy(), self._term.copy(), self._trunc.copy()

    def _compile(self) -> None:
        """:class:`~.worlds.VecArgs` of this environment and the specialisations of :func:`~.worlds.dispatch` (or,
        without ``envs.team``, its pieces) and :func:`~.worlds.serve` for its types."""
        from numba.typed import List

        #: (T, 2) each thread's worlds ``lo, hi`` (:attr:`_blocks`)
        self._bounds = np.array(self._blocks, dtype=np.int64)
        wx, ww = List(), List()
        for _cn, _cc, x, n in self._wviews:
            wx.append(x)
            ww.append(n)
        self._claim = claims(self.threads)
        fields = (
            self._args, self._bounds, self._claim, np.array([d._address for d in self._wdata]), wx, ww,
            self._own, self.warm, self._X, self._sig, self._U, self.pose, self.vel, self._new_pose, self._new_vel,
            self.obs, self._obs_out, self.reward, self.k, self._sc, self._status, self.running, self._term,
            self._trunc, int(self.N), float(self.dt), float(self._w_terminal), self._acc_low, self._acc_high,
        )  # fmt: skip
        # one per thread: each unboxes the arrays into reference counts of its own (numba counts a view or a
        # call's array argument on its parent's count, an atomic add), as the thread pool's calls did; one
        # shared by both threads measured no slower (2 threads, 1 ms: 0.55 of mujoco.rollout against 0.51)
        self._v = [make_vargs(*fields) for _ in range(self.threads)]
        v = self._v[0]
        if HAVE_TEAM:
            self._ctl1 = ctl = team_control()  # one thread: no workers to release
            self._dispatch = Compiled(dispatch, (v, ctl, 0)).call
            if self.threads > 1:
                self._serve = Compiled(serve, (v, ctl, 1, np.int32(0), 0)).call
        else:  # a thread pool where there are no futexes (envs.team)
            self._check = Compiled(check, (v,)).call
            self._start = Compiled(start, (v,)).call
            self._block = Compiled(block, (v, 0)).call
            self._count_warned = Compiled(count_warned, (v,)).call

    def _start_team(self) -> None:
        """Start the workers (threads 1 … T−1) of :func:`~.worlds.serve` on a new control array; they are stopped by
        :meth:`close`, or when the environment is collected or the interpreter exits (``weakref.finalize``,
        which holds no reference to the environment). Also in a forked child, where the parent's are gone."""
        if self._stopper is not None:
            self._stopper()
        ctl = team_control()
        cpus: list = self._cpus if self._pin else [None] * self.threads
        caller = None
        if self._pin:
            caller = (threading.get_native_id(), set(cpus))
            os.sched_setaffinity(0, {cpus[0]})
        args = [(cpus[t], self._serve, self._v[t], ctl, t, np.int32(0), self._spin_ns) for t in range(1, self.threads)]
        workers = [threading.Thread(target=_pinned, args=a, daemon=True, name="bioform-vector") for a in args]
        for th in workers:
            th.start()
        self._team = (ctl, workers, os.getpid())
        self._stopper = weakref.finalize(self, _stop_team, ctl, workers, caller)

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
        """The observations in the environment's dtype (a new array)."""
        self._obs_out[...] = self.obs
        return self._obs_out.copy()

    # ------------------------------------------------------------------ pickling and copies
    def __getstate__(self) -> dict[str, Any]:
        """What rebuilds this environment (its MuJoCo models, compiled calls and threads are not picklable):
        its arguments, each world's episode as its seed and the periods stepped since it began (actions as
        clipped, which worlds ran), the worlds' flags and random streams. The copy replays them."""
        rng = [None if e._np_random is None else e._np_random.bit_generator.state for e in self.envs]
        return {
            "init": self._init, "seeds": self.seeds.copy(), "ep_start": self._ep_start.copy(),
            "hist": [(u.copy(), r.copy()) for u, r in self._hist],
            "ended": {w: a.copy() for w, a in self._ended.items()}, "rng": rng, "running": self.running.copy(),
            "term": self._term.copy(), "trunc": self._trunc.copy(), "started": self._started,
        }  # fmt: skip

    def __setstate__(self, st: dict[str, Any]) -> None:
        """Rebuild from :meth:`__getstate__`, then replay: each world's episode reset with its seed where it
        began, the recorded periods stepped (the worlds whose current episode runs in each), so every world
        continues bit for bit (same machine; ``tests/test_envs_training.py``)."""
        scenario, W, T, kw = st["init"]
        self.__init__(scenario, W, T, **kw)
        ep, hist, ended = st["ep_start"], st["hist"], st.get("ended", {})
        if ended:  # the ended episodes first, each world on its own actions (worlds are independent)
            for w in ended:
                self._reset_world(int(w), int(st["seeds"][w]))
            for j in range(max(len(a) for a in ended.values())):
                U = np.zeros((W, self.n, 2))
                self.running[:] = False
                for w, a in ended.items():
                    if j < len(a):
                        U[w] = a[j]
                        self.running[w] = True
                self._started = True
                self.step(U)
        for i in range(len(hist) + 1):
            for w in np.flatnonzero(ep == i):
                self._reset_world(int(w), int(st["seeds"][w]))
            if i < len(hist):
                run = hist[i][1] & (ep >= 0) & (ep <= i)
                if run.any():
                    self.running[:] = run
                    self._started = True
                    self.step(hist[i][0])
        self._hist, self._ep_start = [(u.copy(), r.copy()) for u, r in hist], ep.copy()
        self._ended = {int(w): a.copy() for w, a in ended.items()}
        self.running[:], self._term[:], self._trunc[:] = st["running"], st["term"], st["trunc"]
        for e, state in zip(self.envs, st["rng"]):
            if state is not None:
                e._np_random = np.random.default_rng()
                e._np_random.bit_generator.state = state
        self._started = st["started"]

    def close(self) -> None:
        """Stop and join the threads (the worlds stay: the next :meth:`step` starts them again)."""
        if self._stopper is not None:
            self._stopper()
            self._stopper = self._team = None
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None


def _usable_cpus() -> int:
    """The CPUs this process may run on (``sched_getaffinity`` where there is one)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return os.cpu_count() or 1


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

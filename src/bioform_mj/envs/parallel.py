"""The formation as a PettingZoo ``ParallelEnv`` (design §20; user guide: docs/envs.md).

Agents are the followers ``follower_1 … follower_n``. Each control period (``sim.control_dt``)
every live agent acts; the plant (the scenario's: the ideal unicycle or MuJoCo robots) then
runs its physics substeps in compiled code (``mj_step`` with ``nstep`` for MuJoCo, the RK4
kernel for the ideal plant): the Python boundary is crossed once per control step.

Observation (float64, the layout of :data:`OBS_FIELDS`; local by construction): the agent's
own measured velocities (truth or odometry, as ``plant.sensing`` says), its tracking error
from its *own* estimate of the leader (the paper's distributed estimator, eqs. 12-13, run for
every follower over the communication graph), that estimate's velocities, its in-neighbours'
estimates relative to its own (what the graph delivers; padded to the largest in-degree, with
a presence flag), and the leader's state relative to its estimate only where it has leader
access (``a_ir = 1``; zeros and flag 0 otherwise). No absolute position and no other robot's
pose enter an observation.

Action: ``action = "velocity"`` (default): ``[υ_cmd m/s, ω_cmd rad/s]`` tracked by the paper's
sliding-mode torque law with the scenario's learner (eqs. 37-39; the method's ``-learning``
suffix decides whether ``ĉ`` learns); ``action = "torque"``: wheel torques ``[τ_L, τ_R]`` N·m
within ``±τ_max``. The action space is float32: an action (float32 or float64) within float32
rounding of a bound is taken and clipped onto it; one outside the space by more than that, NaN,
a missing or unknown agent is a ``ValueError`` naming it.

Seeds (Gymnasium's convention): ``reset(seed=s)`` runs the episode of seed ``s`` and reseeds
:attr:`~FormationParallelEnv.np_random`; ``reset()`` draws the next episode's seed from it.
``randomize=`` draws start and domain parameters per episode (:mod:`.randomize`). Pickles and
copies rebuild the plant and replay the episode (bit for bit).

Reward per agent and step (weights in ``reward=``, defaults :data:`REWARD_WEIGHTS`), an integral
over the period so that an episode's return does not depend on the control rate:
``−dt·(w_formation·e_i + w_effort·((τ_L/τ_max)² + (τ_R/τ_max)²)/2) − w_tipped·[i tipped this step]
− w_terminal·(T − t)·[the episode terminated this step]``, with ``e_i`` the true formation error
(m) of follower ``i`` (a training signal may use the truth; observations may not) and ``T − t`` the
time an early end leaves (s): without it, ending the episode by tipping a robot over would pay.
Termination of every agent: a divergence (the run's guards,
``engine.check``, or a MuJoCo warning) or a robot tipped over; truncation at ``sim.duration``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from bioform_mj.core.engine import Bounds, check, describe
from bioform_mj.core.errors import Diverged, InputError
from bioform_mj.envs.fast import fast_plant, fast_step
from bioform_mj.envs.kernels import (
    actions_within,
    clip_into,
    control_phase,
    formation_error,
    sense_errors,
    step_rewards,
)
from bioform_mj.envs.kernels import observations as obs_kernel
from bioform_mj.envs.randomize import MAX_REDRAWS, Randomization, scale_friction, set_start
from bioform_mj.plants.base import RobotModels, Sensing, TipSlipWatch
from bioform_mj.plants.mujoco.contacts import EVENTS as _EVENTS
from bioform_mj.scenario.config import Scenario
from bioform_mj.scenario.loader import load as load_scenario

try:  # the optional extra [rl]
    from gymnasium import spaces
    from pettingzoo import ParallelEnv
except ImportError as exc:  # pragma: no cover - exercised only without the extra
    raise ImportError(
        "bioform_mj.envs needs the optional extra 'rl': pip install -e '.[rl]' (gymnasium, pettingzoo)"
    ) from exc

#: named observation layout: (field, width, unit, meaning); a field of width ``K·w`` repeats per neighbour slot
OBS_FIELDS: tuple[tuple[str, str, str, str], ...] = (
    ("vel", "2", "m/s, rad/s", "own measured body-frame velocities [υ, ω]"),
    ("slot_error", "3", "m, m, rad", "tracking error [x̃, ỹ, θ̃] to the own slot (body frame, own leader estimate)"),
    ("leader_estimate_vel", "2", "m/s, rad/s", "the own estimate of the leader's velocities [υ_ir, ω_ir]"),
    (
        "neighbours",
        "6·K",
        "-, m, m, rad, m/s, rad/s",
        "per in-neighbour slot: [present, Δx, Δy (own body frame), Δθ, Δυ, Δω] of its leader estimate minus the own",
    ),
    ("leader", "6", "-, m, m, rad, m/s, rad/s", "[access, Δx, Δy, Δθ, Δυ, Δω] of the leader minus the own estimate"),
)

#: reward weights: formation error (1/(m·s)), torque effort (1/s), a tip-over (per event), an early end (1/s),
#: a contact with another robot or an obstacle (per contact event of the plant's watch, design §19)
REWARD_WEIGHTS: dict[str, float] = {
    "formation": 1.0,
    "effort": 0.01,
    "tipped": 10.0,
    "terminal": 10.0,
    "collision": 1.0,
}

ACTIONS = ("velocity", "torque")


def as_numbers(x: np.ndarray, what: str) -> np.ndarray:
    """``x`` as float64, refused (``TypeError``) unless its numbers are real numbers: strings (``"1"``), booleans,
    complex and object arrays were taken (``np.array(..., dtype=float)`` converts them; issue 28)."""
    if x.dtype.kind not in "fiu":
        raise TypeError(f"{what} must be real numbers, got an array of dtype {x.dtype}")
    return x.astype(float, copy=False)


def _scenario_of(scenario: str | Path | Scenario, overrides: Any = None) -> Scenario:
    if isinstance(scenario, Scenario):
        if overrides:
            raise ValueError("overrides= needs a preset name or TOML path, not a Scenario object")
        from bioform_mj.scenario.loader import checked

        return checked(scenario)  # as simulate: a Scenario changed in Python is checked as load checks a file
    return load_scenario(scenario, overrides)


class FormationParallelEnv(ParallelEnv):
    """``n`` followers of a scenario as PettingZoo agents (see the module docstring for the contract).

    Parameters
    ----------
    scenario : a preset name, a TOML path or a :class:`~bioform_mj.scenario.config.Scenario`.
    action : ``"velocity"`` or ``"torque"``.
    reward : weights overriding :data:`REWARD_WEIGHTS` (unknown names are refused).
    v_max, w_max : bounds of the velocity action (m/s, rad/s); default ``limits.speed`` bounded to 2 m/s,
        and 2π rad/s.
    overrides : ``--set``-style overrides (``["sim.control_dt=0.01"]`` or a mapping), with a name/path.
    dtype : ``"float64"`` (default: the controller's own numbers) or ``"float32"`` observations (what most
        learning libraries' networks take; BenchMARL, SB3).
    randomize : start and domain randomisation ``{key: (low, high)}`` drawn per episode
        (:mod:`~bioform_mj.envs.randomize`; units there); None: the scenario's own start.
    max_cycles : control steps per episode (truncation); default ``sim.duration / sim.control_dt``.
    render_mode : None, ``"rgb_array"`` (:meth:`render` returns the frame of ``bioform run --video``) or
        ``"human"`` (every ``reset`` and ``step`` shows that frame in a matplotlib window; :meth:`render` too).
    """

    metadata = {
        "name": "bioform_formation_v0",
        "render_modes": ["rgb_array", "human"],
        "is_parallelizable": True,
        "render_fps": 30,
    }

    def __init__(
        self,
        scenario: str | Path | Scenario = "paper",
        *,
        action: str = "velocity",
        reward: Mapping[str, float] | None = None,
        v_max: float | None = None,
        w_max: float | None = None,
        overrides: Any = None,
        dtype: str = "float64",
        randomize: Mapping[str, Any] | None = None,
        max_cycles: int | None = None,
        render_mode: str | None = None,
    ) -> None:
        if action not in ACTIONS:
            raise ValueError(f"unknown action mode {action!r} (expected one of: {', '.join(ACTIONS)})")
        if dtype not in ("float64", "float32"):
            raise ValueError(f"unknown observation dtype {dtype!r} (expected float64 or float32)")
        self._dtype = np.dtype(dtype)
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"unknown render_mode {render_mode!r} (expected None or one of: rgb_array, human)")
        if max_cycles is not None:
            if isinstance(max_cycles, bool) or not isinstance(max_cycles, (int, np.integer)) or max_cycles < 1:
                raise ValueError(f"max_cycles must be a positive integer (control steps), got {max_cycles!r}")
            max_cycles = int(max_cycles)
        self._max_cycles = max_cycles
        sc = _scenario_of(scenario, overrides)
        weights = dict(REWARD_WEIGHTS)
        for k, v in (reward or {}).items():
            if k not in weights:
                raise ValueError(f"unknown reward term {k!r} (expected one of: {', '.join(weights)})")
            if not math.isfinite(float(v)):
                raise ValueError(f"reward weight {k!r} must be finite, got {v!r}")
            weights[k] = float(v)
        self.base_scenario = sc
        self.action_mode = action
        self.weights = weights
        self.n = sc.n
        self.possible_agents = [f"follower_{i + 1}" for i in range(sc.n)]
        self.agents: list[str] = []
        self._index = {a: i for i, a in enumerate(self.possible_agents)}
        self.render_mode = render_mode
        self._renderer = None
        graph = sc.build_graph()
        self.graph = graph
        src, dst = np.asarray(graph.src), np.asarray(graph.dst)
        self._nbrs = [dst[src == i].tolist() for i in range(sc.n)]
        self._nbr_edges = [np.flatnonzero(src == i).tolist() for i in range(sc.n)]
        self.K = max(1, max(len(x) for x in self._nbrs))
        self.obs_size = 2 + 3 + 2 + 6 * self.K + 6
        self._slots = np.full((sc.n, self.K), -1, dtype=np.int64)  # in-neighbour slot -> edge index (or -1)
        for i, edges in enumerate(self._nbr_edges):
            self._slots[i, : len(edges)] = edges
        self._ones_e = np.ones(len(graph.src))
        self._zeros_n = np.zeros(sc.n)
        self._lacc = np.asarray(graph.leader_access, dtype=float)
        self._off = np.asarray(sc.formation.offsets, dtype=float).reshape(sc.n, 2)
        self._leader_frame = sc.formation.frame == "leader"
        self._plant = None
        self._models = self._tip_watch = False  # its capabilities (set when it is built)
        self._built_sc: Scenario | None = None  # the scenario the plant was built from (its start poses)
        self._sc = sc
        self._build_time_axis(sc)
        self._rand = Randomization(randomize, sc, self.N * self.dt)
        self._init_kwargs = dict(
            action=action, reward=dict(reward or {}), v_max=v_max, w_max=w_max, dtype=dtype,
            randomize=None if randomize is None else {k: tuple(v) for k, v in randomize.items()},
            max_cycles=max_cycles, render_mode=render_mode,
        )  # fmt: skip
        self._np_random: np.random.Generator | None = None
        self._episode_seed: int | None = None
        self._log: list[np.ndarray] = []
        self.metadata = {**type(self).metadata, "render_fps": 30}
        self._build_stack(sc, plant_c_true=None)
        tau_max = np.broadcast_to(np.asarray(self._stack.p.tau_max, dtype=float), (sc.n,))
        vm = float(min(sc.limits.speed, 2.0)) if v_max is None else float(v_max)
        wm = float(2 * math.pi) if w_max is None else float(w_max)
        if not (vm > 0 and wm > 0 and math.isfinite(vm) and math.isfinite(wm)):
            raise ValueError(f"v_max and w_max must be positive and finite, got {vm!r}, {wm!r}")
        # finite bounds (checkers warn on infinite ones): nothing a run the guards let go on can reach
        pos_lim, spd = float(sc.limits.position), float(sc.limits.speed)
        off = float(np.max(np.abs(np.asarray(sc.formation.offsets, dtype=float)), initial=0.0))
        self.obs_bound = 2.0 * (pos_lim + spd) + off
        hi_obs = np.full(self.obs_size, self.obs_bound, dtype=self._dtype)
        self._obs_spaces = {a: spaces.Box(-hi_obs, hi_obs, dtype=self._dtype) for a in self.possible_agents}
        self._state_hi = np.concatenate([np.tile([pos_lim, pos_lim, math.pi], sc.n), np.full(2 * sc.n, spd)])
        shi = self._state_hi.astype(self._dtype)
        self.state_space = spaces.Box(-shi, shi, dtype=self._dtype)
        if action == "velocity":
            hi = np.tile([vm, wm], (sc.n, 1))
        else:
            hi = np.repeat(tau_max[:, None], 2, axis=1)
        # float32, what trainers' networks give; a float64 action within float32 rounding of a bound is taken
        self._act_spaces = {
            a: spaces.Box(-hi[i].astype(np.float32), hi[i].astype(np.float32), dtype=np.float32)
            for a, i in self._index.items()
        }
        self._low, self._high = -hi, hi  # the bounds themselves (float64): an accepted action is clipped to them
        hi32 = hi.astype(np.float32).astype(float)
        self._acc_high = np.maximum(hi, hi32)
        self._acc_low = -self._acc_high
        self._done = True

    # ------------------------------------------------------------------ spaces
    # one space object per agent, as PettingZoo asks: the dicts built once hold them (a functools.cache on
    # these methods kept every environment alive through its cache, issue 28)
    def observation_space(self, agent: str) -> spaces.Box:
        """The observation space of ``agent`` (the same object every call)."""
        self._check_agent(agent)
        return self._obs_spaces[agent]

    def action_space(self, agent: str) -> spaces.Box:
        """The action space of ``agent`` (the same object every call)."""
        self._check_agent(agent)
        return self._act_spaces[agent]

    def _check_agent(self, agent: str) -> None:
        if agent not in self._index:
            raise ValueError(f"unknown agent {agent!r} (agents: {', '.join(self.possible_agents)})")

    # ------------------------------------------------------------------ set-up
    def _build_time_axis(self, sc: Scenario) -> None:
        dt = sc.sim.control_dt
        self.dt = dt
        self.N = self._max_cycles or max(1, int(round(sc.sim.duration / dt)))
        self.stride = max(1, int(round(sc.sim.log_dt / dt)))
        t_all = np.arange(self.N + 1) * dt
        lp, lv, _ = sc.build_leader().states(t_all)
        self.L_pose = np.ascontiguousarray(lp, dtype=float)
        self.L_vel = np.ascontiguousarray(lv, dtype=float)

    def _build_stack(self, sc: Scenario, plant_c_true: np.ndarray | None) -> None:
        import bioform_mj.run  # noqa: F401  (registers the opt-in gain sizing with stack_params, design §14.4)
        from bioform_mj.control.base import TorqueLimited
        from bioform_mj.control.params import stack_params
        from bioform_mj.control.stack import ControlStack

        c = np.array(sc.plant.c_true, dtype=float)[None, :].repeat(sc.n, 0) if plant_c_true is None else plant_c_true
        tau_max = self._plant.tau_max if isinstance(self._plant, TorqueLimited) else None
        self._stack = ControlStack(self.graph, stack_params(sc, c, tau_max))

    def _build_plant(self, sc: Scenario) -> None:
        """Build the scenario's plant at ``sc``'s initial poses and the control stack for its nominal
        ``c_true`` (the learner's prior in every episode: randomised parameters are not told to it)."""
        from bioform_mj.core.errors import InputError
        from bioform_mj.run.simulate import make_plant

        try:
            self._plant = make_plant(sc)
        except InputError as exc:
            raise ValueError(str(exc)) from exc
        self._built_sc = sc
        self._built_poses = np.array(sc.initial_poses(), dtype=float)
        self.nominal_c_true = np.ascontiguousarray(self._plant.c_true(), dtype=float)
        # what the plant offers, by its capabilities (plants/base.py), never by its kind: robots from model files
        # (a MuJoCo scene, compiled once and moved to each start), a tilt watch (design §22)
        self._models = isinstance(self._plant, RobotModels)
        self._tip_watch = isinstance(self._plant, TipSlipWatch)
        if self._models:
            m = self._plant.model
            self._built_qpos0 = m.qpos0.copy()
            self._nominal_friction = (m.geom_friction[:, 0].copy(), m.pair_friction[:, :2].copy())
        self._build_stack(sc, self.nominal_c_true)

    def _plant_for(self, sc: Scenario, poses: np.ndarray, draws: Mapping[str, np.ndarray]):
        """The plant of the episode scenario ``sc`` starting at ``poses`` (n, 3). The ideal plant is
        built anew (microseconds); a MuJoCo scene is compiled once, at the scenario's initial poses
        as written, its robots then moved to each episode's start in ``qpos0``
        (:func:`~.randomize.set_start`; no recompilation, 0.2 s saved per reset): an episode depends
        on its seed alone, not on the episodes before it. A start other than the written one equals a
        fresh build of it (``bioform run``) within rounding, not bit for bit."""
        from bioform_mj.run.simulate import make_plant

        if self._plant is None:  # at the scenario's poses as written: every start is moved from the same build
            b = self.base_scenario
            self._build_plant(
                dataclasses.replace(
                    b, formation=dataclasses.replace(b.formation, init_jitter=0.0, init_jitter_heading=-1.0)
                )
            )
        if not self._models:  # a plant without robot models (the ideal plant): built anew for the episode
            self._plant = make_plant(sc)
            if "c_true" in draws:
                self._plant._c *= draws["c_true"]
            return self._plant
        p = self._plant
        set_start(p, poses, self._built_poses, self._built_qpos0)
        if "friction" in draws:
            scale_friction(p, float(draws["friction"]), self._nominal_friction)
        if p.sensors.on:  # the gyro noise of this episode's seed (a counter hash: no state)
            p.sensors = p.sensors._replace(
                seed=float(sc.sim.seed % 2147483647), sigma=float(sc.plant.gyro_noise), bias=float(sc.plant.gyro_bias)
            )
        return p

    @property
    def np_random(self) -> np.random.Generator:
        """The environment's random stream (Gymnasium's convention): seeded by ``reset(seed=s)``, it
        draws the seed of every episode that ``reset()`` starts without one."""
        if self._np_random is None:
            self._np_random = np.random.default_rng(int(self.base_scenario.sim.seed))
        return self._np_random

    @property
    def episode_scenario(self) -> Scenario:
        """The scenario of the current episode: its seed, start poses and drawn scenario keys
        (``bioform run`` of it starts the same episode, but for drawn ``c_true`` and ``friction``)."""
        return self._sc

    @property
    def episode_parameters(self) -> dict[str, Any]:
        """The current episode's seed and randomised values (:meth:`~.randomize.Randomization.draw`)."""
        return {"seed": self._episode_seed, **{k: np.array(v) for k, v in self._draws.items()}}

    # ------------------------------------------------------------------ PettingZoo API
    def reset(self, seed: int | None = None, options: Mapping[str, Any] | None = None):
        """Start an episode; returns ``(observations, infos)``. ``seed`` (>= 0) is the episode's seed
        (``sim.seed``: the scenario's jitter, every fault draw, the randomisation) and reseeds the
        environment's random stream (:attr:`np_random`); ``seed=None`` draws the next episode's seed
        from that stream (the first time: seeded by the scenario's ``sim.seed``), as Gymnasium's
        environments do: auto-resets explore, and the whole sequence is reproducible from the first seed."""
        if seed is not None:
            if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or int(seed) < 0:
                raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
            ep = int(seed)
            self._np_random = np.random.default_rng(ep)
        elif self._np_random is None:
            ep = int(self.base_scenario.sim.seed)
            self._np_random = np.random.default_rng(ep)
        else:
            ep = int(self._np_random.integers(0, 2**31 - 1))
        self._start(ep)
        self._log = []
        obs = self._observations()
        if self.render_mode == "human":
            self.render()
        return obs, {a: {"t": 0.0, "seed": ep} for a in self.agents}

    def _start(self, ep: int) -> None:
        """Everything of ``reset`` but the random stream: the episode of seed ``ep``."""
        from bioform_mj.run.simulate import initial_estimates

        base = self.base_scenario
        sc = base if ep == base.sim.seed else dataclasses.replace(base, sim=dataclasses.replace(base.sim, seed=ep))
        rz = self._rand
        draws: dict[str, np.ndarray] = {}
        poses = Randomization.start_poses(sc, draws)
        sc_ep = sc
        for attempt in range(MAX_REDRAWS):
            if rz:
                draws = rz.draw(ep, self.n, attempt)
                poses = Randomization.start_poses(sc, draws)
                sc_ep = rz.scenario(sc, draws, poses)
            plant = self._plant_for(sc_ep, poses, draws)
            if not (rz and ("position" in draws or "heading" in draws)) or not self._models:
                break
            if not plant.start_overlaps():
                break
        else:
            raise ValueError(
                f"randomize: {MAX_REDRAWS} draws of the start positions all overlap robots or obstacles (seed {ep}): "
                "narrow 'position'/'heading' or spread the formation"
            )
        sc = sc_ep
        self._sc, self._draws, self._episode_seed = sc, draws, ep
        if any(k.startswith("leader.") for k in draws):
            self._build_time_axis(sc)
        plant.reset()
        self._odometry = isinstance(plant, Sensing) and plant.sensing == "odometry"
        self._lim = Bounds(float(sc.limits.position), float(sc.limits.speed), float(sc.limits.torque))
        self._diag = np.zeros(3)
        self.k = 0
        pose, vel = plant.observe()
        self._pose, self._vel = pose, vel
        st = self._stack
        g, s = st.kernel
        self._g, self._s = g, s
        self._tau_max = np.broadcast_to(np.asarray(st.p.tau_max, dtype=float), (self.n,))
        self._faults = None
        if sc.faults.per_step:  # faults.py: the same Faults object, in the same order, as bioform run
            from bioform_mj.run.faults import Faults

            self._faults = Faults(sc, self.graph, np.array(self._tau_max))
            st.set_tau_max(np.array(self._tau_max))
        st.reset(initial_estimates(sc, pose, self.L_pose[0]), vel)  # the truth, as sim.simulate does
        self._sense_phase(0, learn=False)
        self._stats_reset()
        self.agents = list(self.possible_agents)
        self._done = False
        self._diverged = None
        self._tipped = np.zeros(self.n, dtype=bool)
        self._any_tipped = False
        self._events_seen = np.zeros(self.n)
        self._fast_ok, self._fastp = fast_plant(self), None  # envs/fast.py: the period as one compiled call
        if self._renderer is not None:
            self._renderer.new_episode(self)

    def _raw_measurement(self) -> tuple[np.ndarray, np.ndarray]:
        """The sensors' pose and velocity now (odometry where ``plant.sensing`` says), before fault noise."""
        if self._odometry:
            return self._plant.measurement(self._pose, self._vel)
        return self._pose, self._vel

    def _measure(self) -> tuple[np.ndarray, np.ndarray]:
        """What the followers measure at this control step (with the faults' noise): cached per step."""
        return self._mp, self._mv

    def _sense_phase(self, k: int, learn: bool) -> None:
        """Control step ``k``'s inputs, in ``Faults.step``'s order: actuator limits and pushes at ``t_k``,
        the measurement (noise), the network (link weights, held or delayed neighbour estimates, the
        leader as received); then the learner, the consensus and the tracking errors (``sense_errors``)."""
        t = k * self.dt
        mp, mv = self._raw_measurement()
        lp, lv = self.L_pose[k], self.L_vel[k]
        f, st = self._faults, self._stack
        comm = None
        if f is not None:
            if f.has_act:
                f.actuate(t, st)
            while f._push_i < len(f._pushes) and f._pushes[f._push_i][1] <= t + 1e-12:
                i, t0, dur, fx, fy, tz = f._pushes[f._push_i]
                self._plant.push(int(i) - 1, (fx, fy), tz, t0 + dur)
                f._push_i += 1
            if f.has_noise:
                mp, mv = f.sense(k, t, mp, mv)
            if f.has_comm:
                comm, lp, lv = f.comm(k, t, st.state.est_pose, st.state.est_vel, lp, lv)
        if f is None:  # fresh arrays of observe() and read-only rows of the leader's trajectory: no copies
            self._mp, self._mv, self._lp_rx, self._lv_rx = mp, mv, lp, lv
        else:
            self._mp, self._mv = np.array(mp, dtype=float), np.array(mv, dtype=float)
            self._lp_rx, self._lv_rx = np.array(lp, dtype=float), np.array(lv, dtype=float)
        self._comm = comm
        self._comm_in = st.comm_in(comm)
        sense_errors(self._g, self._s, self._lp_rx, self._lv_rx, self._mp, self._mv, self._comm_in, learn)

    def step(self, actions: Mapping[str, Any]):
        """One control period for every live agent. Returns ``(obs, rewards, terminations, truncations, infos)``."""
        if self._done:
            raise RuntimeError("step() after the episode ended: call reset() first")
        out = fast_step(self, actions) if self._fast_ok else None  # one compiled call (envs/fast.py)
        if out is None:
            u = self._actions(actions)
            self._log.append(u)
            out = self._outputs(*self._advance(u))
        if self.render_mode == "human":
            self.render()
        return out

    def _outputs(self, r, end, trunc, diverged, hits, agents, O=None):
        """``step``'s five dicts from :meth:`_advance`'s results (``O``: the observations, computed here if None)."""
        if diverged is not None:
            obs = {a: np.zeros(self.obs_size, self._dtype) for a in agents}
        elif O is None:
            obs = self._observations(agents)
        else:
            if self._dtype != O.dtype:
                O = O.astype(self._dtype)
            obs = {a: O[self._index[a]] for a in agents}
        info = {"t": self.k * self.dt}
        if diverged is not None:
            info["diverged"] = diverged
        if self._any_tipped:
            info["tipped"] = [self.possible_agents[i] for i in np.flatnonzero(self._tipped)]
        if hits.any():
            info["collided"] = [self.possible_agents[i] for i in np.flatnonzero(hits)]
        rewards = {a: float(r[self._index[a]]) for a in agents}
        terms = dict.fromkeys(agents, end)
        truncs = dict.fromkeys(agents, trunc)
        infos = {a: dict(info) for a in agents}
        return obs, rewards, terms, truncs, infos

    def _advance(self, u: np.ndarray) -> tuple[np.ndarray, bool, bool, str | None, np.ndarray, list[str]]:
        """The control period of the checked actions ``u`` (n, 2): ``(rewards (n,), terminated, truncated,
        divergence or None, new contact events (n,), the agents that acted)``; what a copy replays."""
        g, s, k = self._g, self._s, self.k
        mp, mv = self._measure()
        tau = np.empty((self.n, 2))
        control_phase(g, s, mv, u, self.action_mode == "velocity", self._verr, self._vel, tau)
        if self._faults is not None and self._faults._lim is not None:  # weakened motors deliver no more
            tau = np.clip(tau, -self._faults._lim, self._faults._lim)
        diverged = None
        try:
            self._events(k)
            self._plant.step(tau, k * self.dt)
            self._pose, self._vel = self._plant.observe()
        except Diverged as e:
            diverged = str(e)
        return self._advance_tail(tau, diverged)

    def _advance_tail(self, tau: np.ndarray, diverged: str | None):
        """:meth:`_advance` after the plant's step (``diverged``: its MuJoCo warning, or None)."""
        s, k = self._s, self.k
        self.k = k = k + 1
        self._sense_phase(k, learn=True)
        if diverged is None and not check(s, self._pose, self._vel, self._lim, self._diag):
            diverged = describe(self._diag, k * self.dt, self._lim)
        fe = self._formation_error(k)
        self._stats_sample(k, fe)
        tip = self._plant.tip_step if self._tip_watch else None
        newly = self._zeros_n
        if tip is not None and tip.max() >= 0:
            newly = ((tip >= 0) & ~self._tipped).astype(float)
            self._tipped |= newly > 0
            self._any_tipped = bool(self._tipped.any())
        w = self.weights
        end = diverged is not None or self._any_tipped
        hits = self._new_contacts()
        r = np.empty(self.n)
        step_rewards(fe, tau, self._tau_max, newly, hits, w["formation"], w["effort"], w["tipped"],
                     w["collision"], self.dt, r)  # fmt: skip
        if end:
            r = r - w["terminal"] * max(0.0, (self.N - k) * self.dt)
        trunc = k >= self.N and not end
        agents = self.agents
        if end or trunc:
            self._done = True
            self._diverged = diverged
            self.agents = []
        return r, end, trunc, diverged, hits, agents

    def _new_contacts(self) -> np.ndarray:
        """Contact events (robots and obstacles) of each follower in the period just ended (n,), from the
        plant's contact watch (MuJoCo, design §19; zeros for a plant without one)."""
        if not hasattr(self._plant, "contacts"):
            return self._zeros_n
        ev = self._plant.contacts.contacts.ci[:, :, _EVENTS].sum(axis=1).astype(float)  # since the plant's reset
        new, self._events_seen = ev - self._events_seen, ev
        return new

    def _actions(self, actions: Mapping[str, Any]) -> np.ndarray:
        if not isinstance(actions, Mapping):
            raise ValueError(f"actions must be a dict {{agent: action}}, got {type(actions).__name__}")
        for a in actions:
            if a not in self._index:
                raise ValueError(f"unknown agent {a!r} in actions (agents: {', '.join(self.possible_agents)})")
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise ValueError(f"no action for live agent(s) {', '.join(missing)}")
        try:
            u = as_numbers(np.array([actions[a] for a in self.possible_agents]), "actions")
            if u.shape == (self.n, 2) and actions_within(u, self._acc_low, self._acc_high):  # the usual case
                return clip_into(u, self._low, self._high)
        except (ValueError, TypeError) as exc:  # ragged or non-numeric: find which agent
            for a in self.possible_agents:
                x = np.asarray(actions[a])
                if x.shape != (2,) or x.dtype.kind not in "fiu":
                    raise ValueError(f"action of {a} must be 2 numbers, got {actions[a]!r}") from exc
            raise ValueError(f"actions could not be read as numbers: {exc}") from exc
        if u.shape != (self.n, 2):
            for a in self.possible_agents:
                if np.shape(actions[a]) != (2,):
                    raise ValueError(f"action of {a} must have shape (2,), got {np.shape(actions[a])}")
        bad = ~np.isfinite(u).all(axis=1) | (u < self._acc_low).any(axis=1) | (u > self._acc_high).any(axis=1)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            a = self.possible_agents[i]
            what = "is not finite" if not np.isfinite(u[i]).all() else "is outside the action space"
            bounds = f"[{self._low[i].tolist()}, {self._high[i].tolist()}]"
            raise ValueError(f"action of {a} {u[i].tolist()} {what} {bounds}")
        return np.clip(u, self._low, self._high)  # within float32 rounding of a bound: onto it

    def _events(self, k: int) -> None:
        from bioform_mj.run.loop import EventQueue

        if k == 0:
            self._evq = EventQueue(self._sc.events, self.dt)
            self._ev_next = self._evq.next_step()
        if self._ev_next is not None and k >= self._ev_next:
            self._evq.apply(k, self._plant)
            self._ev_next = self._evq.next_step()  # a payload: c_true changes, the learner is not told

    # ------------------------------------------------------------------ observations
    def _observations(self, agents: list[str] | None = None) -> dict[str, np.ndarray]:
        s, comm = self._s, self._comm
        mp, mv = self._measure()
        lp, lv = self._lp_rx, self._lv_rx  # the leader as this step's network delivers it
        lacc = self._lacc
        if comm is not None:
            lacc = lacc * np.asarray(comm.leader_w, dtype=float)
        rp = s.est_pose[self.graph.dst] if comm is None or comm.recv_pose is None else comm.recv_pose
        rv = s.est_vel[self.graph.dst] if comm is None or comm.recv_vel is None else comm.recv_vel
        ew = self._ones_e if comm is None else np.asarray(comm.edge_w, dtype=float)
        O = np.zeros((self.n, self.obs_size))  # a new array each step: the agents' rows are views of it
        obs_kernel(O, mp, mv, s.err, s.est_pose, s.est_vel, self._slots, ew, rp, rv, lacc, lp, lv, self.obs_bound)
        if self._dtype != O.dtype:
            O = O.astype(self._dtype)
        idx = self._index
        return {a: O[idx[a]] for a in (self.agents if agents is None else agents)}

    def _formation_error(self, k: int) -> np.ndarray:
        """True formation error (n,) m at control step ``k`` (the arithmetic of ``slots_of`` and ``np.hypot``)."""
        out = np.empty(self.n)
        formation_error(self._pose, self.L_pose[k], self._off, self._leader_frame, out)
        return out

    # ------------------------------------------------------------------ episode statistics
    def _stats_reset(self) -> None:
        self._verr = np.zeros(self.n)
        self._rows_t: list[float] = []
        self._rows_fe: list[np.ndarray] = []
        self._rows_vel: list[np.ndarray] = []
        self._stats_sample(0, self._formation_error(0))

    def _stats_sample(self, k: int, fe: np.ndarray) -> None:
        if k % self.stride == 0 and k < self.N:
            self._rows_t.append(k * self.dt)
            self._rows_fe.append(fe.copy())
            self._rows_vel.append(self._vel.copy())

    def leader_state(self) -> tuple[np.ndarray, np.ndarray]:
        """The virtual leader's pose (3,) and velocities (2,) now, as this step's network delivers them
        (faults: delayed or held): for baselines that read the leader where the graph gives access
        (:class:`ControllerPolicy`); an observation holds it only for followers with access."""
        return self._lp_rx, self._lv_rx

    def network(self):
        """This step's :class:`~bioform_mj.control.base.Comm` (None: the paper's perfect network)."""
        return self._comm

    def measured_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Every follower's measured pose (n, 3) and velocity (n, 2) now (what a ``Controller`` reads)."""
        mp, mv = self._measure()
        return mp.copy(), mv.copy()

    def episode_summary(self, controller: Any = None) -> dict[str, Any]:
        """Per follower the run metrics of ``bioform run``'s ``summary.json`` for this episode so far:
        ``total_velocity_error`` (Table I's metric), ``final_formation_error_m``, ``rms_formation_error_m``,
        ``c_hat``, ``outcome`` and every outcome in ``outcomes`` (``sim.follower_outcomes``)."""
        from bioform_mj.assess.outcomes import follower_outcomes

        sc, n = self._sc, self.n
        fe_rows = np.array(self._rows_fe).reshape(-1, n)
        logd = {
            "t": np.array(self._rows_t),
            "vel": np.array(self._rows_vel).reshape(-1, n, 2),
            "formation_error": fe_rows,
        }
        final = self._formation_error(self.k)
        c_hat = np.array(self._s.c_hat)
        sig = controller.signals() if controller is not None and hasattr(controller, "signals") else {}
        if sig.get("c_hat") is not None:  # the controller's own learner, not the environment's
            c_hat = np.array(sig["c_hat"], dtype=float)
        from bioform_mj.assess.outcomes import severity
        from bioform_mj.run.summary import contact_outcomes

        ctrl = controller if controller is not None else self._stack
        oc = follower_outcomes(sc, self._plant, ctrl, logd, final, c_hat, self.dt)
        contact = contact_outcomes(self._plant, n, self.dt)
        oc = [sorted(o + contact[i][1], key=severity) for i, o in enumerate(oc)]

        followers = []
        for i in range(n):
            o = oc[i]
            followers.append(
                {
                    "id": i + 1,
                    "total_velocity_error": float(self._verr[i] * self.dt),
                    "final_formation_error_m": float(final[i]),
                    "rms_formation_error_m": float(np.sqrt(np.mean(fe_rows[:, i] ** 2))) if len(fe_rows) else math.nan,
                    "c_hat": [float(v) for v in c_hat[i]],
                    "outcome": o[0]["kind"] if o else "ok",  # the most severe (sim.outcome_list's order)
                    "outcomes": o,
                }
            )
        return {
            "scenario": sc.name,
            "seed": sc.sim.seed,
            "steps": self.k,
            "diverged": getattr(self, "_diverged", None),
            "followers": followers,
        }

    def state(self) -> np.ndarray:
        """The global state (for centralised critics), :attr:`state_space`: every follower's true pose
        ``[x m, y m, θ rad]`` then every velocity ``[υ m/s, ω rad/s]``, (n·5,) in the observations'
        dtype; within ``±limits.position``, ``±π``, ``±limits.speed`` (beyond them the guards end the
        episode; the last state is clipped to the space)."""
        if not hasattr(self, "_pose"):
            raise RuntimeError("state() before reset(): call reset() first")
        x = np.concatenate([self._pose.ravel(), self._vel.ravel()])
        return np.clip(np.nan_to_num(x), -self._state_hi, self._state_hi).astype(self._dtype)

    def render(self) -> np.ndarray | None:
        """The current frame, ``(height, width, 3)`` uint8, with ``render_mode = "rgb_array"``: the
        renderer of ``bioform run --video`` (:mod:`~bioform_mj.envs.render`; needs off-screen OpenGL,
        ``MUJOCO_GL=egl`` or ``osmesa``). ``"human"``: that frame shown in a window, None returned."""
        if self.render_mode is None:
            raise RuntimeError(
                "render() needs a render mode: build the environment with render_mode='rgb_array' "
                "(parallel_env(..., render_mode='rgb_array'))"
            )
        if not hasattr(self, "_pose"):
            raise RuntimeError("render() before reset(): call reset() first")
        if self._renderer is None:
            from bioform_mj.envs.render import EnvRenderer

            self._renderer = EnvRenderer(self, window=self.render_mode == "human")
        return self._renderer.show(self)

    def close(self) -> None:
        """Free the renderer's OpenGL context (the plant is kept: a closed environment may be reset again)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # ------------------------------------------------------------------ pickling and copies
    def __getstate__(self) -> dict[str, Any]:
        """What rebuilds this environment in another process (MjSpec and compiled objects are not
        picklable): its scenario and options, the scenario its plant was built from, the random
        stream, and the current episode as its seed and the checked actions so far (replayed)."""
        return {
            "scenario": self.base_scenario,
            "kwargs": self._init_kwargs,
            "built": self._built_sc,
            "rng": None if self._np_random is None else self._np_random.bit_generator.state,
            "episode": self._episode_seed if hasattr(self, "_pose") else None,
            "log": [u.copy() for u in self._log],
        }

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Rebuild from :meth:`__getstate__`: the same plant, then the episode replayed action by
        action; the copy continues it bit for bit (same machine; ``tests/test_envs_training.py``)."""
        self.__init__(state["scenario"], **state["kwargs"])
        if state["built"] is not None:
            self._build_plant(state["built"])
        if state["episode"] is not None:
            self._start(state["episode"])
            for u in state["log"]:
                self._log.append(u)
                self._advance(u)
        if state["rng"] is not None:
            self._np_random = np.random.default_rng()
            self._np_random.bit_generator.state = state["rng"]


def parallel_env(scenario: str | Path | Scenario = "paper", **options: Any) -> FormationParallelEnv:
    """The formation of ``scenario`` as a PettingZoo ``ParallelEnv`` (``options``: :class:`FormationParallelEnv`)."""
    try:
        return FormationParallelEnv(scenario, **options)
    except InputError as exc:  # a bad scenario: the project's one-line message, as a ValueError
        raise ValueError(str(exc)) from exc

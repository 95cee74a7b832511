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
within ``±τ_max``. An action outside its space, NaN, a missing or unknown agent is a
``ValueError`` naming it: nothing is clipped silently.

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

from bioform_mj.control.kernel import estimator_advance
from bioform_mj.core.engine import Bounds, check, describe
from bioform_mj.core.errors import Diverged, InputError
from bioform_mj.envs.kernels import direct_torque, sense_errors, track_velocity
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
    """

    metadata = {"name": "bioform_formation_v0", "render_modes": [], "is_parallelizable": True}

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
    ) -> None:
        if action not in ACTIONS:
            raise ValueError(f"unknown action mode {action!r} (expected one of: {', '.join(ACTIONS)})")
        if dtype not in ("float64", "float32"):
            raise ValueError(f"unknown observation dtype {dtype!r} (expected float64 or float32)")
        self._dtype = np.dtype(dtype)
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
        self.render_mode = None
        graph = sc.build_graph()
        self.graph = graph
        src, dst = np.asarray(graph.src), np.asarray(graph.dst)
        self._nbrs = [dst[src == i].tolist() for i in range(sc.n)]
        self._nbr_edges = [np.flatnonzero(src == i).tolist() for i in range(sc.n)]
        self.K = max(1, max(len(x) for x in self._nbrs))
        self.obs_size = 2 + 3 + 2 + 6 * self.K + 6
        self._plant = None
        self._plant_poses: np.ndarray | None = None
        self._sc = sc
        self._build_time_axis(sc)
        self._build_stack(sc, plant_c_true=None)
        tau_max = np.broadcast_to(np.asarray(self._stack.p.tau_max, dtype=float), (sc.n,))
        vm = float(min(sc.limits.speed, 2.0)) if v_max is None else float(v_max)
        wm = float(2 * math.pi) if w_max is None else float(w_max)
        if not (vm > 0 and wm > 0 and math.isfinite(vm) and math.isfinite(wm)):
            raise ValueError(f"v_max and w_max must be positive and finite, got {vm!r}, {wm!r}")
        hi_obs = np.full(self.obs_size, np.inf, dtype=self._dtype)
        self._obs_spaces = {a: spaces.Box(-hi_obs, hi_obs, dtype=self._dtype) for a in self.possible_agents}
        if action == "velocity":
            hi = np.array([vm, wm])
            self._act_spaces = {a: spaces.Box(-hi, hi, dtype=np.float64) for a in self.possible_agents}
        else:
            self._act_spaces = {
                a: spaces.Box(-np.full(2, tau_max[i]), np.full(2, tau_max[i]), dtype=np.float64)
                for a, i in self._index.items()
            }
        self._low = np.array([self._act_spaces[a].low for a in self.possible_agents])
        self._high = np.array([self._act_spaces[a].high for a in self.possible_agents])
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
        self.N = max(1, int(round(sc.sim.duration / dt)))
        self.stride = max(1, int(round(sc.sim.log_dt / dt)))
        t_all = np.arange(self.N + 1) * dt
        lp, lv, _ = sc.build_leader().states(t_all)
        self.L_pose = np.ascontiguousarray(lp, dtype=float)
        self.L_vel = np.ascontiguousarray(lv, dtype=float)

    def _build_stack(self, sc: Scenario, plant_c_true: np.ndarray | None) -> None:
        from bioform_mj.control.stack import ControlStack
        from bioform_mj.run.simulate import stack_params

        c = np.array(sc.plant.c_true, dtype=float)[None, :].repeat(sc.n, 0) if plant_c_true is None else plant_c_true
        tau_max = getattr(self._plant, "tau_max", None) if self._plant is not None else None
        self._stack = ControlStack(self.graph, stack_params(sc, c, tau_max))

    def _plant_for(self, sc: Scenario):
        """The scenario's plant at ``sc``'s initial poses (rebuilt only when the poses change: a seeded jitter)."""
        from bioform_mj.run.simulate import make_plant

        poses = sc.initial_poses()
        if self._plant is None or not np.array_equal(poses, self._plant_poses):
            self._plant = make_plant(sc)
            self._plant_poses = poses
            self._build_stack(sc, np.ascontiguousarray(self._plant.c_true(), dtype=float))
        return self._plant

    # ------------------------------------------------------------------ PettingZoo API
    def reset(self, seed: int | None = None, options: Mapping[str, Any] | None = None):
        """Start an episode; ``seed`` (≥ 0) replaces ``sim.seed`` (the jitter of the initial poses and
        every fault draw), None keeps the last one. Returns ``(observations, infos)``."""
        from bioform_mj.run.simulate import initial_estimates

        sc = self._sc
        if seed is not None:
            if int(seed) < 0:
                raise ValueError(f"seed must be >= 0, got {seed}")
            base = self.base_scenario
            sc = dataclasses.replace(base, sim=dataclasses.replace(base.sim, seed=int(seed)))
        self._sc = sc
        plant = self._plant_for(sc)
        plant.reset()
        self._odometry = getattr(plant, "sensing", "truth") == "odometry"
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
        self._tipped = np.zeros(self.n, dtype=bool)
        self._events_seen = np.zeros(self.n)
        obs = self._observations()
        return obs, {a: {"t": 0.0} for a in self.agents}

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
        self._mp, self._mv = np.array(mp, dtype=float), np.array(mv, dtype=float)
        self._comm, self._lp_rx, self._lv_rx = comm, np.array(lp, dtype=float), np.array(lv, dtype=float)
        self._comm_in = st.comm_in(comm)
        sense_errors(self._g, self._s, self._lp_rx, self._lv_rx, self._mp, self._mv, self._comm_in, learn)

    def step(self, actions: Mapping[str, Any]):
        """One control period for every live agent. Returns ``(obs, rewards, terminations, truncations, infos)``."""
        if self._done:
            raise RuntimeError("step() after the episode ended: call reset() first")
        u = self._actions(actions)
        g, s, k = self._g, self._s, self.k
        mp, mv = self._measure()
        if self.action_mode == "velocity":
            track_velocity(g, s, mv, u)
        else:
            direct_torque(g, s, u)
        self._stats_control(mv)
        tau = np.array(s.tau, dtype=float)
        if self._faults is not None and self._faults._lim is not None:  # weakened motors deliver no more
            tau = np.clip(tau, -self._faults._lim, self._faults._lim)
        estimator_advance(g, s)
        diverged = None
        try:
            self._events(k)
            self._plant.step(tau, k * self.dt)
            self._pose, self._vel = self._plant.observe()
        except Diverged as e:
            diverged = str(e)
        self.k = k = k + 1
        self._sense_phase(k, learn=True)
        if diverged is None and not check(s, self._pose, self._vel, self._lim, self._diag):
            diverged = describe(self._diag, k * self.dt, self._lim)
        fe = self._formation_error(k)
        self._stats_sample(k, fe)
        tip = getattr(self._plant, "tip_step", None)
        newly = np.zeros(self.n, dtype=bool) if tip is None else (np.asarray(tip) >= 0) & ~self._tipped
        self._tipped |= newly
        eff = ((tau / self._tau_max[:, None]) ** 2).mean(axis=1)
        w = self.weights
        end = diverged is not None or bool(self._tipped.any())
        hits = self._new_contacts()
        r = -self.dt * (w["formation"] * np.where(np.isfinite(fe), fe, 0.0) + w["effort"] * eff) - w["tipped"] * newly
        r = r - w["collision"] * hits
        if end:
            r = r - w["terminal"] * max(0.0, (self.N - k) * self.dt)
        trunc = k >= self.N and not end
        obs = (
            self._observations() if diverged is None else {a: np.zeros(self.obs_size, self._dtype) for a in self.agents}
        )
        info = {"t": k * self.dt}
        if diverged is not None:
            info["diverged"] = diverged
        if self._tipped.any():
            info["tipped"] = [self.possible_agents[i] for i in np.flatnonzero(self._tipped)]
        if hits.any():
            info["collided"] = [self.possible_agents[i] for i in np.flatnonzero(hits)]
        agents = self.agents
        rewards = {a: float(r[self._index[a]]) for a in agents}
        terms = dict.fromkeys(agents, end)
        truncs = dict.fromkeys(agents, trunc)
        infos = {a: dict(info) for a in agents}
        if end or trunc:
            self._done = True
            self._diverged = diverged
            self.agents = []
        return obs, rewards, terms, truncs, infos

    def _new_contacts(self) -> np.ndarray:
        """Contact events (robots and obstacles) of each follower in the period just ended (n,), from the
        plant's contact watch (MuJoCo, design §19; zeros for a plant without one)."""
        watch = getattr(self._plant, "contact_watch", None)
        if watch is None:
            return np.zeros(self.n)
        ev = np.asarray(watch().events, dtype=float).sum(axis=1)  # since the plant's reset
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
            u = np.array([actions[a] for a in self.possible_agents], dtype=float)
        except (ValueError, TypeError) as exc:  # ragged or non-numeric: find which agent
            for a in self.possible_agents:
                x = np.asarray(actions[a])
                if x.shape != (2,) or not np.issubdtype(x.dtype, np.number):
                    raise ValueError(f"action of {a} must be 2 numbers, got {actions[a]!r}") from exc
            raise ValueError(f"actions could not be read as numbers: {exc}") from exc
        if u.shape != (self.n, 2):
            for a in self.possible_agents:
                if np.shape(actions[a]) != (2,):
                    raise ValueError(f"action of {a} must have shape (2,), got {np.shape(actions[a])}")
        bad = ~np.isfinite(u).all(axis=1) | (u < self._low).any(axis=1) | (u > self._high).any(axis=1)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            a, sp = self.possible_agents[i], self._act_spaces[self.possible_agents[i]]
            what = "is not finite" if not np.isfinite(u[i]).all() else "is outside the action space"
            raise ValueError(f"action of {a} {u[i].tolist()} {what} [{sp.low.tolist()}, {sp.high.tolist()}]")
        return u

    def _events(self, k: int) -> None:
        from bioform_mj.run.loop import EventQueue

        if k == 0:
            self._evq = EventQueue(self._sc.events, self.dt)
        self._evq.apply(k, self._plant)  # a payload: c_true changes, the learner is not told (as in bioform run)

    # ------------------------------------------------------------------ observations
    def _observations(self) -> dict[str, np.ndarray]:
        s, comm = self._s, self._comm
        mp, mv = self._measure()
        lp, lv = self._lp_rx, self._lv_rx  # the leader as this step's network delivers it
        lacc = np.asarray(self.graph.leader_access, dtype=float)
        if comm is not None:
            lacc = lacc * np.asarray(comm.leader_w, dtype=float)
        rp = s.est_pose[self.graph.dst] if comm is None or comm.recv_pose is None else comm.recv_pose
        rv = s.est_vel[self.graph.dst] if comm is None or comm.recv_vel is None else comm.recv_vel
        ew = np.ones(len(self.graph.src)) if comm is None else np.asarray(comm.edge_w, dtype=float)
        out = {}
        for a in self.agents:
            i = self._index[a]
            o = np.zeros(self.obs_size)
            o[0:2] = mv[i]
            o[2:5] = s.err[i]
            o[5:7] = s.est_vel[i]
            own = s.est_pose[i]
            c, sn = math.cos(mp[i, 2]), math.sin(mp[i, 2])
            for q, e in enumerate(self._nbr_edges[i]):
                if ew[e] > 0:  # a link that is down delivers nothing
                    o[7 + 6 * q : 13 + 6 * q] = _relative(rp[e], rv[e], own, s.est_vel[i], c, sn)
            if lacc[i] > 0:
                o[7 + 6 * self.K :] = _relative(lp, lv, own, s.est_vel[i], c, sn)
            out[a] = o.astype(self._dtype, copy=False)
        return out

    def _formation_error(self, k: int) -> np.ndarray:
        from bioform_mj.assess.outcomes import slots_of

        return np.hypot(*(self._pose[:, :2] - slots_of(self._sc, self.L_pose[k])).T)

    # ------------------------------------------------------------------ episode statistics
    def _stats_reset(self) -> None:
        self._verr = np.zeros(self.n)
        self._rows_t: list[float] = []
        self._rows_fe: list[np.ndarray] = []
        self._rows_vel: list[np.ndarray] = []
        self._stats_sample(0, self._formation_error(0))

    def _stats_control(self, mv: np.ndarray) -> None:
        s = self._s
        self._verr += np.abs(s.cmd[:, 0] - self._vel[:, 0]) + np.abs(s.cmd[:, 1] - self._vel[:, 1])

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
        """The global state (for centralised critics): every follower's true pose and velocity, (n·5,)."""
        return np.concatenate([self._pose.ravel(), self._vel.ravel()])

    def render(self) -> None:
        return None

    def close(self) -> None:
        self._plant = None


def _relative(p: np.ndarray, v: np.ndarray, own_p: np.ndarray, own_v: np.ndarray, c: float, s: float) -> np.ndarray:
    """``[1, Δx, Δy, Δθ, Δυ, Δω]`` of ``(p, v)`` minus the own estimate, positions in the body frame (c, s)."""
    dx, dy = p[0] - own_p[0], p[1] - own_p[1]
    dth = (p[2] - own_p[2] + math.pi) % (2 * math.pi) - math.pi
    return np.array([1.0, c * dx + s * dy, -s * dx + c * dy, dth, v[0] - own_v[0], v[1] - own_v[1]])


def parallel_env(scenario: str | Path | Scenario = "paper", **options: Any) -> FormationParallelEnv:
    """The formation of ``scenario`` as a PettingZoo ``ParallelEnv`` (``options``: :class:`FormationParallelEnv`)."""
    try:
        return FormationParallelEnv(scenario, **options)
    except InputError as exc:  # a bad scenario: the project's one-line message, as a ValueError
        raise ValueError(str(exc)) from exc

"""The closed loop: scenario in, plant and control stack built, log and summary out."""
from __future__ import annotations

import logging
import math
import platform
import time
from dataclasses import dataclass, field
from typing import Any, Protocol, Sequence

import numpy as np

from . import __version__
from .control.fused import M_SAT, M_TAU, M_TAURAW, M_VERR, M_VMAX
from .control.stack import ControlStack, StackParams, parse_method
from .disturbance import Harmonic as HarmonicDisturbance
from .errors import Diverged
from .plants.base import Plant
from .plants.ideal import IdealPlant
from .scenario import Scenario

log = logging.getLogger(__name__)

#: Time-series channels of ``log.npz``: name → trailing shape (``n`` = followers).
CHANNELS: dict[str, tuple[str, ...]] = {
    "pose": ("n", "3"),            # [x, y, θ] m, m, rad
    "vel": ("n", "2"),             # [υ, ω] m/s, rad/s (measured)
    "est_pose": ("n", "3"),        # P_ir, each follower's estimate of the leader's pose
    "est_vel": ("n", "2"),         # [υ_ir, ω_ir]
    "cmd": ("n", "2"),             # [υ_cmd, ω_cmd]
    "dcmd": ("n", "2"),            # filtered [υ̇_cmd, ω̇_cmd]
    "tau": ("n", "2"),             # applied [τ_L, τ_R] N·m
    "tau_raw": ("n", "2"),         # commanded before saturation
    "c_hat": ("n", "2"),           # [â, b̂]
    "c_true": ("n", "2"),          # [a, b] of the plant
    "z_hat": ("n", "2"),           # learner's velocity estimate
    "vs": ("n",),                  # neuron output V_s
    "tracking_error": ("n", "3"),  # [x̃, ỹ, θ̃] body frame
    "formation_error": ("n",),     # |p_i − (p_r − Δ_i)| m, against the true leader
    "estimation_error": ("n",),    # |P_ir[:2] − p_r| m
    "saturated": ("n",),           # any wheel at its limit
}


class Observer(Protocol):
    """Something that watches a run (video, rerun) at its own period, without slowing a run that has none."""

    period: float  # s of simulated time between calls

    def start(self, run: "RunState") -> None: ...
    def sample(self, run: "RunState") -> None: ...
    def finish(self, run: "RunState") -> None: ...


@dataclass
class RunState:
    """What observers may read during a run (the live objects, not copies)."""

    scenario: Scenario
    plant: Plant
    stack: ControlStack
    t: float = 0.0
    leader_pose: np.ndarray = field(default_factory=lambda: np.zeros(3))
    leader_vel: np.ndarray = field(default_factory=lambda: np.zeros(2))
    pose: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    vel: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    @property
    def slots(self) -> np.ndarray:
        """Formation slots (n, 2): the true leader's position minus each offset (m)."""
        return self.leader_pose[None, :2] - np.asarray(self.scenario.formation.offsets)


@dataclass
class RunResult:
    """The log (time series at ``log_dt``), the summary dict and, if it happened, the divergence."""

    scenario: Scenario
    log: dict[str, np.ndarray]
    summary: dict[str, Any]
    plant: Plant
    diverged: Diverged | None = None


def make_plant(sc: Scenario) -> Plant:
    """The plant named by ``sc.plant.kind``, at the scenario's initial poses."""
    poses = sc.initial_poses()
    dist = HarmonicDisturbance(sc.n, sc.disturbance.bias, sc.disturbance.amp, sc.disturbance.freq, sc.disturbance.phase)
    if sc.plant.kind == "ideal":
        return IdealPlant(np.array(sc.plant.c_true), poses, sc.sim.control_dt, sc.sim.physics_dt, dist,
                          mass=sc.plant.mass, inertia=sc.plant.inertia)
    from .plants.mujoco_plant import MujocoPlant  # imported only when asked: the ideal plant needs no MuJoCo
    from .robots import resolve_robot

    robots = list(sc.plant.robots) * (sc.n if len(sc.plant.robots) == 1 else 1)
    return MujocoPlant([resolve_robot(r) for r in robots], poses, sc.sim.control_dt, sc.sim.physics_dt, dist,
                       friction_patch=sc.faults.friction_patch or None)  # faults: low-friction floor patch


def stack_params(sc: Scenario, c_true: np.ndarray, tau_max: np.ndarray | None = None) -> StackParams:
    """Resolve the scenario's numbers into the control stack's per-follower arrays."""
    law, learning = parse_method(sc.method)
    n = sc.n
    c_hat0 = np.asarray(sc.learner.c_hat0_scale) * c_true
    lo, hi = sc.learner.c_bounds
    return StackParams(
        offsets=np.array(sc.formation.offsets, dtype=float),
        kp=np.array(sc.estimator.kp), ka=np.array(sc.estimator.ka), kb=np.array(sc.estimator.kb),
        est_phi=np.array(sc.estimator.phi),
        k1=sc.kinematic.k1, k2=sc.kinematic.k2, k3=sc.kinematic.k3,
        A=sc.kinematic.A, B=sc.kinematic.B, D=sc.kinematic.D,
        law=law, learning=learning,
        c_gain=np.array(sc.torque.c), torque_phi=sc.torque.phi,
        tau_max=np.full(n, sc.torque.tau_max) if tau_max is None else np.asarray(tau_max, dtype=float),
        steer_priority=sc.torque.saturation == "steer-priority",
        deriv_wn=sc.torque.deriv_wn,
        k4=_learner_k4(sc, c_hat0), k5=np.array(sc.learner.k5), kd=np.array(sc.learner.kd),
        c_hat0=c_hat0, c_min=lo * c_hat0, c_max=hi * c_hat0,
        dt=sc.sim.control_dt,
    )


def _learner_k4(sc: Scenario, c_hat0: np.ndarray) -> np.ndarray:
    """``k4`` (2,) as configured, or (n, 2) per robot for ``gain_scaling = "c_hat0"``:
    ``k4 ⊙ (ĉ_i(0) / ĉ_paper(0))²`` with ``ĉ_paper(0) = c_hat0_scale ⊙ PAPER_C``, the initial
    estimate the paper's robot gets, so that robot keeps the paper's gains exactly."""
    from .scenario import PAPER_C

    k4 = np.array(sc.learner.k4, dtype=float)
    if sc.learner.gain_scaling == "c_hat0":
        ref = np.asarray(sc.learner.c_hat0_scale, dtype=float) * np.asarray(PAPER_C)
        return k4 * (np.asarray(c_hat0, dtype=float) / ref) ** 2
    return k4


def initial_estimates(sc: Scenario, pose0: np.ndarray, leader_pose0: np.ndarray) -> np.ndarray:
    """``P_ir(0)`` (n, 3) per ``estimator.init``: ``zero``, ``self`` (own pose + offset) or ``leader``."""
    n = sc.n
    if sc.estimator.init == "zero":
        return np.zeros((n, 3))
    if sc.estimator.init == "leader":
        return np.tile(leader_pose0, (n, 1))
    est = pose0.copy()
    est[:, :2] += np.asarray(sc.formation.offsets)
    return est


ENGINES = ("auto", "fused", "numpy")


def simulate(sc: Scenario, observers: Sequence[Observer] = (), progress: Any = None,
             engine: str = "auto", record_inputs: tuple[np.ndarray, np.ndarray] | None = None) -> RunResult:
    """Run the closed loop of ``sc`` and return its log and summary.

    ``engine``: ``numpy`` runs the reference :class:`ControlStack` with a Python loop;
    ``fused`` the numba-compiled stack, and the whole loop compiled in chunks between
    log samples where the plant allows (see ``fastloop``); ``auto`` = fused if numba
    imports. Both compute the same equations; results agree to rounding.
    ``record_inputs`` (compiled MuJoCo loop only): arrays ``(N, nu)``, ``(N, n, 6)`` that
    receive each step's ``ctrl`` and chassis ``xfrc_applied``, for a bare replay.

    A divergence (NaN/inf or a state beyond ``sc.limits``) stops the loop; the
    result then holds the log up to that point and ``diverged`` says why.
    ``progress``, if given, is called as ``progress(k, N)`` every log sample.
    """
    graph = sc.build_graph()
    traj = sc.build_leader()
    plant = make_plant(sc)
    if engine not in ENGINES:
        raise ValueError(f"unknown engine '{engine}' (expected one of: {', '.join(ENGINES)})")
    from .control.fused import HAVE_NUMBA, FusedControlStack

    fused = engine == "fused" or (engine == "auto" and HAVE_NUMBA)
    stack_cls = FusedControlStack if fused else ControlStack
    stack = stack_cls(graph, stack_params(sc, plant.c_true(), getattr(plant, "tau_max", None)))
    n = sc.n
    dt = sc.sim.control_dt
    N = max(1, int(round(sc.sim.duration / dt)))
    stride = max(1, int(round(sc.sim.log_dt / dt)))
    t_all = np.arange(N + 1) * dt
    L_pose, L_vel, _ = traj.states(t_all)  # analytic, all steps at once
    offsets = np.asarray(sc.formation.offsets, dtype=float)

    plant.reset()
    pose, vel = plant.observe()
    stack.reset(initial_estimates(sc, pose, L_pose[0]), vel)
    faults = None  # fault injection (faults.py): built only when configured, else no per-step cost
    if sc.faults.per_step:  # (a friction patch is in the MuJoCo scene: nothing per step)
        from .faults import Faults

        faults = Faults(sc, graph, stack.p.tau_max)
    K = (N - 1) // stride + 1
    shapes = {"n": n, "3": 3, "2": 2}
    logd: dict[str, np.ndarray] = {"t": np.zeros(K), "leader_pose": np.zeros((K, 3)), "leader_vel": np.zeros((K, 2))}
    for name, shp in CHANNELS.items():
        logd[name] = np.zeros((K,) + tuple(shapes[s] for s in shp), dtype=bool if name == "saturated" else float)

    state = RunState(sc, plant, stack)
    for o in observers:
        o.start(state)
    obs = ObserverClock(observers, state)
    evq = EventQueue(sc.events, dt)
    wall0 = time.perf_counter()
    from . import fastloop

    if fused and faults is None and fastloop.supported(plant, stack):  # no per-step Python hooks
        k_done, j, diverged, pose, vel, met = fastloop.run(
            sc, plant, stack, L_pose, L_vel, N, stride, evq, obs, progress, logd, _guard, record_inputs)
    else:
        k_done, j, diverged, pose, vel, met = _run_stepwise(
            sc, plant, stack, faults, L_pose, L_vel, N, stride, evq, obs, progress, logd)
    wall = time.perf_counter() - wall0
    if diverged is None and not (np.all(np.isfinite(pose)) and np.all(np.isfinite(vel))):
        diverged = Diverged(f"non-finite robot state at the end of the run (t = {N * dt:g} s)", step=N, time=N * dt)
    if progress is not None:
        progress(N, N)
    state.t, state.pose, state.vel = k_done * dt, pose, vel
    state.leader_pose, state.leader_vel = L_pose[k_done], L_vel[k_done]
    for o in observers:
        o.finish(state)
    logd = {key: v[:j] for key, v in logd.items()}
    logd["offsets"] = offsets
    logd["edges"] = graph.edges + 1
    logd["leader_access"] = graph.leader_access
    sim_time = k_done * dt
    final_form = np.linalg.norm(pose[:, :2] - (L_pose[k_done, None, :2] - offsets), axis=1)
    final_est = np.linalg.norm(stack.estimator.pose[:, :2] - L_pose[k_done, None, :2], axis=1)
    fe = logd["formation_error"]
    half = fe[len(fe) // 2:] if len(fe) else fe
    followers = []
    c_true = plant.c_true()
    for i in range(n):
        followers.append({
            "id": i + 1,
            "total_velocity_error": float(met[i, M_VERR] * dt),
            "final_formation_error_m": float(final_form[i]),
            "rms_formation_error_m": float(np.sqrt(np.mean(fe[:, i] ** 2))) if len(fe) else float("nan"),
            "rms_formation_error_last_half_m": float(np.sqrt(np.mean(half[:, i] ** 2))) if len(half) else float("nan"),
            "final_estimation_error_m": float(final_est[i]),
            "max_abs_v_cmd": float(met[i, M_VMAX]),
            "peak_abs_torque": float(met[i, M_TAU]),
            "peak_abs_torque_commanded": float(met[i, M_TAURAW]),
            "saturation_fraction": float(met[i, M_SAT] / max(1, k_done)),
            "c_hat": [float(v) for v in stack.c_hat[i]],
            "c_true": [float(v) for v in c_true[i]],
            "c_hat_rel_error": [float(v) for v in (stack.c_hat[i] / c_true[i] - 1.0)],
        })
    summary = {
        "scenario": sc.name,
        "plant": sc.plant.kind,
        "method": sc.method,
        "seed": sc.sim.seed,
        "sim_time_s": sim_time,
        "wall_time_s": wall,
        "steps": k_done,
        "diverged": None if diverged is None else {"message": str(diverged), "time_s": diverged.time, "step": diverged.step},
        "versions": _versions(),
        "config": sc.to_dict(),
        "followers": followers,
    }
    return RunResult(sc, logd, summary, plant, diverged)


class ObserverClock:
    """Calls each observer's ``sample`` once its period of simulated time has passed."""

    def __init__(self, observers: Sequence[Observer], state: RunState) -> None:
        self.observers = list(observers)
        self.state = state
        self.next = [0.0] * len(self.observers)  # s, next due time of each

    def sample(self, t: float, leader_pose, leader_vel, pose, vel) -> None:
        """At control time ``t`` (s), before the plant step: sample the observers that are due."""
        if not self.observers:
            return
        st = self.state
        st.t, st.leader_pose, st.leader_vel, st.pose, st.vel = t, leader_pose, leader_vel, pose, vel
        for i, o in enumerate(self.observers):
            if t >= self.next[i] - 1e-12:
                o.sample(st)
                self.next[i] += o.period


class EventQueue:
    """The scenario's timed events, applied to the plant at the first control step at or after their time."""

    def __init__(self, events: Sequence[Any], dt: float) -> None:
        self.events = sorted(events, key=lambda e: e.time)
        self.steps = [first_step_at(e.time, dt) for e in self.events]
        self.i = 0

    def next_step(self) -> int | None:
        """Control step of the next pending event (None: no more)."""
        return self.steps[self.i] if self.i < len(self.steps) else None

    def apply(self, k: int, plant: Plant) -> bool:
        """Apply every event due at step ``k``; True if any was."""
        applied = False
        while self.i < len(self.events) and self.steps[self.i] <= k:
            ev = self.events[self.i]
            plant.add_payload(ev.follower - 1, ev.mass, ev.inertia)
            self.i += 1
            applied = True
        return applied


def first_step_at(t: float, dt: float) -> int:
    """The first control step ``k`` with ``k·dt ≥ t`` (to 1e-12 s)."""
    return max(0, int(math.ceil((t - 1e-12) / dt - 1e-9)))


def _run_stepwise(sc: Scenario, plant: Plant, stack: ControlStack, faults: Any, L_pose: np.ndarray,
                  L_vel: np.ndarray, N: int, stride: int, evq: EventQueue, obs: ObserverClock, progress: Any,
                  logd: dict[str, np.ndarray]) -> tuple[int, int, Diverged | None, np.ndarray, np.ndarray, np.ndarray]:
    """The closed loop one control step at a time in Python: the numpy reference engine, and
    every run with per-step hooks (faults). Same contract as :func:`bioform_mj.fastloop.run`:
    returns ``(steps done, log rows, divergence, pose, vel, metrics (n, 5))``."""
    dt = sc.sim.control_dt
    offsets = np.asarray(sc.formation.offsets, dtype=float)
    met = np.zeros((plant.n, 5))
    pose, vel = plant.observe()
    diverged: Diverged | None = None
    j = k_done = 0
    for k in range(N):
        t = k * dt
        evq.apply(k, plant)
        if faults is None:
            tau = stack.step(L_pose[k], L_vel[k], pose, vel)
        else:  # faults: noisy sensing, faulty network, weakened motors, pushes; tau = what reaches the plant
            tau = faults.step(k, t, stack, plant, L_pose[k], L_vel[k], pose, vel)
        cmd = stack.cmd
        met[:, M_VERR] += np.abs(cmd - vel).sum(axis=1)  # SPEC §7 metric, times dt in the summary
        met[:, M_SAT] += stack.saturated
        np.maximum(met[:, M_VMAX], np.abs(cmd[:, 0]), out=met[:, M_VMAX])
        np.maximum(met[:, M_TAU], np.abs(tau).max(axis=1), out=met[:, M_TAU])
        np.maximum(met[:, M_TAURAW], np.abs(stack.tau_raw).max(axis=1), out=met[:, M_TAURAW])
        if k % stride == 0:
            _record(logd, j, t, L_pose[k], L_vel[k], pose, vel, stack, plant, offsets)
            diverged = _guard(logd, j, t, k, sc.limits)
            j += 1
            if progress is not None:
                progress(k, N)
            if diverged is not None:
                break
        obs.sample(t, L_pose[k], L_vel[k], pose, vel)
        try:
            plant.step(tau, t)
        except Diverged as e:  # e.g. a MuJoCo warning: keep the log so far
            diverged = e
            break
        pose, vel = plant.observe()
        k_done = k + 1
    return k_done, j, diverged, pose, vel, met


def _record(logd, j, t, lp, lv, pose, vel, stack: ControlStack, plant: Plant, offsets) -> None:
    logd["t"][j] = t
    logd["leader_pose"][j] = lp
    logd["leader_vel"][j] = lv
    logd["pose"][j] = pose
    logd["vel"][j] = vel
    logd["est_pose"][j] = stack.estimator.pose
    logd["est_vel"][j] = stack.estimator.vel
    logd["cmd"][j] = stack.cmd
    logd["dcmd"][j] = stack.dcmd
    logd["tau"][j] = stack.tau
    logd["tau_raw"][j] = stack.tau_raw
    logd["c_hat"][j] = stack.c_hat
    logd["c_true"][j] = plant.c_true()
    logd["z_hat"][j] = stack.learner.z_hat
    logd["vs"][j] = stack.vs
    logd["tracking_error"][j] = stack.err
    logd["formation_error"][j] = np.linalg.norm(pose[:, :2] - (lp[None, :2] - offsets), axis=1)
    logd["estimation_error"][j] = np.linalg.norm(stack.estimator.pose[:, :2] - lp[None, :2], axis=1)
    logd["saturated"][j] = stack.saturated


_GUARDS = (
    # channel, column (None = all), limit attribute, what
    ("pose", slice(0, 2), "position", "position"),
    ("est_pose", slice(0, 2), "position", "leader-pose estimate"),
    ("vel", slice(0, 1), "speed", "speed υ"),
    ("cmd", slice(0, 1), "speed", "commanded speed υ_cmd"),
    ("est_vel", slice(0, 1), "speed", "leader-speed estimate υ_ir"),
    ("tau_raw", slice(0, 2), "torque", "commanded wheel torque"),
)


def _guard(logd, j: int, t: float, k: int, lim) -> Diverged | None:
    """Check sample ``j`` for NaN/inf and magnitudes beyond ``lim``; return a diagnosis or None."""
    for name in ("pose", "vel", "est_pose", "est_vel", "cmd", "tau_raw", "c_hat", "vs"):
        row = logd[name][j]
        bad = ~np.isfinite(row)
        if bad.any():
            i = int(np.flatnonzero(bad.reshape(row.shape[0], -1).any(axis=1))[0])
            return Diverged(f"follower {i + 1}: signal '{name}' is not finite ({row[i]}) at t = {t:.4f} s", step=k, time=t)
    for name, cols, attr, what in _GUARDS:
        mag = np.abs(logd[name][j][:, cols]).max(axis=1)
        limit = getattr(lim, attr)
        over = np.flatnonzero(mag > limit)
        if over.size:
            i = int(over[0])
            return Diverged(
                f"follower {i + 1}: {what} |{name}| = {mag[i]:.3g} exceeds limits.{attr} = {limit:g} at t = {t:.4f} s",
                step=k, time=t)
    return None


def _versions() -> dict[str, str]:
    out = {"bioform_mj": __version__, "numpy": np.__version__, "python": platform.python_version()}
    try:
        import mujoco

        out["mujoco"] = mujoco.__version__
    except ImportError:  # pragma: no cover - mujoco is a dependency
        out["mujoco"] = "not installed"
    return out

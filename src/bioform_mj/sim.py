"""The closed loop: scenario in, plant and controller built (or given), log and summary out.

One driver runs every loop: between the points where Python must act (events,
observers, progress, interrupts) it calls a *chunk* of control periods. Where the plant
offers a compiled chunk (``plant.compiled_chunk``) and the controller exposes a compiled
kernel (``controller.kernel``), the chunk runs in machine code; otherwise (injected
faults, a user's controller, ``engine="stepwise"``, ``NUMBA_DISABLE_JIT=1``) it runs step
by step in Python. Both call the same compiled equations and the same metric, log and
guard functions (``engine.py``), so the two engines agree bit for bit on one machine
(docs/design.md §9).
"""

from __future__ import annotations

import logging
import math
import platform
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from . import __version__
from .control.kernel import StackState, new_state
from .control.stack import ControlStack, StackParams, parse_method
from .disturbance import Harmonic as HarmonicDisturbance
from .engine import (
    CHANNELS,
    GUARD_FAILED,
    MEAN_CHANNELS,
    OK,
    Bounds,
    Formation,
    LogArrays,
    Loop,
    after_control,
    describe,
    new_acc,
    new_log,
    new_metrics,
    record_odometry,
)
from .errors import Diverged, RobotWarning
from .plants.base import Plant
from .plants.ideal import IdealPlant
from .scenario import Scenario

log = logging.getLogger(__name__)


class Observer(Protocol):
    """Something that watches a run (video, rerun) at its own period, without slowing a run that has none."""

    period: float  # s of simulated time between calls

    def start(self, run: RunState) -> None: ...
    def sample(self, run: RunState) -> None: ...
    def finish(self, run: RunState) -> None: ...


@dataclass
class RunState:
    """What observers may read during a run (the live objects, not copies)."""

    scenario: Scenario
    plant: Plant
    stack: Any  # the controller (a control.base.Controller)
    t: float = 0.0
    leader_pose: np.ndarray = field(default_factory=lambda: np.zeros(3))
    leader_vel: np.ndarray = field(default_factory=lambda: np.zeros(2))
    pose: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    vel: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    @property
    def slots(self) -> np.ndarray:
        """Formation slots (n, 2): the true leader's position minus each offset (m)."""
        return slots_of(self.scenario, self.leader_pose)


@dataclass
class RunResult:
    """The log (time series at ``log_dt``), the summary dict and, if it happened, the divergence."""

    scenario: Scenario
    log: dict[str, np.ndarray]
    summary: dict[str, Any]
    plant: Plant
    diverged: Diverged | None = None
    interrupted: KeyboardInterrupt | None = None  # what stopped the loop (SIGINT/SIGTERM): log and summary so far


def make_plant(sc: Scenario) -> Plant:
    """The plant named by ``sc.plant.kind``, at the scenario's initial poses."""
    poses = sc.initial_poses()
    dist = HarmonicDisturbance(sc.n, sc.disturbance.bias, sc.disturbance.amp, sc.disturbance.freq, sc.disturbance.phase)
    if sc.plant.kind == "ideal":
        return IdealPlant(
            np.array(sc.plant.c_true),
            poses,
            sc.sim.control_dt,
            sc.sim.physics_dt,
            dist,
            mass=sc.plant.mass,
            inertia=sc.plant.inertia,
        )
    from .plants.mujoco_plant import MujocoPlant  # imported only when asked: the ideal plant needs no MuJoCo
    from .robots import resolve_robot

    robots = list(sc.plant.robots) * (sc.n if len(sc.plant.robots) == 1 else 1)
    refs = [resolve_robot(r) for r in robots]
    pc = sc.plant
    sensing = {}
    if pc.sensing == "odometry":  # design §8.3: encoders (the scenario's cpr or each robot file's) and gyro
        from .scenario import robot_encoder_cpr

        cpr = [float(pc.encoder_cpr) if pc.encoder_cpr > 0 else robot_encoder_cpr(r.model) for r in refs]
        sensing = dict(
            sensing="odometry",
            encoder_cpr=cpr,
            sensor_dt=pc.sensor_dt,
            gyro_noise=pc.gyro_noise,
            gyro_bias=pc.gyro_bias,
            seed=sc.sim.seed,
        )
    plant = MujocoPlant(
        refs,
        poses,
        sc.sim.control_dt,
        sc.sim.physics_dt,
        dist,
        friction_patch=sc.faults.friction_patch or None,  # faults: low-friction floor patch
        obstacles=sc.obstacle_list(),
        safety_distance=sc.safety.distance,
        **sensing,
    )
    if plant.contacts.off:  # design §19: never silent
        why = plant.contacts.off
        warnings.warn(f"contacts between robots and with obstacles are not watched: {why}", RobotWarning, stacklevel=2)
    bad = plant.start_overlaps()  # design §19: an impossible start is refused before any work
    if bad:
        from .errors import InputError

        jit = (
            f" (formation.init_jitter = {sc.formation.init_jitter:g} m, seed {sc.sim.seed})"
            if sc.formation.init_jitter
            else ""
        )
        raise InputError("impossible initial poses" + jit + ": " + "; ".join(bad))
    return plant


def stack_params(sc: Scenario, c_true: np.ndarray, tau_max: np.ndarray | None = None, plant: Any = None) -> StackParams:
    """Resolve the scenario's numbers into the control stack's per-follower arrays (``plant``, if
    given, tells the safety filter each robot's footprint radius and the obstacles, design §19)."""
    law, learning = parse_method(sc.method)
    n = sc.n
    c_hat0 = np.asarray(sc.learner.c_hat0_scale) * c_true
    lo, hi = sc.learner.c_bounds
    return StackParams(
        offsets=np.array(sc.formation.offsets, dtype=float),
        kp=np.array(sc.estimator.kp),
        ka=np.array(sc.estimator.ka),
        kb=np.array(sc.estimator.kb),
        est_phi=np.array(sc.estimator.phi),
        k1=sc.kinematic.k1,
        k2=sc.kinematic.k2,
        k3=sc.kinematic.k3,
        A=sc.kinematic.A,
        B=sc.kinematic.B,
        D=sc.kinematic.D,
        law=law,
        learning=learning,
        c_gain=np.array(sc.torque.c),
        torque_phi=sc.torque.phi,
        tau_max=np.full(n, sc.torque.tau_max) if tau_max is None else np.asarray(tau_max, dtype=float),
        steer_priority=sc.torque.saturation == "steer-priority",
        deriv_wn=sc.torque.deriv_wn,
        derivative=sc.torque.derivative,
        k4=_learner_k4(sc, c_hat0),
        k5=np.array(sc.learner.k5),
        kd=np.array(sc.learner.kd),
        c_hat0=c_hat0,
        c_min=lo * c_hat0,
        c_max=hi * c_hat0,
        dt=sc.sim.control_dt,
        leader_frame=sc.formation.frame == "leader",
        **_cbf_params(sc, plant),
    )


def _cbf_params(sc: Scenario, plant: Any) -> dict[str, Any]:
    """The safety filter's part of :class:`StackParams` (design §19; empty when it is off)."""
    sf = sc.safety
    if sf.filter != "cbf":
        return {}
    from .obstacles import to_rows

    radius = getattr(plant, "footprint_radius", None)
    obstacles = getattr(plant, "obstacles", None) or []
    return dict(
        cbf=True,
        cbf_par=(sf.lookahead, sf.gain, sf.distance, sf.range, sf.pass_right),
        cbf_radius=None if radius is None else np.asarray(radius, dtype=float),
        cbf_obstacles=to_rows(obstacles) if obstacles else None,
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


def slots_of(sc: Scenario, leader_pose: np.ndarray) -> np.ndarray:
    """Formation slots (n, 2) m of the true leader at ``leader_pose`` (3,): ``p_r − Δ_i``, with the
    offsets rotated by the leader's heading for ``formation.frame = "leader"`` (design §4)."""
    off = np.asarray(sc.formation.offsets, dtype=float).reshape(sc.n, 2)
    if sc.formation.frame == "leader":
        c, s = np.cos(leader_pose[2]), np.sin(leader_pose[2])
        off = np.column_stack([c * off[:, 0] - s * off[:, 1], s * off[:, 0] + c * off[:, 1]])
    return np.asarray(leader_pose[:2], dtype=float)[None, :] - off


def initial_estimates(sc: Scenario, pose0: np.ndarray, leader_pose0: np.ndarray) -> np.ndarray:
    """``P_ir(0)`` (n, 3) per ``estimator.init``: ``zero``, ``self`` (own pose + offset) or ``leader``."""
    n = sc.n
    if sc.estimator.init == "zero":
        return np.zeros((n, 3))
    if sc.estimator.init == "leader":
        return np.tile(leader_pose0, (n, 1))
    est = pose0.copy()
    off = np.asarray(sc.formation.offsets, dtype=float).reshape(n, 2)
    if sc.formation.frame == "leader":  # own pose + offset, in its own heading's frame
        c, s = np.cos(pose0[:, 2]), np.sin(pose0[:, 2])
        off = np.column_stack([c * off[:, 0] - s * off[:, 1], s * off[:, 0] + c * off[:, 1]])
    est[:, :2] += off
    return est


ENGINES = ("auto", "compiled", "stepwise")

#: longest stretch of simulated time between two visits to Python (s): bounds the delay of
#: progress reports and of interrupts
MAX_CHUNK_S = 0.1


#: what a plant's compiled chunk shares with this driver (kept under its old name)
LoopContext = Loop


def simulate(
    sc: Scenario,
    observers: Sequence[Observer] = (),
    progress: Any = None,
    engine: str = "auto",
    record_inputs: tuple[np.ndarray, np.ndarray] | None = None,
    *,
    plant: Plant | None = None,
    controller: Any = None,
) -> RunResult:
    """Run the closed loop of ``sc`` and return its log and summary.

    ``plant``: a :class:`~bioform_mj.plants.base.Plant` (default: built from ``sc.plant``);
    ``controller``: a :class:`~bioform_mj.control.base.Controller` (default: the paper's
    stack for ``sc.method``). ``engine``: ``auto`` (compiled where plant and controller
    allow it), ``compiled`` (refuse if they do not) or ``stepwise`` (one Python call per
    control step; the same compiled equations, the same bits). ``record_inputs`` (compiled
    MuJoCo loop only): arrays ``(N, nu)``, ``(N, n, 6)`` that receive each step's ``ctrl``
    and chassis ``xfrc_applied``, for a bare replay.

    A divergence (NaN/inf or a state beyond ``sc.limits``, checked after every control
    step; a MuJoCo warning) stops the loop; the result then holds the log up to the last
    good row and ``diverged`` says why. A ``KeyboardInterrupt`` stops it too
    (``interrupted``). ``progress``, if given, is called as ``progress(k, N)``; if it has a
    ``phase(text)`` method it is told when kernels load or compile.
    """
    if engine not in ENGINES:
        raise ValueError(f"unknown engine '{engine}' (expected one of: {', '.join(ENGINES)})")
    t_setup = time.perf_counter()
    graph = sc.build_graph()
    traj = sc.build_leader()
    if plant is None:
        plant = make_plant(sc)
    own_stack = controller is None
    if own_stack:
        controller = ControlStack(graph, stack_params(sc, plant.c_true(), getattr(plant, "tau_max", None), plant))
    n = sc.n
    if getattr(controller, "n", n) != n or getattr(plant, "n", n) != n:
        raise ValueError(f"the scenario has {n} followers, the plant {plant.n} and the controller {controller.n}")
    dt = sc.sim.control_dt
    N = max(1, int(round(sc.sim.duration / dt)))
    stride = max(1, int(round(sc.sim.log_dt / dt)))
    t_all = np.arange(N + 1) * dt
    L_pose, L_vel, _ = traj.states(t_all)  # analytic, all steps at once
    L_pose = np.ascontiguousarray(L_pose, dtype=float)
    L_vel = np.ascontiguousarray(L_vel, dtype=float)
    offsets = np.ascontiguousarray(sc.formation.offsets, dtype=float).reshape(n, 2)
    form = Formation(offsets, sc.formation.frame == "leader")

    feasibility: list[str] = []
    if hasattr(plant, "params") and hasattr(plant, "model"):  # MuJoCo robots: what the scenario asks of them
        from .robot_check import feasibility as _feasibility

        feasibility = _feasibility(sc, plant)  # in summary.json too
        for line in feasibility:
            warnings.warn(line, RobotWarning, stacklevel=2)  # before the run (the CLI prints warning: lines)
    plant.reset()
    pose0, vel0 = plant.observe()
    controller.reset(initial_estimates(sc, pose0, L_pose[0]), vel0)
    faults = None  # fault injection (faults.py): built only when configured, else no per-step cost
    if sc.faults.per_step:  # (a friction patch is in the MuJoCo scene: nothing per step)
        from .faults import Faults

        p = getattr(controller, "p", None)
        faults = Faults(sc, graph, np.asarray(p.tau_max if p is not None else np.full(n, sc.torque.tau_max)))
    K = (N - 1) // stride + 1
    lg = new_log(K, n)
    kernel = getattr(controller, "kernel", None)
    missing: set[str] = set()
    if kernel is not None:
        gains, state = kernel
    else:  # a user's controller: its signals are copied into a shadow state each step
        gains, state = None, new_state(n)
    lim = sc.limits
    ctx = Loop(
        gains,
        state,
        getattr(controller, "_no_comm", None),
        N,
        dt,
        L_pose,
        L_vel,
        np.ascontiguousarray(pose0, dtype=float),
        np.ascontiguousarray(vel0, dtype=float),
        new_metrics(n),
        new_acc(n),
        lg,
        stride,
        form,
        Bounds(float(lim.position), float(lim.speed), float(lim.torque)),
        np.zeros(3),
    )

    chunk = None
    if engine != "stepwise" and kernel is not None and faults is None and hasattr(plant, "compiled_chunk"):
        chunk = plant.compiled_chunk(ctx, record_inputs) if record_inputs is not None else plant.compiled_chunk(ctx)
    if engine == "compiled" and chunk is None:
        raise ValueError(
            "engine 'compiled' needs a plant and a controller with compiled kernels, and no "
            "per-step faults (use engine 'auto' or 'stepwise')"
        )
    c_true = np.ascontiguousarray(plant.c_true(), dtype=float)
    # design §8.3: with sensing = "odometry" the controllers get each robot's dead reckoning
    # (plant.measurement), everything else (metrics, guards, formation error, outcomes) the truth
    odometry = getattr(plant, "sensing", "truth") == "odometry"

    def measure() -> tuple[np.ndarray, np.ndarray]:
        return plant.measurement(ctx.pose, ctx.vel) if odometry else (ctx.pose, ctx.vel)

    def control(k: int) -> np.ndarray:
        """Control step ``k`` on the current measurements; the torques to apply."""
        mp, mv = measure()
        if faults is None:
            tau = controller.step(L_pose[k], L_vel[k], mp, mv)
        else:  # noisy sensing, faulty network, weakened motors, pushes; tau = what reaches the plant
            tau = faults.step(k, k * dt, controller, plant, L_pose[k], L_vel[k], mp, mv)
        if kernel is None:
            _shadow(state, controller.signals(), tau, missing)
        return np.array(tau, dtype=float)

    applied = [np.zeros((n, 2))]

    def record(k: int, j: int) -> tuple[int, int]:
        """After the control step of ``k``: metrics, guards and the log row (``engine.after_control``)."""
        return after_control(
            k,
            N,
            stride,
            state,
            ctx.pose,
            ctx.vel,
            ctx.met,
            ctx.acc,
            lg,
            j,
            L_pose,
            L_vel,
            dt,
            c_true,
            form,
            ctx.bounds,
            ctx.diag,
        )

    feed = bool(getattr(plant, "feed_delivered", False))

    def python_chunk(k0: int, k1: int, j: int) -> tuple[int, int, int]:
        """The same contract as a compiled chunk, one Python call per step."""
        for k in range(k0, k1):
            plant.step(applied[0], k * dt)  # may raise Diverged (MuJoCo warnings)
            if feed:  # DC motors: the learner gets the torque delivered over the period (design §8.2)
                plant.feed_delivered_torque(state.tau_body)
            p, v = plant.observe()
            ctx.pose[:] = p
            ctx.vel[:] = v
            if k + 1 < N:
                applied[0] = control(k + 1)
                j1, status = record(k + 1, j)
                if odometry and j1 > j:
                    record_odometry(lg, j, plant.odo.mpose, plant.odo.mvel)
                j = j1
                if status != OK:
                    return k + 1 - k0, j, status
        return k1 - k0, j, OK

    if progress is not None and hasattr(progress, "phase"):
        progress.phase("loading compiled kernels (compiling them on the first run)")
    # control step 0 and its row, then a zero-length chunk: kernels are loaded (or compiled) here,
    # outside the timed loop
    applied[0] = control(0)
    j, status = record(0, 0)
    if odometry and j > 0:
        record_odometry(lg, 0, plant.odo.mpose, plant.odo.mvel)
    run_chunk = chunk if chunk is not None else python_chunk
    run_chunk(0, 0, j)
    setup_s = time.perf_counter() - t_setup
    if progress is not None and hasattr(progress, "phase"):
        progress.phase(None)

    state_obs = RunState(sc, plant, controller)
    for o in observers:
        o.start(state_obs)
    obs = ObserverClock(observers, state_obs)
    evq = EventQueue(sc.events, dt)
    wall0 = time.perf_counter()
    diverged: Diverged | None = None
    interrupted: KeyboardInterrupt | None = None
    k = 0
    if status != OK:
        diverged = Diverged(describe(ctx.diag, 0.0, ctx.bounds), step=0, time=0.0)
    try:
        max_chunk = max(1, int(round(MAX_CHUNK_S / dt)))
        while k < N and diverged is None:
            if evq.apply(k, plant):
                c_true[:] = plant.c_true()
                if k % stride == 0 and j > 0:
                    lg.c_true[j - 1] = c_true  # this step's row shows the new plant
            obs.sample(k * dt, L_pose[k], L_vel[k], ctx.pose, ctx.vel)
            k1 = min(N, k + max_chunk)
            nxt = evq.next_step()
            if nxt is not None:
                k1 = min(k1, max(k + 1, nxt))
            for tn in obs.next:
                k1 = min(k1, max(k + 1, first_step_at(tn, dt)))
            try:
                done, j, status = run_chunk(k, k1, j)
            except Diverged as e:  # a MuJoCo warning: keep the log so far
                diverged = e
                k = e.step
                break
            k += done
            if status == GUARD_FAILED:
                diverged = Diverged(describe(ctx.diag, k * dt, ctx.bounds), step=k, time=k * dt)
            if progress is not None:
                progress(k, N)
    except KeyboardInterrupt as exc:
        interrupted = exc
    wall = time.perf_counter() - wall0
    pose, vel = ctx.pose.copy(), ctx.vel.copy()
    k_done = min(k, N)
    if diverged is None and not interrupted and not (np.all(np.isfinite(pose)) and np.all(np.isfinite(vel))):
        diverged = Diverged(f"non-finite robot state at the end of the run (t = {N * dt:g} s)", step=N, time=N * dt)
    if progress is not None and diverged is None and not interrupted:
        progress(N, N)
    state_obs.t, state_obs.pose, state_obs.vel = k_done * dt, pose, vel
    state_obs.leader_pose, state_obs.leader_vel = L_pose[k_done], L_vel[k_done]
    for o in observers:
        o.finish(state_obs)
    logd = {name: getattr(lg, name)[:j] for name in LogArrays._fields}
    for name in missing:
        logd[name] = np.full_like(logd[name], np.nan)
    if not odometry:  # the controllers used the truth
        logd["odom_pose"] = logd["pose"].copy()
        logd["odom_vel"] = logd["vel"].copy()
    logd["offsets"] = offsets
    if getattr(plant, "obstacles", None):  # design §19: drawn by the figures and rerun from the log
        from .obstacles import to_rows

        logd["obstacles"] = to_rows(plant.obstacles)
    logd["edges"] = graph.edges + 1
    logd["leader_access"] = graph.leader_access
    summary = _summary(
        sc,
        plant,
        controller,
        state,
        ctx.met,
        logd,
        L_pose[k_done],
        pose,
        vel,
        offsets,
        k_done,
        dt,
        wall,
        setup_s,
        diverged,
        interrupted,
        missing,
        engine="compiled" if chunk else "stepwise",
    )
    summary["feasibility_warnings"] = feasibility
    summary["sensing"] = "odometry" if odometry else "truth"
    drift = plant.odometry_drift() if odometry else None
    for i, f in enumerate(summary["followers"]):  # pose error of the odometry at the end (design §8.3)
        f["odometry_drift_m"] = None if drift is None else float(drift[i, 0])
        f["odometry_heading_drift_rad"] = None if drift is None else float(drift[i, 1])
    unmodelled = getattr(plant, "unmodelled", None)
    if unmodelled is not None and len(logd["vel"]):  # damping and frictionloss at the run's speeds
        v = float(np.abs(logd["vel"][:, :, 0]).max())
        w = float(np.abs(logd["vel"][:, :, 1]).max())
        for f, u in zip(summary["followers"], unmodelled(v, w)):
            f["unmodelled"] = u
    from .hardware import verdict  # design §19: would this run on the robots as specified?

    summary["hardware"] = verdict(sc, plant, summary, logd)
    return RunResult(sc, logd, summary, plant, diverged, interrupted)


def _shadow(state: StackState, sig: Any, tau: np.ndarray, missing: set[str]) -> None:
    """Copy a user controller's signals into the shadow state the metrics, guards and log read."""
    fields = {
        "est_pose": "est_pose",
        "est_vel": "est_vel",
        "cmd": "cmd",
        "dcmd": "dcmd",
        "tau_raw": "tau_raw",
        "c_hat": "c_hat",
        "z_hat": "z_hat",
        "vs": "vs",
        "tracking_error": "err",
        "saturated": "saturated",
    }
    for name, attr in fields.items():
        v = sig.get(name)
        if v is None:
            missing.add(name)
            if name == "tau_raw":
                state.tau_raw[:] = tau
            continue
        getattr(state, attr)[:] = v
    state.tau[:] = tau


#: outcome kinds, most severe first (``outcome`` is the first of a follower's ``outcomes``)
SEVERITY = ("tipped", "collided", "slipping", "spinning", "lost", "too_close", "c_hat_at_bound")

#: follower outcomes (design §8): thresholds
LOST_M = 1.0  # m: final formation error beyond this → lost ...
LOST_AFTER_S = 10.0  # s: ... once the run has had this long to converge (or if the error grew over the run)
SPIN_RAD_S = 6.0  # rad/s: |ω| beyond this over the last second → spinning


def _summary(
    sc,
    plant,
    controller,
    state,
    met,
    logd,
    lp_end,
    pose,
    vel,
    offsets,
    k_done,
    dt,
    wall,
    setup_s,
    diverged,
    interrupted,
    missing,
    engine,
) -> dict[str, Any]:
    n = sc.n
    final_form = np.linalg.norm(pose[:, :2] - slots_of(sc, lp_end), axis=1)
    est = state.est_pose if "est_pose" not in missing else np.full((n, 3), np.nan)
    final_est = np.linalg.norm(est[:, :2] - lp_end[None, :2], axis=1)
    fe = logd["formation_error"]
    half = fe[len(fe) // 2 :] if len(fe) else fe
    c_true = plant.c_true()
    c_hat = state.c_hat if "c_hat" not in missing else np.full((n, 2), np.nan)
    nan_if = lambda name, v: float("nan") if name in missing else float(v)  # noqa: E731
    outcomes = follower_outcomes(sc, plant, controller, logd, final_form, c_hat, dt)
    contact = _contact_outcomes(plant, n, dt)  # design §19: contacts and distances (MuJoCo)
    followers = []
    for i in range(n):
        every = contact[i][1]
        if outcomes[i][0] != "ok":
            every = every + [{"kind": outcomes[i][0], "detail": outcomes[i][1], "t": None}]
        every = sorted(every, key=lambda o: SEVERITY.index(o["kind"]) if o["kind"] in SEVERITY else len(SEVERITY))
        first = every[0] if every else {"kind": "ok", "detail": ""}
        followers.append(
            {
                "id": i + 1,
                "outcome": first["kind"],
                "outcome_detail": first["detail"],
                "outcomes": every,
                **contact[i][0],
                "total_velocity_error": nan_if("cmd", met.verr[i] * dt),
                "final_formation_error_m": float(final_form[i]),
                "rms_formation_error_m": float(np.sqrt(np.mean(fe[:, i] ** 2))) if len(fe) else float("nan"),
                "rms_formation_error_last_half_m": float(np.sqrt(np.mean(half[:, i] ** 2)))
                if len(half)
                else float("nan"),
                "final_estimation_error_m": float(final_est[i]),
                "max_abs_v_cmd": nan_if("cmd", met.vmax[i]),
                "peak_abs_torque": float(met.tau[i]),
                "peak_abs_torque_commanded": float(met.tau_raw[i]),
                "saturation_fraction": nan_if("saturated", met.sat[i] / max(1, k_done)),
                "c_hat": [float(v) for v in c_hat[i]],
                "c_true": [float(v) for v in c_true[i]],
                "c_hat_rel_error": [float(v) for v in (c_hat[i] / c_true[i] - 1.0)],
                **_robot_used(sc, plant, controller, i),
            }
        )
    return {
        "scenario": sc.name,
        "plant": sc.plant.kind,
        "method": sc.method if getattr(controller, "p", None) is not None else type(controller).__name__,
        "controller": type(controller).__name__,
        "engine": engine,
        "seed": sc.sim.seed,
        "sim_time_s": k_done * dt,
        "wall_time_s": wall,
        "setup_time_s": setup_s,
        "steps": k_done,
        "diverged": None
        if diverged is None
        else {"message": str(diverged), "time_s": diverged.time, "step": diverged.step},
        "interrupted": None
        if interrupted is None
        else {"signal": _signal_name(getattr(interrupted, "signum", 2)), "time_s": k_done * dt},
        "log_channels": {name: CHANNELS[name][1] for name in CHANNELS},
        "log_interval_means": list(MEAN_CHANNELS),
        "versions": _versions(),
        "config": sc.to_dict(),
        "followers": followers,
    }


def _contact_outcomes(plant: Any, n: int, dt: float) -> list[tuple[dict[str, Any], list[dict]]]:
    """Per follower the contact/proximity fields and outcomes (``collided``, ``too_close``) of a
    plant that watches them (:func:`bioform_mj.safety.follower_fields`); none for the others."""
    if not hasattr(plant, "contact_watch"):
        return [({}, []) for _ in range(n)]
    watch = plant.contact_watch()
    from .safety import follower_fields

    names = [o.name for o in getattr(plant, "obstacles", [])]
    return [follower_fields(watch, i, dt, names) for i in range(n)]


def _robot_used(sc: Scenario, plant: Any, controller: Any, i: int) -> dict[str, Any]:
    """What follower ``i``'s robot really was: torque limit, mass, yaw inertia (design §9)."""
    p = getattr(controller, "p", None)
    out: dict[str, Any] = {"tau_max_nm": float(np.broadcast_to(p.tau_max, (sc.n,))[i]) if p is not None else None}
    params = getattr(plant, "params", None)
    if params is not None:
        rp = params[i]
        out["mass_kg"] = float(rp.mass)
        out["yaw_inertia_kgm2"] = float(rp.yaw_inertia)
    else:
        mass = getattr(plant, "mass", None)
        inertia = getattr(plant, "inertia", None)
        out["mass_kg"] = None if mass is None else float(mass[i])
        out["yaw_inertia_kgm2"] = None if inertia is None else float(inertia[i])
    return out


def follower_outcomes(
    sc: Scenario,
    plant: Any,
    controller: Any,
    logd: dict[str, np.ndarray],
    final_form: np.ndarray,
    c_hat: np.ndarray,
    dt: float,
) -> list[tuple[str, str]]:
    """Per follower ``(outcome, detail)``: ``ok`` or the first failure of ``tipped`` (tilt beyond
    the plant's ``TIP_ANGLE_DEG``, with the time), ``slipping`` (a wheel's slip ratio beyond the
    plant's ``SLIP_RATIO`` for ``SLIP_TIME`` s), ``spinning`` (|ω| > :data:`SPIN_RAD_S` over
    the last second), ``lost`` (final formation error > :data:`LOST_M` after
    :data:`LOST_AFTER_S` s, or grown by half over a shorter run), ``c_hat_at_bound``
    (a learned parameter at its projection bound at the end)."""
    n = sc.n
    out: list[tuple[str, str]] = []
    tip = getattr(plant, "tip_step", None)
    slip = getattr(plant, "slip_step", None)
    p = getattr(controller, "p", None)
    t = logd["t"]
    last = t >= (t[-1] - 1.0) if len(t) else np.zeros(0, bool)
    for i in range(n):
        if tip is not None and tip[i] >= 0:
            from .plants.mujoco_plant import TIP_ANGLE_DEG

            out.append(("tipped", f"tilt beyond {TIP_ANGLE_DEG:g} deg at t = {tip[i] * dt:.3f} s"))
            continue
        if slip is not None and slip[i] >= 0:
            out.append(
                (
                    "slipping",
                    f"wheel slip ratio > {plant.SLIP_RATIO:g} for {plant.SLIP_TIME:g} s, by t = {slip[i] * dt:.3f} s",
                )
            )
            continue
        if len(t) and np.all(np.abs(logd["vel"][last, i, 1]) > SPIN_RAD_S):
            out.append(("spinning", f"|omega| > {SPIN_RAD_S:g} rad/s over the last second"))
            continue
        fe0 = float(logd["formation_error"][0, i]) if len(t) else 0.0
        t_end = float(t[-1]) if len(t) else 0.0
        if final_form[i] > LOST_M and (t_end >= LOST_AFTER_S - 1e-9 or final_form[i] > 1.5 * fe0):
            out.append(("lost", f"final formation error {final_form[i]:.3g} m > {LOST_M:g} m"))
            continue
        if p is not None and p.learning:
            lo = np.broadcast_to(p.c_min, (n, 2))[i]
            hi = np.broadcast_to(p.c_max, (n, 2))[i]
            at = [k for k in range(2) if c_hat[i, k] <= lo[k] * (1 + 1e-9) or c_hat[i, k] >= hi[k] * (1 - 1e-9)]
            if at:
                out.append(("c_hat_at_bound", "learned " + ", ".join("ab"[k] for k in at) + " at its bound"))
                continue
        out.append(("ok", ""))
    return out


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


def _signal_name(signum: int) -> str:
    import signal

    try:
        return signal.Signals(signum).name
    except ValueError:
        return str(signum)


def _versions() -> dict[str, str]:
    out = {"bioform_mj": __version__, "numpy": np.__version__, "python": platform.python_version()}
    try:
        import mujoco

        out["mujoco"] = mujoco.__version__
    except ImportError:  # pragma: no cover - mujoco is a dependency
        out["mujoco"] = "not installed"
    return out

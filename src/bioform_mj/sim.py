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
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from .control.kernel import StackState, new_state
from .control.stack import ControlStack, StackParams, parse_method
from .disturbance import Harmonic as HarmonicDisturbance
from .engine import (
    GUARD_FAILED,
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
from .errors import ControllerError, Diverged, RobotWarning
from .outcomes import (  # noqa: F401 - re-exported: sim is where callers have found them
    C_HAT_BOUND_BAND,
    C_HAT_OFF,
    LOST_AFTER_S,
    LOST_FRACTION,
    LOST_M,
    OUTCOME_ORDER,
    SPIN_RAD_S,
    braking_casters,
    follower_outcomes,
    lost_threshold_m,
    outcome_kinds,
    outcome_list,
    slots_of,
    unmodelled_causes,
)
from .plants.base import Plant
from .plants.ideal import IdealPlant
from .runsummary import _signal_name, _summary, _versions  # noqa: F401 - sim's own names
from .scenario import Scenario
from .userhooks import (  # noqa: F401 - simulate's checks, importable from sim as before
    CONTROLLER_METHODS,
    OBSERVER_METHODS,
    _add_outcome,
    _checked_torques,
    _tag,
    check_controller,
    check_observers,
)

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

    def table(self) -> Any:
        """The log as a tidy ``pyarrow.Table``: one row per log sample and follower (``K × n`` rows,
        sample-major), columns ``t_s``, ``follower`` (1-based) and one per channel component with its
        unit in the name (``pose_x_m``, ``tau_left_Nm``, ``formation_error_m``; :mod:`bioform_mj.logtable`),
        each field's unit in its metadata, scenario name, plant and method in the schema's."""
        from .logtable import to_arrow

        sc = self.scenario
        return to_arrow(self.log, {"scenario": sc.name, "plant": sc.plant.kind, "method": sc.method})

    to_arrow = table

    def to_pandas(self) -> Any:
        """:meth:`table` as a pandas DataFrame (needs pandas)."""
        return self.table().to_pandas()

    def to_polars(self) -> Any:
        """:meth:`table` as a polars DataFrame (needs polars)."""
        import polars as pl

        return pl.from_arrow(self.table())


def import_warnings(plant: Any) -> list[str]:
    """Each guess a format import made (URDF, design §12), once per robot file: ``"FILE: note"``
    (empty for MJCF robots and the ideal plant)."""
    out: list[str] = []
    seen: set[str] = set()
    for lay in getattr(plant, "layouts", ()):
        if lay.file in seen:
            continue
        seen.add(lay.file)
        out += [f"{Path(lay.file).name}: {n}" for n in lay.import_notes]
    return out


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
        kk=np.array(sc.learner.drag_gain) if sc.learner.drag else np.zeros(2),
        k_max=float(sc.learner.drag_max) if sc.learner.drag else 0.0,
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

    A user's ``controller`` and ``observers`` are checked before any step (design §17): a
    missing protocol method is a :class:`~bioform_mj.errors.ControllerError`. Torques that
    are not ``(n, 2)`` raise one at the step; non-finite torques stop the run as a divergence
    whose followers get the outcome ``controller_nonfinite``. An exception raised by the
    controller or an observer mid-run ends the run: the log up to the last good step is kept
    in a :class:`RunResult` attached to the exception as ``result`` (with ``summary["raised"]``
    saying what raised where), a note naming the controller or observer is added to the
    exception, and it is re-raised.
    """
    if engine not in ENGINES:
        raise ValueError(f"unknown engine '{engine}' (expected one of: {', '.join(ENGINES)})")
    if controller is not None:
        check_controller(controller)
    check_observers(observers)
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

    imported = import_warnings(plant)  # design §12: the guesses of a URDF import, said before the run
    for line in imported:
        warnings.warn(line, RobotWarning, stacklevel=2)
    feasibility: list[str] = []
    if hasattr(plant, "params") and hasattr(plant, "model"):  # MuJoCo robots: what the scenario asks of them
        from .robot_check import feasibility as _feasibility

        feasibility = _feasibility(sc, plant)  # in summary.json too
        for line in feasibility:
            warnings.warn(line, RobotWarning, stacklevel=2)  # before the run (the CLI prints warning: lines)
    plant.reset()
    pose0, vel0 = plant.observe()
    try:
        controller.reset(initial_estimates(sc, pose0, L_pose[0]), vel0)
    except Exception as exc:
        exc.add_note(f"bioform: raised by controller {type(controller).__name__}.reset, before the first step")
        raise
    faults = None  # fault injection (faults.py): built only when configured, else no per-step cost
    if sc.faults.per_step:  # (a friction patch is in the MuJoCo scene: nothing per step)
        from .faults import Faults

        p = getattr(controller, "p", None)
        faults = Faults(sc, graph, np.asarray(p.tau_max if p is not None else np.full(n, sc.torque.tau_max)))
        if faults.has_act and faults.act_known and not callable(getattr(controller, "set_tau_max", None)):
            raise ControllerError(  # design §17: named before any step, not an AttributeError mid-run
                f"controller {type(controller).__name__} has no set_tau_max(tau_max) method, which "
                "faults.actuator_known = true calls when a motor weakens (add it, or set actuator_known = false)"
            )
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

    cname = type(controller).__name__
    nonfinite: dict[str, Any] = {}  # design §17: a user's controller returned NaN/inf torques

    def control(k: int) -> np.ndarray:
        """Control step ``k`` on the current measurements; the torques to apply."""
        mp, mv = measure()
        try:
            if faults is None:
                tau = controller.step(L_pose[k], L_vel[k], mp, mv)
            else:  # noisy sensing, faulty network, weakened motors, pushes; tau = what reaches the plant
                tau = faults.step(k, k * dt, controller, plant, L_pose[k], L_vel[k], mp, mv)
        except Exception as exc:
            _tag(exc, f"controller {cname}.step", k, k * dt)
            raise
        if not own_stack:
            tau = _checked_torques(tau, n, cname, k, dt)
            bad = ~np.all(np.isfinite(tau), axis=1)
            if bad.any():
                nonfinite.update(k=k, rows=np.flatnonzero(bad), tau=tau.copy())
                i = int(nonfinite["rows"][0])
                raise Diverged(
                    f"follower {i + 1}: controller {cname}.step returned non-finite torques {tau[i].tolist()} "
                    f"at t = {k * dt:.4f} s (step {k})",
                    step=k,
                    time=k * dt,
                )
        if kernel is None:
            try:
                sig = controller.signals()
            except Exception as exc:
                _tag(exc, f"controller {cname}.signals", k, k * dt)
                raise
            try:
                _shadow(state, sig, tau, missing)
            except (ValueError, TypeError) as exc:  # a signal of the wrong shape
                err = ControllerError(f"controller {cname}.signals() at step {k}: {exc}")
                _tag(err, f"controller {cname}.signals", k, k * dt)
                raise err from exc
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
    at = [0, 0]  # (steps done, log rows) of the Python chunk so far: kept when a step raises

    def python_chunk(k0: int, k1: int, j: int) -> tuple[int, int, int]:
        """The same contract as a compiled chunk, one Python call per step."""
        at[:] = k0, j
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
                at[:] = k + 1, j
                if status != OK:
                    return k + 1 - k0, j, status
        return k1 - k0, j, OK

    if progress is not None and hasattr(progress, "phase"):
        progress.phase("loading compiled kernels (compiling them on the first run)")
    # control step 0 and its row, then a zero-length chunk: kernels are loaded (or compiled) here,
    # outside the timed loop
    diverged: Diverged | None = None
    raised: Exception | None = None  # what a user's controller or observer raised (design §17)
    j, status = 0, OK
    try:
        applied[0] = control(0)
        j, status = record(0, 0)
    except Diverged as e:  # non-finite torques of a user's controller at step 0
        diverged = e
    except Exception as exc:  # noqa: BLE001 - re-raised below, with the log so far attached
        raised = exc
    if odometry and j > 0:
        record_odometry(lg, 0, plant.odo.mpose, plant.odo.mvel)
    run_chunk = chunk if chunk is not None else python_chunk
    run_chunk(0, 0, j)
    setup_s = time.perf_counter() - t_setup
    if progress is not None and hasattr(progress, "phase"):
        progress.phase(None)

    state_obs = RunState(sc, plant, controller)
    started: list[Observer] = []
    if raised is None:
        try:
            for o in observers:
                try:
                    o.start(state_obs)
                except Exception as exc:
                    _tag(exc, f"observer {type(o).__name__}.start", 0, 0.0)
                    raise
                started.append(o)
        except Exception as exc:  # noqa: BLE001 - re-raised below
            raised = exc
    obs = ObserverClock(observers, state_obs)
    evq = EventQueue(sc.events, dt)
    wall0 = time.perf_counter()
    interrupted: KeyboardInterrupt | None = None
    k = 0
    if status != OK and diverged is None:
        diverged = Diverged(describe(ctx.diag, 0.0, ctx.bounds), step=0, time=0.0)
    try:
        max_chunk = max(1, int(round(MAX_CHUNK_S / dt)))
        while k < N and diverged is None and raised is None:
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
            except Diverged as e:  # a MuJoCo warning, a user's non-finite torques: keep the log so far
                diverged = e
                if nonfinite:  # ours (a user's controller, stepwise): the rows of this chunk are kept
                    j = at[1]
                k = e.step
                break
            except Exception as exc:  # noqa: BLE001 - a user's controller raised: re-raised below
                raised = exc
                if chunk is None:  # the steps the plant made (the failing control step's index), the rows kept
                    k, j = int(getattr(exc, "_bioform_step", at[0])), at[1]
                break
            k += done
            if status == GUARD_FAILED:
                diverged = Diverged(describe(ctx.diag, k * dt, ctx.bounds), step=k, time=k * dt)
            if progress is not None:
                progress(k, N)
    except KeyboardInterrupt as exc:
        interrupted = exc
    except Exception as exc:  # noqa: BLE001 - an observer's sample raised: re-raised below
        raised = exc
    wall = time.perf_counter() - wall0
    pose, vel = ctx.pose.copy(), ctx.vel.copy()
    k_done = min(k, N)
    if (
        diverged is None
        and not interrupted
        and raised is None
        and not (np.all(np.isfinite(pose)) and np.all(np.isfinite(vel)))
    ):
        diverged = Diverged(f"non-finite robot state at the end of the run (t = {N * dt:g} s)", step=N, time=N * dt)
    if progress is not None and diverged is None and not interrupted and raised is None:
        progress(N, N)
    state_obs.t, state_obs.pose, state_obs.vel = k_done * dt, pose, vel
    state_obs.leader_pose, state_obs.leader_vel = L_pose[k_done], L_vel[k_done]
    culprit = getattr(raised, "_bioform_source", None)
    for o in started:
        if (
            culprit is not None
            and culprit == f"observer {type(o).__name__}.sample"
            and o is getattr(raised, "_bioform_obj", None)
        ):
            continue  # the observer that failed is not asked to finish
        try:
            o.finish(state_obs)
        except Exception as exc:
            if raised is not None:  # already failing: say it, keep the first error
                raised.add_note(f"(observer {type(o).__name__}.finish also raised {type(exc).__name__}: {exc})")
                continue
            _tag(exc, f"observer {type(o).__name__}.finish", k_done, k_done * dt)
            raised = exc
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
    summary["import_warnings"] = imported
    summary["sensing"] = "odometry" if odometry else "truth"
    drift = plant.odometry_drift() if odometry else None
    for i, f in enumerate(summary["followers"]):  # pose error of the odometry at the end (design §8.3)
        f["odometry_drift_m"] = None if drift is None else float(drift[i, 0])
        f["odometry_heading_drift_rad"] = None if drift is None else float(drift[i, 1])
    if nonfinite:  # design §17: the followers whose torques the user's controller made NaN/inf
        kn = int(nonfinite["k"])
        for i in nonfinite["rows"]:
            _add_outcome(
                summary["followers"][int(i)],
                "controller_nonfinite",
                f"{cname}.step returned torques {nonfinite['tau'][int(i)].tolist()} N·m at t = {kn * dt:.4f} s "
                f"(step {kn})",
                kn * dt,
            )
    if raised is not None:
        src = getattr(raised, "_bioform_source", "the loop")
        ks = int(getattr(raised, "_bioform_step", k_done))
        summary["raised"] = {
            "by": src,
            "error": f"{type(raised).__name__}: {raised}",
            "step": ks,
            "time_s": ks * dt,
        }
    unmodelled = getattr(plant, "unmodelled", None)
    if unmodelled is not None and len(logd["vel"]):  # damping and frictionloss at the run's speeds
        v = float(np.abs(logd["vel"][:, :, 0]).max())
        w = float(np.abs(logd["vel"][:, :, 1]).max())
        for f, u in zip(summary["followers"], unmodelled(v, w)):
            f["unmodelled"] = u
    from .hardware import verdict  # design §19: would this run on the robots as specified?

    summary["hardware"] = verdict(sc, plant, summary, logd)
    result = RunResult(sc, logd, summary, plant, diverged, interrupted)
    if raised is not None:
        raised.result = result  # type: ignore[attr-defined]
        raised.add_note(
            f"bioform: raised by {summary['raised']['by']} at t = {summary['raised']['time_s']:.4f} s "
            f"(step {summary['raised']['step']}); the run stopped there, its log up to the last good step "
            f"({len(logd['t'])} rows) is in this exception's .result (a RunResult)"
        )
        raise raised
    return result


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
                try:
                    o.sample(st)
                except Exception as exc:
                    _tag(exc, f"observer {type(o).__name__}.sample", int(round(t / st.scenario.sim.control_dt)), t)
                    exc._bioform_obj = o  # type: ignore[attr-defined]
                    raise
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

"""The closed loop: scenario in, plant and controller built (or given), log and summary out.

One driver runs every loop: between the points where Python must act (events,
observers, progress, interrupts) it calls a *chunk* of control periods. Where the plant
offers a compiled chunk (``plant.compiled_chunk``) and the controller exposes a compiled
kernel (``controller.kernel``), the chunk runs in machine code; otherwise (injected
faults, a user's controller, ``engine="stepwise"``, ``NUMBA_DISABLE_JIT=1``) it runs step
by step in Python. Both call the same compiled equations and the same metric, log and
guard functions (``core/engine.py``), so the two engines agree bit for bit on one machine
(docs/design.md §9). :func:`simulate` resolves, builds, runs the loop (``run/loop.py``) and
summarises (``run/summary.py``).
"""

from __future__ import annotations

import logging
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple, Protocol

import numpy as np

from bioform_mj.assess.outcomes import (
    slots_of,
)
from bioform_mj.control.base import Obstacles
from bioform_mj.control.kernel import new_state
from bioform_mj.control.registry import build_controller, is_builtin
from bioform_mj.core.engine import Bounds, Formation, LogArrays, Loop, new_acc, new_log, new_metrics
from bioform_mj.core.errors import ControllerError, Diverged, OutcomeWarning, RobotWarning
from bioform_mj.formation.disturbance import Harmonic as HarmonicDisturbance
from bioform_mj.outputs.mjlog import api_warnings
from bioform_mj.plants.base import CompiledChunk, Plant, RobotModels, Sensing, Unmodelled
from bioform_mj.plants.ideal import IdealPlant
from bioform_mj.plants.registry import plant_factory, register_plant
from bioform_mj.run.demand import register_loop
from bioform_mj.run.hooks import (
    _add_outcome,
    check_controller,
    check_observers,
)
from bioform_mj.run.loop import (
    LoopEnd,
    Stepper,
    finish_observers,
    run_loop,
    start_observers,
    warm_up,
)
from bioform_mj.run.summary import RunEnd, _summary
from bioform_mj.scenario.config import Scenario
from bioform_mj.scenario.loader import checked

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
    #: CPU seconds this process spent in the loop (``time.process_time``; the summary's ``wall_time_s`` is wall
    #: time): the loop's own cost on a shared machine, read by ``bioform bench``; kept out of the summary, which
    #: is the same for the same seed apart from its wall times
    loop_cpu_s: float = float("nan")

    def table(self) -> Any:
        """The log as a tidy ``pyarrow.Table``: one row per log sample and follower (``K × n`` rows,
        sample-major), columns ``t_s``, ``follower`` (1-based) and one per channel component with its
        unit in the name (``pose_x_m``, ``tau_left_Nm``, ``formation_error_m``; :mod:`bioform_mj.run.logtable`),
        each field's unit in its metadata, scenario name, plant and method in the schema's."""
        from bioform_mj.run.logtable import to_arrow

        sc = self.scenario
        return to_arrow(self.log, {"scenario": sc.name, "plant": sc.plant.kind, "method": sc.method})

    to_arrow = table

    def to_pandas(self) -> Any:
        """:meth:`table` as a pandas DataFrame (needs pandas, which the package does not install)."""
        _need("pandas")
        return self.table().to_pandas()

    def to_polars(self) -> Any:
        """:meth:`table` as a polars DataFrame (needs polars, which the package does not install)."""
        _need("polars")
        import polars as pl

        return pl.from_arrow(self.table())


def _need(module: str) -> None:
    """Raise ``ModuleNotFoundError`` saying how to install ``module`` when it is not installed
    (pyarrow's own error would name only the missing import, from inside pyarrow)."""
    import importlib.util

    if importlib.util.find_spec(module) is None:
        raise ModuleNotFoundError(
            f"RunResult.to_{module}() needs {module}, which is not installed: pip install {module} "
            f"(RunResult.table() gives the same table as pyarrow, which is installed)",
            name=module,
        )


def import_warnings(plant: Any) -> list[str]:
    """Each guess a format import made (URDF, design §12), once per robot file: ``"FILE: note"``
    (empty for MJCF robots and the ideal plant)."""
    out: list[str] = []
    seen: set[str] = set()
    for lay in plant.layouts if isinstance(plant, RobotModels) else ():
        if lay.file in seen:
            continue
        seen.add(lay.file)
        out += [f"{Path(lay.file).name}: {n}" for n in lay.import_notes]
    return out


def make_plant(sc: Scenario) -> Plant:
    """The plant named by ``sc.plant.kind``, at the scenario's initial poses: the factory registered for that kind
    (:func:`bioform_mj.plants.registry.register_plant`; the shipped ones below, registered when this module is
    imported)."""
    return plant_factory(sc.plant.kind)(sc)


def _disturbance(sc: Scenario) -> HarmonicDisturbance:
    """The scenario's harmonic disturbance ``d(t)`` (eq. 34)."""
    return HarmonicDisturbance(sc.n, sc.disturbance.bias, sc.disturbance.amp, sc.disturbance.freq, sc.disturbance.phase)


def ideal_plant(sc: Scenario) -> IdealPlant:
    """The paper's ideal plant (eq. 34) of ``sc``: ``plant.c_true``, optional lumped mass and inertia."""
    return IdealPlant(
        np.array(sc.plant.c_true),
        sc.initial_poses(),
        sc.sim.control_dt,
        sc.sim.physics_dt,
        _disturbance(sc),
        mass=sc.plant.mass,
        inertia=sc.plant.inertia,
    )


def mujoco_plant(sc: Scenario) -> Plant:
    """The MuJoCo plant of ``sc``'s robots (design §8, §12, §19): sensing, friction patch, obstacles; refuses
    impossible initial poses (InputError) and warns where contacts are not watched."""
    poses = sc.initial_poses()
    dist = _disturbance(sc)
    from bioform_mj.plants.mujoco.plant import MujocoPlant  # imported only when asked: the ideal plant needs no MuJoCo
    from bioform_mj.robots.entries import resolve_robot

    robots = list(sc.plant.robots) * (sc.n if len(sc.plant.robots) == 1 else 1)
    refs = [resolve_robot(r) for r in robots]
    pc = sc.plant
    sensing = {}
    if pc.sensing == "odometry":  # design §8.3: encoders (the scenario's cpr or each robot file's) and gyro
        from bioform_mj.scenario.check import robot_encoder_cpr

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
        from bioform_mj.core.errors import InputError

        jit = (
            f" (formation.init_jitter = {sc.formation.init_jitter:g} m, seed {sc.sim.seed})"
            if sc.formation.init_jitter
            else ""
        )
        raise InputError("impossible initial poses" + jit + ": " + "; ".join(bad))
    return plant


register_plant("ideal", ideal_plant)
register_plant("mujoco", mujoco_plant)


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


#: what a plant's compiled chunk shares with this driver (kept under its old name)
LoopContext = Loop


@api_warnings  # MuJoCo's warnings as Python warnings, not a MUJOCO_LOG.TXT in the caller's folder (issue 28)
def simulate(
    sc: Scenario,
    observers: Sequence[Observer] = (),
    progress: Any = None,
    engine: str = "auto",
    record_inputs: tuple[np.ndarray, np.ndarray] | None = None,
    *,
    plant: Plant | None = None,
    controller: Any = None,
    full_state: bool = False,
) -> RunResult:
    """Run the closed loop of ``sc`` and return its log and summary.

    Parameters
    ----------
    sc
        The scenario (:func:`~bioform_mj.scenario.loader.load`), checked again here as a file is.
    observers
        Objects that watch the run at their own period of simulated time (``period`` in s;
        ``start``/``sample``/``finish``): video, rerun, one's own.
    progress
        Called as ``progress(k, N)`` with the control step ``k`` of ``N``; a ``phase(text)`` method, if
        present, is told when kernels load or compile. ``None``: silent.
    engine
        ``"auto"`` (compiled where plant and controller allow it), ``"compiled"`` (refuse if they do
        not) or ``"stepwise"`` (one Python call per control step; the same compiled equations, the same
        bits).
    record_inputs
        Compiled MuJoCo loop only: arrays ``(N, nu)`` and ``(N, n, 6)`` that receive each step's ``ctrl``
        (N·m or the actuator's unit) and chassis ``xfrc_applied`` (N, N·m), for a bare replay.
    plant
        A :class:`~bioform_mj.plants.base.Plant`; ``None``: built from ``sc.plant``.
    controller
        A :class:`~bioform_mj.control.base.Controller`; ``None``: the one registered as ``sc.method``
        (the paper's stack for its four methods, :mod:`bioform_mj.control.registry`).
    full_state
        Also log the 3-D state, wheel angles and speeds, the IMU and the leader's state with a last sample
        at t = T (what a ROS 2 bag needs, :mod:`bioform_mj.outputs.rosbag`); off: the log of before.

    Returns
    -------
    RunResult
        The log (SI units, one row per log sample) and ``summary`` (metrics, outcomes, the robot).

    A divergence (NaN/inf or a state beyond ``sc.limits``, checked after every control
    step; a MuJoCo warning) stops the loop; the result then holds the log up to the last
    good row and ``diverged`` says why. A ``KeyboardInterrupt`` stops it too
    (``interrupted``). ``progress``, if given, is called as ``progress(k, N)``; if it has a
    ``phase(text)`` method it is told when kernels load or compile.

    A user's ``controller`` and ``observers`` are checked before any step (design §17): a
    missing protocol method is a :class:`~bioform_mj.core.errors.ControllerError`. Torques that
    are not ``(n, 2)`` raise one at the step; non-finite torques stop the run as a divergence
    whose followers get the outcome ``controller_nonfinite``. An exception raised by the
    controller or an observer mid-run ends the run: the log up to the last good step is kept
    in a :class:`RunResult` attached to the exception as ``result`` (with ``summary["raised"]``
    saying what raised where), a note naming the controller or observer is added to the
    exception, and it is re-raised.

    ``sc`` is checked as :func:`~bioform_mj.scenario.loader.load` checks a file, before any work (the same
    :class:`~bioform_mj.core.errors.InputError` and message: a NaN gain set by ``dataclasses.replace`` is
    refused), and a ``formation.scale`` changed after loading is applied (``result.scenario`` is then
    the scaled scenario; design §18.1). Every follower whose run did not end ``ok`` (tipped, lost, ...)
    gets one :class:`~bioform_mj.core.errors.OutcomeWarning` naming it and every outcome with its detail,
    and a divergence one more (filter the class to silence them: the outcomes stay in the summary);
    none when a user's controller or observer raised (the exception is the news).
    """
    # resolve: the scenario (checked as load checks a file), the arguments, the graph, the leader's path
    sc = checked(sc)
    _check_arguments(engine, controller, observers)
    t_setup = time.perf_counter()
    graph = sc.build_graph()
    traj = sc.build_leader()
    # build the plant and the controller, say what the run will meet, and reset them
    if plant is None:
        plant = make_plant(sc)
    named = controller is None  # built from the registry: the summary's method is sc.method
    controller, own_stack = _build_controller(sc, plant, controller)
    tl = _timeline(sc, traj)
    warned = _warn_before_run(sc, plant)
    pose0, vel0 = _reset(sc, plant, controller, tl.L_pose[0])
    faults = _build_faults(sc, graph, controller)
    # the loop: its shared arrays, a compiled chunk where possible, warm-up, observers, chunks to the end
    ctx, kernel = _loop_context(sc, controller, tl, pose0, vel0)
    chunk = _compiled_chunk(engine, plant, ctx, kernel, faults, record_inputs)
    c_true = np.ascontiguousarray(plant.c_true(), dtype=float)
    # design §8.3: with sensing = "odometry" the controllers get each robot's dead reckoning
    # (plant.measurement), everything else (metrics, guards, formation error, outcomes) the truth
    odometry = isinstance(plant, Sensing) and plant.sensing == "odometry"
    missing: set[str] = set()  # the signals a user's controller does not give
    step = Stepper(ctx, sc.n, plant, controller, faults, own_stack, kernel, c_true, odometry, missing)
    run_chunk = chunk if chunk is not None else step.python_chunk
    warm = warm_up(step, run_chunk, progress, t_setup)
    state_obs = RunState(sc, plant, controller)
    sampler = None
    if full_state:  # the 3-D state at the log's rows (outputs/fullstate.py): a ROS 2 bag's needs
        from bioform_mj.outputs.fullstate import StateSampler

        sampler = StateSampler(sc.sim.log_dt, sc.sim.control_dt, in_kernel=chunk is not None)
        observers = [*observers, sampler]
    started, raised = start_observers(observers, state_obs, warm.raised)
    end = run_loop(sc, step, run_chunk, chunk is not None, observers, state_obs, warm, raised, progress)
    raised = finish_observers(started, state_obs, step, end)
    # summarise: the log, summary.json, the result (attached to what a user's code raised)
    logd = _log_dict(plant, graph, ctx.log, end.j, missing, odometry, tl.offsets)
    if sampler is not None:
        logd.update(sampler.log_arrays(logd))
    engine_used = "compiled" if chunk else "stepwise"
    summary = _summarise(sc, plant, controller, step, end, logd, warm.setup_s, engine_used, warned)
    if named:  # a registered controller is named by its method (a given one by its class)
        summary["method"] = sc.method
    _add_run_notes(summary, sc, plant, step, end, logd, raised)
    result = RunResult(sc, logd, summary, plant, end.diverged, end.interrupted, end.cpu)
    if raised is not None:  # the exception says the run failed (its summary holds the outcomes so far)
        raise _with_result(raised, result)
    for w in outcome_warnings(summary):  # never silent (design §18.1): the CLI prints its own lines instead
        warnings.warn(w, stacklevel=3)  # the caller of simulate, past its api_warnings wrapper
    return result


register_loop(simulate)  # the demand's ideal twin runs on this loop (run/demand.py cannot import it)


def outcome_warnings(summary: dict[str, Any]) -> list[OutcomeWarning]:
    """What :func:`simulate` warns of a run's ``summary``: per follower with outcomes one
    :class:`OutcomeWarning` ``"SCENARIO / METHOD: follower I: KIND (DETAIL); KIND (DETAIL)"``, the
    CLI's ``warning:`` lines joined (``clireport._warn_outcomes``), and one for a divergence."""
    head = f"{summary.get('scenario', '')} / {summary.get('method', '')}: "
    out = []
    for f in summary["followers"]:
        got = f.get("outcomes") or []
        if got:
            said = "; ".join(f"{o['kind']} ({o['detail']})" for o in got)
            out.append(OutcomeWarning(f"{head}follower {f['id']}: {said}", int(f["id"]), got))
    div = summary.get("diverged")
    if div is not None:
        out.append(OutcomeWarning(f"{head}the simulation diverged at t = {div['time_s']:g} s: {div['message']}"))
    return out


def _check_arguments(engine: str, controller: Any, observers: Sequence[Observer]) -> None:
    """The engine's name; a user's controller and observers (design §17)."""
    if engine not in ENGINES:
        raise ValueError(f"unknown engine '{engine}' (expected one of: {', '.join(ENGINES)})")
    if controller is not None:
        check_controller(controller)
    check_observers(observers)


def _build_controller(sc: Scenario, plant: Plant, controller: Any) -> tuple[Any, bool]:
    """``(controller, own_stack)``: the user's, or the one registered as ``sc.method`` (the paper's stack for
    its four methods: ``own_stack`` True; design §22); both the plant and the controller must have the
    scenario's ``n`` followers. A registered user's controller is checked as a given one is."""
    own_stack = controller is None and is_builtin(sc.method)
    if controller is None:
        controller = build_controller(sc.method, sc, plant)
        if not own_stack:
            check_controller(controller)
    n = sc.n
    if getattr(controller, "n", n) != n or getattr(plant, "n", n) != n:
        raise ValueError(f"the scenario has {n} followers, the plant {plant.n} and the controller {controller.n}")
    return controller, own_stack


class _Timeline(NamedTuple):
    """The run's steps and the leader's path: ``N`` control steps of ``dt`` s, a log row every
    ``stride``; the leader at every step ``L_pose`` (N+1, 3), ``L_vel`` (N+1, 2); the formation."""

    dt: float
    N: int
    stride: int
    L_pose: np.ndarray
    L_vel: np.ndarray
    offsets: np.ndarray  # (n, 2) m
    form: Formation


def _timeline(sc: Scenario, traj: Any) -> _Timeline:
    n = sc.n
    dt = sc.sim.control_dt
    N = max(1, int(round(sc.sim.duration / dt)))
    stride = max(1, int(round(sc.sim.log_dt / dt)))
    t_all = np.arange(N + 1) * dt
    L_pose, L_vel, _ = traj.states(t_all)  # analytic, all steps at once
    L_pose = np.ascontiguousarray(L_pose, dtype=float)
    L_vel = np.ascontiguousarray(L_vel, dtype=float)
    offsets = np.ascontiguousarray(sc.formation.offsets, dtype=float).reshape(n, 2)
    form = Formation(offsets, sc.formation.frame == "leader")
    return _Timeline(dt, N, stride, L_pose, L_vel, offsets, form)


def _warn_before_run(sc: Scenario, plant: Plant) -> tuple[list[str], list[str], dict | None, dict | None]:
    """``(imported, feasibility, robot_check, demand)``: the guesses of a URDF import (design §12), what the
    scenario asks of the MuJoCo robots (``assess.feasibility.feasibility``) and what ``robot check`` fails
    them for (``prerun.before_run``, design §14.2; None for other plants), warned before the run (the
    CLI prints ``warning:`` lines) and kept for summary.json."""
    imported = import_warnings(plant)  # design §12: the guesses of a URDF import, said before the run
    for line in imported:
        warnings.warn(line, RobotWarning, stacklevel=4)  # simulate's caller, past its api_warnings wrapper
    feasibility: list[str] = []
    if isinstance(plant, RobotModels):  # robots from model files: what the scenario asks of them
        from bioform_mj.assess.feasibility import feasibility as _feasibility

        feasibility = _feasibility(sc, plant)  # in summary.json too
        for line in feasibility:
            warnings.warn(line, RobotWarning, stacklevel=4)  # before the run (the CLI prints warning: lines)
    checked = None
    if sc.plant.kind == "mujoco" and isinstance(plant, RobotModels):  # the scenario's robots are the plant's
        from bioform_mj.assess.prerun import before_run  # design §14.2: once per robot, cached

        checked = before_run(sc, plant)
        for line in checked["warnings"]:
            warnings.warn(line, RobotWarning, stacklevel=4)
    demand = None
    if checked is not None and not checked.get("skipped"):  # design §21: the scenario's demand vs the limits
        from bioform_mj.run.demand import before_run as _demand

        demand = _demand(sc, plant, checked)
        for line in demand["warnings"]:
            warnings.warn(line, RobotWarning, stacklevel=4)
    return imported, feasibility, checked, demand


def _reset(sc: Scenario, plant: Plant, controller: Any, leader_pose0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reset the plant, then the controller on its first measurement; returns ``(pose0, vel0)``."""
    plant.reset()
    pose0, vel0 = plant.observe()
    try:
        controller.reset(initial_estimates(sc, pose0, leader_pose0), vel0)
    except Exception as exc:
        exc.add_note(f"bioform: raised by controller {type(controller).__name__}.reset, before the first step")
        raise
    return pose0, vel0


def _build_faults(sc: Scenario, graph: Any, controller: Any) -> Any:
    """Fault injection (faults.py): built only when configured, else None (no per-step cost)."""
    faults = None
    if sc.faults.per_step:  # (a friction patch is in the MuJoCo scene: nothing per step)
        from bioform_mj.run.faults import Faults

        p = getattr(controller, "p", None)
        faults = Faults(sc, graph, np.asarray(p.tau_max if p is not None else np.full(sc.n, sc.torque.tau_max)))
        if faults.has_act and faults.act_known and not callable(getattr(controller, "set_tau_max", None)):
            raise ControllerError(  # design §17: named before any step, not an AttributeError mid-run
                f"controller {type(controller).__name__} has no set_tau_max(tau_max) method, which "
                "faults.actuator_known = true calls when a motor weakens (add it, or set actuator_known = false)"
            )
    return faults


def _loop_context(sc: Scenario, controller: Any, tl: _Timeline, pose0: np.ndarray, vel0: np.ndarray):
    """``(ctx, kernel)``: the arrays the loop shares with a compiled chunk (:class:`~bioform_mj.core.engine.Loop`)
    and the controller's compiled kernel (None: a user's controller, whose signals are copied into
    a shadow state each step)."""
    n = sc.n
    K = (tl.N - 1) // tl.stride + 1
    lg = new_log(K, n)
    kernel = getattr(controller, "kernel", None)
    if kernel is not None:
        gains, state = kernel
    else:  # a user's controller: its signals are copied into a shadow state each step
        gains, state = None, new_state(n)
    lim = sc.limits
    ctx = Loop(
        gains,
        state,
        getattr(controller, "_no_comm", None),
        tl.N,
        tl.dt,
        tl.L_pose,
        tl.L_vel,
        np.ascontiguousarray(pose0, dtype=float),
        np.ascontiguousarray(vel0, dtype=float),
        new_metrics(n),
        new_acc(n),
        lg,
        tl.stride,
        tl.form,
        Bounds(float(lim.position), float(lim.speed), float(lim.torque)),
        np.zeros(3),
    )
    return ctx, kernel


def _compiled_chunk(engine: str, plant: Plant, ctx: Loop, kernel: Any, faults: Any, record_inputs: Any) -> Any:
    """The plant's compiled chunk, where the engine, the controller's kernel and no per-step faults
    allow it (None: the Python chunk); ``engine = "compiled"`` without one is refused."""
    chunk = None
    if engine != "stepwise" and kernel is not None and faults is None and isinstance(plant, CompiledChunk):
        chunk = plant.compiled_chunk(ctx, record_inputs) if record_inputs is not None else plant.compiled_chunk(ctx)
    if engine == "compiled" and chunk is None:
        raise ValueError(
            "engine 'compiled' needs a plant and a controller with compiled kernels, and no "
            "per-step faults (use engine 'auto' or 'stepwise')"
        )
    return chunk


def _log_dict(plant: Plant, graph: Any, lg: LogArrays, j: int, missing: set[str], odometry: bool, offsets):
    """The run's log: the ``j`` rows written (a user's missing signals NaN), the odometry (the truth
    when the controllers used it), the offsets, obstacles and graph."""
    logd = {name: getattr(lg, name)[:j] for name in LogArrays._fields}
    for name in missing:
        logd[name] = np.full_like(logd[name], np.nan)
    if not odometry:  # the controllers used the truth
        logd["odom_pose"] = logd["pose"].copy()
        logd["odom_vel"] = logd["vel"].copy()
    logd["offsets"] = offsets
    if isinstance(plant, Obstacles) and plant.obstacles:  # design §19: drawn by the figures and rerun from the log
        from bioform_mj.formation.obstacles import to_rows

        logd["obstacles"] = to_rows(plant.obstacles)
    logd["edges"] = graph.edges + 1
    logd["leader_access"] = graph.leader_access
    return logd


def _summarise(sc, plant, controller, step: Stepper, end: LoopEnd, logd, setup_s: float, engine: str, warned):
    """summary.json's body (:func:`bioform_mj.run.summary._summary`) for the run that ended as ``end``,
    with the warnings said before the run (``warned``: ``(imported, feasibility, robot_check)``)."""
    ctx = step.ctx
    run = RunEnd(
        state=ctx.state,
        met=ctx.met,
        logd=logd,
        lp_end=ctx.L_pose[end.k_done],
        pose=end.pose,
        k_done=end.k_done,
        dt=ctx.dt,
        wall=end.wall,
        setup_s=setup_s,
        diverged=end.diverged,
        interrupted=end.interrupted,
        missing=step.missing,
        engine=engine,
    )
    summary = _summary(sc, plant, controller, run, warned[2])
    summary["feasibility_warnings"] = warned[1]
    summary["import_warnings"] = warned[0]
    if warned[2] is not None:  # design §14.2: what robot check fails the robots for
        from bioform_mj.assess.prerun import for_summary

        summary["robot_check"] = for_summary(warned[2])
    if warned[3] is not None:  # design §21: the scenario's demand against the robots' limits
        from bioform_mj.run.demand import for_summary as _demand_summary

        summary["demand"] = _demand_summary(warned[3])
        from bioform_mj.run.demand import twin_share

        twin_share(summary)  # a c_hat_off its ideal twin shares is the method's (design §21)
    return summary


def _add_run_notes(summary: dict[str, Any], sc, plant, step: Stepper, end: LoopEnd, logd, raised) -> None:
    """What summary.json says beyond :func:`_summary`: the sensing and the odometry drift (design
    §8.3), a user's non-finite torques and what raised (design §17), the unmodelled drags and the
    hardware verdict (design §19)."""
    dt, k_done, cname, nonfinite = step.ctx.dt, end.k_done, step.cname, step.nonfinite
    summary["sensing"] = "odometry" if step.odometry else "truth"
    drift = plant.odometry_drift() if step.odometry else None
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
    if isinstance(plant, Unmodelled) and len(logd["vel"]):  # damping and frictionloss at the run's speeds
        v = float(np.abs(logd["vel"][:, :, 0]).max())
        w = float(np.abs(logd["vel"][:, :, 1]).max())
        for f, u in zip(summary["followers"], plant.unmodelled(v, w)):
            f["unmodelled"] = u
    bad = getattr(getattr(step.controller, "gains", None), "cbf_bad", None)
    if bad is not None and sc.safety.filter == "cbf":  # design §19: the filter says when its QP had no solution
        for i, f in enumerate(summary["followers"]):
            f["cbf_infeasible_steps"] = int(bad[i])
            if bad[i]:
                warnings.warn(
                    f"follower {i + 1}: the safety filter's QP had no solution at {int(bad[i])} of {k_done} control "
                    "steps (robots or obstacles closer than it can keep apart; its command there is the solver's "
                    "last iterate, not a safe one)",
                    RobotWarning,
                    stacklevel=4,
                )
    from bioform_mj.assess.hardware import verdict  # design §19: would this run on the robots as specified?

    summary["hardware"] = verdict(sc, plant, summary, logd)


def _with_result(raised: Exception, result: RunResult) -> Exception:
    """``raised`` with the run so far attached as ``.result`` and a note saying where it stopped."""
    summary, logd = result.summary, result.log
    raised.result = result  # type: ignore[attr-defined]
    raised.add_note(
        f"bioform: raised by {summary['raised']['by']} at t = {summary['raised']['time_s']:.4f} s "
        f"(step {summary['raised']['step']}); the run stopped there, its log up to the last good step "
        f"({len(logd['t'])} rows) is in this exception's .result (a RunResult)"
    )
    return raised

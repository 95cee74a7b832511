"""``bioform robot fit``: a real robot's recording in, a calibrated robot out (issue 29; design §8, §13).

The model is the project's own robot (:mod:`bioform_mj.robots.realdata.simmodel`: the file and mapping
``robot check`` uses, on a floor). The recording is cut into chunks (2 s by default; shorter, down to 0.5 s, where a
short recording gives fewer than the parameters + 4 of them: :func:`~.status.choose_chunk`); each chunk is simulated
open loop from the state the recording gives at its start (wheel angles and speeds, the body rolling with
them) under the recorded wheel torques, and compared with what was measured: wheel speeds, and where the
recording has them the body's forward speed (``/odom`` twist) and yaw rate (``/imu``, else ``/odom``).
Each signal is weighted by one over its RMS, so wheels, speed and yaw rate count alike.

The parameters are found by ``mujoco.sysid`` (MuJoCo's system-identification toolbox: its
``ParameterDict``, residual pipeline, ``mujoco.rollout`` in parallel and least-squares optimiser) and their
95 % confidence intervals from the Jacobian at the optimum: the wider of ``mujoco.sysid.calculate_intervals``
(independent residuals, widened by their autocorrelation) and the leave-one-chunk-out jackknife with the chunks
as the independent units (:func:`~bioform_mj.robots.realdata.intervals.cluster_halfwidths`, design §8.4: the
residuals within a chunk are correlated, and with 12 chunks for 6 parameters the plain sandwich under-covers),
each widened by the Gauss–Newton step still to go where the optimiser stopped short (its time budget holds within
an iteration: a residual asked for after the deadline stops it). The parameters:

==================  ==================================================  =========
name                what (spec element)                                  unit
==================  ==================================================  =========
``mass``            the chassis body's mass (a payload at its CoM)       kg
``yaw_inertia``     the chassis body's inertia about its vertical axis   kg·m²
``damping_L/R``     each wheel joint's viscous damping                   N·m·s/rad
``frictionloss_L/R``each wheel joint's dry friction                       N·m
``armature_L/R``    each wheel joint's armature (rotor inertia · gear²)   kg·m²
``caster_friction`` sliding friction of the casters on the floor           —
==================  ==================================================  =========

Armature is not fitted unless asked (``--fit ...,armature``): a wheel's armature, the mass and the yaw
inertia act through the same two effective inertias (design §8: ``a_eff = 1/(m r + 2 I_w/r)``,
``b_eff = l/(I r + 2 I_w l²/r)``), so a recording of torques and speeds cannot separate the three; fitted
together, their intervals say so. A parameter is reported ``identified`` only when its interval is
narrower than 30 % of its value (so it does not include 0); one whose interval includes 0 (or is too wide) is
``negligible`` where its upper end's torque at the recording's own speeds is under 5 % of the wheel's RMS
effort, else ``not identified`` ("the recording says only that it is below X"); any other is ``not identified``
and its most correlated partners (``|ρ| > 0.9``) are named (:mod:`~bioform_mj.robots.realdata.status`). A
recording too short for ``p + 2`` chunks even at the 0.5 s floor identifies nothing, and says how long to record.
Caster friction is fitted only where the robot has casters: the mapping's (``--caster``), else those ``robot check``
finds (a non-wheel geom carrying a share of the weight at rest, design §0); where the recording cannot tell it from
the wheels' dry friction (both brake the robot alike when it drives straight; only turning sets them apart), the
report says so with their correlation. A caster the file makes frictionless (``condim 1``) is given ``condim 3``
so that its friction acts (a note says so), and the optimiser starts from the best, by simulation, of the linear
estimate and of a 1-D search over the caster's friction (:func:`~.casters.caster_start`: the rest regressed around each
value). A sliding caster chatters, so where its friction is fitted the signals are compared as means over
:data:`~.casters.CASTER_WINDOW_S` windows, the finite-difference step is :data:`~.casters.CASTER_FD_STEP` and
every interval and status comes from the cost's profile (:func:`~.casters.cost_profile`), not the Jacobian.

The intervals come from a Jacobian, which means something only where the residual is smooth: the Jacobian is
taken at two finite-difference steps (1× and 10×), and a parameter whose column differs by more than
:data:`ROUGH_JACOBIAN` is not identified, whatever its interval (a dragging caster's stick-slip makes the
open-loop rollouts chaotic: a change of 1e-4 in its friction moves the cost by 10 %).
"""

from __future__ import annotations

import io
import math
import sys
import time
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from bioform_mj.core.errors import InputError
from bioform_mj.robots.layout import CONTACT_PRIORITY
from bioform_mj.robots.realdata.casters import (
    CASTER_FD_STEP,
    CASTER_WINDOW_S,
    caster_notes,
    caster_regressor,
    caster_start,
    caster_start_notes,
    cost_profile,
    profile_row,
    robot_casters,
    window_means,
)
from bioform_mj.robots.realdata.chassis import chassis_body, explicit_base, set_yaw_inertia
from bioform_mj.robots.realdata.intervals import halfwidths, jacobian_at, remaining_step
from bioform_mj.robots.realdata.recording import Recording, chunk_starts, pauses, still_note
from bioform_mj.robots.realdata.simmodel import SimRobot, effort_to_ctrl, initial_state, sensor_times
from bioform_mj.robots.realdata.status import (
    choose_chunk,
    parameter_rows,
    settle_zero,
    suspension_rule,
    too_short_why,
    torque_effects,
)

__all__ = [
    "FIT_PARAMETERS",
    "DEFAULT_FIT",
    "Chunks",
    "make_chunks",
    "parameters",
    "fit",
    "FitResult",
    "simulate_chunks",
]

FIT_PARAMETERS = ("mass", "yaw_inertia", "damping", "frictionloss", "armature", "caster_friction")
DEFAULT_FIT = ("mass", "yaw_inertia", "damping", "frictionloss", "caster_friction")
#: a weighted residual sample (signal / its RMS) for a trial whose rollout diverged: far above any real one
DIVERGED = 1e6
#: measured samples per second of a chunk compared with the simulation (Hz)
GRID_HZ = 50.0
#: finite-difference step of the optimiser's scaled variables (a tenth of a search range is 1)
FD_STEP = 1e-3
#: the optimiser stops when a step changes the scaled variables by less than this
X_TOL = 1e-4
#: a calibrated model whose weighted residual RMS (1 = each signal's own RMS) exceeds this has no identified
#: parameters: measured 0.07-0.1 on the good tb3 fits (24 s, noise seeds 101-103), 1.4 on the tb3 recording
#: with a dragging caster the fit does not follow (mass 3.72 kg against 1.243 kg, intervals ±0.1 %)
MISFIT_RMS = 0.3
#: a parameter whose Jacobian column at a 10x finite-difference step differs from the 1x one by more than this
#: (relative norm) is not identified: the residual is not smooth in it. Measured: 0.006-0.008 on the tb3 test
#: recording (24 s); 0.33-0.72 on the paper robot's (30 s, dry friction 0.1 N·m, all within 2 % of the truth);
#: 0.94-0.97 on a tb3 with a dragging caster (friction 0.3), whose rollouts are chaotic; 0.93-1.0 on a 60 s tb3
#: recording at 0.06 N·m whose fit stopped at its time budget after 2 iterations (mass 17 % off)
ROUGH_JACOBIAN = 0.8
#: the note where the Gauss-Newton step still to go exceeds half an interval (design §8.4)
STOPPED_SHORT = "its remaining Gauss-Newton step exceeds half the interval; the intervals are widened by that step"


def _sysid():
    try:
        from mujoco import sysid
    except ImportError:  # pragma: no cover
        sysid = None
    if sysid is None or not hasattr(sysid, "optimize"):
        raise InputError(
            "bioform robot fit needs mujoco.sysid's dependencies (pip install 'mujoco[sysid]==4.0.0', or the "
            "project's 'ros' extra)"
        )
    return sysid


# ------------------------------------------------------------------ data
@dataclass
class Chunks:
    """The recording cut for simulation: per chunk its start (s), initial state, controls and the measured
    signals on a grid (chunk-local times from 0); ``weights``: per sensordata column (1/RMS, 0: not measured)."""

    starts: list[float]
    states: list[np.ndarray]
    controls: list[Any]  # sysid TimeSeries of the two motors' ctrl (N·m)
    measured: list[Any]  # sysid TimeSeries of the 8 sensordata columns
    weights: np.ndarray
    measured_cols: list[str]
    length: float
    window: float = 0.0  # > 0: ``measured`` holds means over windows of this length (s), at each window's end


def _at(t: float, tt: np.ndarray, y: np.ndarray) -> float:
    """``y`` at ``t`` from its finite samples (NaN where it has none)."""
    ok = np.isfinite(y)
    return float(np.interp(t, tt[ok], y[ok])) if ok.any() else math.nan


def _interp(t: np.ndarray, tt: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t, tt, y[:, k]) for k in range(y.shape[1])], axis=1)


def make_chunks(
    robot: SimRobot,
    model: mujoco.MjModel,
    rec: Recording,
    length: float = 2.0,
    max_chunks: int = 12,
    window: float = 0.0,
) -> Chunks:
    """Cut ``rec`` into chunks of ``length`` s, at most ``max_chunks`` of them spread evenly (each starts from
    the recorded state, so the open-loop drift of a long replay does not decide the fit). ``window`` > 0 (s):
    the measured signals are the means of the recorded samples over consecutive windows of that length
    (:func:`window_means`), not samples on the 50 Hz grid."""
    sysid = _sysid()
    TS = sysid.TimeSeries
    mapping = TS.compute_all_sensor_mapping(model)
    ctrl_map = TS.compute_all_control_mapping(model)
    cols = ["left_speed", "right_speed"]
    meas_full = np.zeros((len(rec.t), 8))
    meas_full[:, 0:2] = rec.velocity
    weights = np.zeros(8)
    wheel_rms = float(np.sqrt(np.mean(rec.velocity**2))) or 1.0
    weights[0:2] = 1.0 / wheel_rms
    if len(rec.odom_t):
        vx = np.interp(rec.t, rec.odom_t, rec.odom_twist[:, 0])
        meas_full[:, 2] = vx
        weights[2] = 1.0 / (float(np.sqrt(np.mean(vx**2))) or 1.0)
        cols.append("vx")
    yaw_src = (
        (rec.imu_t, rec.imu_gyro[:, 2])
        if len(rec.imu_t)
        else (rec.odom_t, rec.odom_twist[:, 5])
        if len(rec.odom_t)
        else None
    )
    if yaw_src is not None:
        wz = np.interp(rec.t, *yaw_src)
        meas_full[:, 7] = wz
        weights[7] = 1.0 / (float(np.sqrt(np.mean(wz**2))) or 1.0)
        cols.append("wz")
    yaw_pose = None
    if len(rec.odom_t):
        q = rec.odom_pose[:, 3:7]
        yaw_pose = np.unwrap(
            np.arctan2(2 * (q[:, 0] * q[:, 3] + q[:, 1] * q[:, 2]), 1 - 2 * (q[:, 2] ** 2 + q[:, 3] ** 2))
        )
    n_grid = int(round(length * GRID_HZ))
    if rec.duration < length + 1.0 / GRID_HZ:
        raise InputError(f"{rec.source}: {rec.duration:.3g} s of joint states, shorter than one {length:g} s chunk")
    grid = np.arange(1, n_grid + 1) / GRID_HZ  # chunk-local measured times, s
    dt = float(model.opt.timestep)
    starts, states, controls, measured = [], [], [], []
    # at most max_chunks, spread evenly over the recording (none across a pause): the cost stays bounded
    picks = chunk_starts(rec, length, max_chunks)
    if not picks.size:
        raise InputError(
            f"{rec.source}: no {length:g} s chunk of joint states without a pause ({pauses(rec.t).size} pauses of more "
            "than ten sample periods); give a shorter --chunk"
        )
    for c in picks:
        t0 = float(rec.t[0]) + c * length
        k = int(np.searchsorted(rec.t, t0))
        lo, hi = max(0, k - 2), min(len(rec.t), k + 3)
        speed = rec.velocity[lo:hi].mean(axis=0)  # a 5-sample mean: the noise of one sample would kick the start
        angle = np.array([np.interp(t0, rec.t, rec.position[:, i]) for i in range(2)])
        yaw = float(np.interp(t0, rec.odom_t, yaw_pose)) if yaw_pose is not None else 0.0
        others = {n: tuple(_at(t0, rec.t, v[:, i]) for i in range(2)) for n, v in rec.others.items()}
        states.append(initial_state(robot, model, angle, speed, yaw, others))
        ct = np.arange(0, int(round(length / dt)) + 2) * dt
        ctrl = effort_to_ctrl(robot, model, rec.effort_at(t0 + ct))
        controls.append(TS(ct, ctrl, ctrl_map))
        if window > 0:
            ends = np.arange(1, int(round(length / window)) + 1) * window
            measured.append(TS(ends, window_means(rec.t - t0, meas_full, ends, window), mapping))
        else:
            measured.append(TS(grid.copy(), _interp(t0 + grid, rec.t, meas_full), mapping))
        starts.append(t0)
    return Chunks(starts, states, controls, measured, weights, cols, length, window)


# ------------------------------------------------------------------ parameters
@dataclass
class ParamInfo:
    """One fitted quantity: its name, unit, what it is, its published value."""

    name: str
    unit: str
    what: str
    published: float
    scale: float = 1.0  # the optimiser's x is value / scale


@dataclass
class _Value:
    """What a modifier reads: ``value`` in the parameter's own unit."""

    value: np.ndarray


def parameters(
    robot: SimRobot, rec: Recording, which: tuple[str, ...], find_casters: bool = False
) -> tuple[Any, list[ParamInfo]]:
    """The ``mujoco.sysid.ParameterDict`` of the parameters in ``which`` (:data:`FIT_PARAMETERS`), their
    modifiers writing into ``robot.spec``; bounds from the robot and the recording (a physical range).
    ``caster_friction``: of the mapping's casters, or with ``find_casters`` of those found
    (:func:`robot_casters`)."""
    sysid = _sysid()
    spec, lay = robot.spec, robot.layout
    chassis = chassis_body(spec.compile(), lay.base)  # the base, or the heaviest body welded to it
    axis, izz = explicit_base(spec, chassis)
    model = spec.compile()
    m0 = float(spec.body(chassis).mass)
    of = f"the chassis body '{chassis}'"
    if chassis != lay.base:
        of += f" (the heaviest welded to the base '{lay.base}')"
    tau = float(np.abs(rec.effort).max()) or 1e-3
    wmax = float(np.abs(rec.velocity).max()) or 1.0
    pd = sysid.ParameterDict()
    info: list[ParamInfo] = []
    sides = ("L", "R")

    def add(name: str, nominal: float, lo: float, hi: float, modifier, unit: str, what: str) -> None:
        # the optimiser works on x = value / scale (scale: a tenth of the search range), so that every x is
        # O(1) and one finite-difference step (FD_STEP in x) is far above the solver's noise for all of them
        lo, hi = min(lo, nominal), max(hi, nominal)
        s = (hi - lo) / 10.0 or 1.0

        def scaled(spec, p, modifier=modifier, s=s):
            modifier(spec, _Value(p.value * s))

        pd.add(sysid.Parameter(name, nominal / s, lo / s, hi / s, modifier=scaled))
        info.append(ParamInfo(name, unit, what, float(nominal), s))

    if "mass" in which:

        def set_mass(s, p):
            s.body(chassis).mass = float(p.value[0])

        add("mass", m0, 0.25 * m0, 4.0 * m0, set_mass, "kg", f"mass of {of}")
    if "yaw_inertia" in which:

        def set_izz(s, p):
            set_yaw_inertia(s.body(chassis), axis, float(p.value[0]))

        add("yaw_inertia", izz, 0.25 * izz, 4.0 * izz, set_izz, "kg·m²", f"yaw inertia of {of}")
    for kind, unit, hi, what in (
        ("damping", "N·m·s/rad", 2.0 * tau / wmax, "viscous damping"),
        ("frictionloss", "N·m", tau, "dry friction"),
        ("armature", "kg·m²", None, "armature (rotor inertia × gear²)"),
    ):
        if kind not in which:
            continue
        for side, j in zip(sides, lay.wheel_joints):
            jid = model.joint(j).id
            if kind == "damping":
                pub = float(model.dof_damping[model.jnt_dofadr[jid]])
            elif kind == "frictionloss":
                pub = float(model.dof_frictionloss[model.jnt_dofadr[jid]])
            else:
                pub = float(model.dof_armature[model.jnt_dofadr[jid]])
                hi = pub + 2.0 * m0 * lay.wheel_radius**2

            def mod(s, p, j=j, kind=kind):
                el = s.joint(j)
                v = float(p.value[0])
                if kind == "damping":
                    d = np.array(el.damping, float)
                    d[0] = v
                    el.damping = d
                else:
                    setattr(el, kind, v)

            add(f"{kind}_{side}", pub, 0.0, hi, mod, unit, f"{what} of wheel joint '{j}'")
    geoms = (
        robot_casters(robot, spec, model) if "caster_friction" in which and (find_casters or robot.ref.casters) else []
    )
    if geoms:
        model = spec.compile()  # with the names robot_casters gave unnamed caster geoms
        pub = float(max(model.geom(g).friction[0] for g in geoms)) if geoms else 0.0
        pub = pub if all(model.geom(g).condim[0] > 1 for g in geoms) else 0.0

        def set_caster(s, p, geoms=tuple(geoms)):
            for g in geoms:
                el = s.geom(g)
                fr = np.array(el.friction, float)
                fr[0] = float(p.value[0])
                el.friction = fr
                el.condim = 3
                el.priority = CONTACT_PRIORITY

        add("caster_friction", pub, 0.0, 1.0, set_caster, "", f"sliding friction of the casters {', '.join(geoms)}")
    if not len(pd.keys()):
        raise InputError(f"--fit {','.join(which)}: nothing to fit on this robot")
    return pd, info


# ------------------------------------------------------------------ a starting point
def initial_guess(
    robot: SimRobot,
    rec: Recording,
    info: list[ParamInfo],
    pd,
    caster_mu: float | None = None,
    smooth_s: float = 0.1,
) -> np.ndarray:
    """A starting point for the optimiser, from a linear regression on the recording (design §8, rolling
    without slip): per wheel ``τ_i = A u̇_i + B u̇_j + d_i u_i + f_i sign(u_i)`` with ``u`` the forward wheel
    rates (rad/s) and ``A ± B = r² M_eff/2, r² I_eff/(2 l²)``; the changes of ``M_eff``, ``I_eff`` against
    the published robot go to the chassis mass and yaw inertia. Only where the fit starts: the open-loop
    rollouts far from the truth are chaotic (a robot without its friction runs away), near it smooth.
    With casters, their friction is a column too (:func:`~.casters.caster_regressor`); ``caster_mu`` holds
    it at that value instead (its torque moved to the left side), the rest regressed around it.
    Returns the scaled vector, clipped into the search ranges."""
    from scipy.signal import savgol_filter

    from bioform_mj.robots.params import robot_truth

    x = pd.as_vector().copy()
    lo, hi = pd.get_bounds()
    lay = robot.layout
    sign = np.asarray(lay.wheel_sign, float)
    dt = float(np.median(np.diff(rec.t)))
    win = max(5, int(round(smooth_s / dt)) | 1)  # Savitzky-Golay window: samples
    if len(rec.t) <= win + 2:
        return x
    u = savgol_filter(rec.velocity, win, 2, axis=0) * sign
    ud = savgol_filter(rec.velocity, win, 2, deriv=1, delta=dt, axis=0) * sign
    tau = rec.effort * sign
    moving = np.abs(u) > 0.05 * (np.abs(u).max() or 1.0)
    r, l = lay.wheel_radius, lay.half_track
    caster = caster_regressor(robot, u, r, l) if any(p.name == "caster_friction" for p in info) else None
    fixed = caster is not None and caster_mu is not None
    ncol = 6 + (caster is not None and not fixed)
    rows, rhs = [], []
    for i, j in ((0, 1), (1, 0)):
        for k in range(len(rec.t)):
            if not moving[k, i]:
                continue
            row = np.zeros(ncol)
            row[0], row[1] = ud[k, i], ud[k, j]
            row[2 + i] = u[k, i]
            row[4 + i] = np.sign(u[k, i])
            if caster is not None and not fixed:
                row[6] = caster[k, i]
            rows.append(row)
            rhs.append(tau[k, i] - (caster_mu * caster[k, i] if fixed else 0.0))
    if len(rows) < 20:
        return x
    sol, *_ = np.linalg.lstsq(np.asarray(rows), np.asarray(rhs), rcond=None)
    A, B, dL, dR, fL, fR = sol[:6]
    try:
        pub = robot_truth(robot.ref)
        dm = 2 * (A + B) / r**2 - pub.mass_eff
        dI = 2 * l**2 * (A - B) / r**2 - pub.inertia_eff
    except Exception:  # noqa: BLE001 - only a starting point: keep the published inertias
        dm = dI = 0.0
    guess = {
        "mass": dm,
        "yaw_inertia": dI,
        "damping_L": dL,
        "damping_R": dR,
        "frictionloss_L": fL,
        "frictionloss_R": fR,
    }
    if caster is not None:
        guess["caster_friction"] = caster_mu if fixed else sol[6]
    for i, p in enumerate(info):
        if p.name in ("mass", "yaw_inertia"):
            v = p.published + guess[p.name]
        elif p.name in guess:
            v = guess[p.name]
        else:  # no estimate (armature): the published value, moved off a search bound
            v = x[i] * p.scale
        if np.isfinite(v):
            x[i] = np.clip(v / p.scale, lo[i] + 1e-3 * (hi[i] - lo[i]), hi[i] - 1e-3 * (hi[i] - lo[i]))
    return x


# ------------------------------------------------------------------ the fit
class _OutOfTime(Exception):
    """Raised from the optimiser's iteration callback when the fit's time budget is spent."""


@dataclass
class FitResult:
    """What :func:`fit` found; ``parameters``: one dict per parameter (fit.json)."""

    parameters: list[dict[str, Any]]
    correlation: np.ndarray
    names: list[str]
    cost_published: float
    cost_calibrated: float
    seconds: float
    evaluations: int
    notes: list[str] = field(default_factory=list)
    #: s since the fit began: ``optimiser_start_s``, ``optimiser_end_s``; ``rollout_s``: one rollout of all chunks
    #: (the published robot's); ``time_budget_s``: the budget (the optimiser stops at the first rollout after it)
    timing: dict[str, float] = field(default_factory=dict)
    #: at the optimum: the weighted residual (chunk after chunk), its Jacobian in the optimiser's scaled variables
    #: (``value = x · scale``), the scales and the chunk count: what the intervals were computed from
    #: (``scripts/fit_coverage.py`` recomputes them)
    residual: np.ndarray | None = None
    jacobian: np.ndarray | None = None
    scales: np.ndarray | None = None
    n_chunks: int = 0
    #: the chunk length used (s): ``chunk_s`` as given, else :func:`~.status.choose_chunk`'s
    chunk_s: float = 2.0
    #: the signals compared per sample (wheel speeds, and vx, wz where recorded): the residual's row width
    n_signals: int = 2


def _residual_fn(robot: SimRobot, chunks: Chunks, n_threads: int, deadline: list[float] | None = None):
    """A residual ``fn(x, params) -> ([r], None, None)`` over all chunks: ``mujoco.sysid.model_residual``
    (one model compiled per parameter vector, the chunks rolled out in parallel by ``mujoco.rollout``) with a
    ``modify_residual`` comparing each chunk's grid samples, weighted by 1/RMS per signal. A 2-D ``x``
    (finite-difference columns) gives a 2-D residual, one column per ``x`` column.

    ``deadline``: a one-element list holding a ``time.perf_counter()`` value (s); a residual asked for after it
    raises :class:`_OutOfTime` before its rollouts, so that the fit's time budget holds inside an optimiser
    iteration (a finite-difference Jacobian is one rollout per parameter), not only between iterations."""
    sysid = _sysid()
    seqs = sysid.ModelSequences(
        "robot",
        robot.spec,
        [f"chunk{k}" for k in range(len(chunks.states))],
        chunks.states,
        chunks.controls,
        chunks.measured,
    )
    trajs = seqs.measured_rollout
    w = chunks.weights

    def modify_residual(params, pred, meas, model, return_pred_all, state=None, **_):
        times = sensor_times(pred.times, model)  # sysid stamps them one step late
        if chunks.window > 0:  # the simulated signals' means over the measured windows
            p = window_means(times, np.asarray(pred.data, float), meas.times, chunks.window)
        else:
            p = _interp(meas.times, times, np.asarray(pred.data, float))
        res = (meas.data - p) * w
        return res[:, w > 0], sysid.TimeSeries(meas.times, p, meas.signal_mapping), meas

    def build(p):
        return sysid.apply_param_modifiers(p, robot.spec)

    size: list[int] = []  # the residual's length, once a rollout gave one
    diverged = {"n": 0}  # trials whose rollouts diverged (fit.json's notes)

    def one(x: np.ndarray, params) -> np.ndarray:
        if deadline is not None and time.perf_counter() > deadline[0]:
            raise _OutOfTime
        try:
            res, _, _ = sysid.model_residual(
                x, params, build, trajs, modify_residual=modify_residual, n_threads=n_threads
            )
        except ValueError as exc:  # a rollout gone NaN under efforts far beyond the robot: an internal error before
            if size:  # the published robot rolled out: a trial parameter made it diverge, not the efforts. The
                # Freight's base mesh as a caster at friction 0.5-1 went NaN in the caster search, and the fit
                # stopped blaming the efforts; a residual of DIVERGED per sample keeps the optimiser away instead
                diverged["n"] += 1
                return np.full(size[0], DIVERGED)
            ctl = [np.asarray(getattr(c, "data", c), float) for c in chunks.controls]
            emax = max((float(np.max(np.abs(c))) for c in ctl if c.size), default=0.0)
            raise InputError(
                f"the robot simulated under the recording's efforts (up to {emax:.3g} in the motors' units) gives "
                f"no usable trajectory ({exc}): do the efforts fit this robot file (N·m at the wheel, its motors)?"
            ) from None
        out = np.asarray(res).ravel()
        size[:] = [out.size]
        return out

    def fn(x, params, **_):
        if np.ndim(x) == 1:
            return [one(x, params)], None, None
        return [np.stack([one(x[:, k], params) for k in range(x.shape[1])], axis=1)], None, None

    fn.diverged = diverged
    return fn


def _flat(fn, x: np.ndarray, pd) -> np.ndarray:
    return np.concatenate(fn(x, pd)[0])


def fit(
    robot: SimRobot,
    rec: Recording,
    which: tuple[str, ...] = DEFAULT_FIT,
    *,
    chunk_s: float | None = None,
    max_chunks: int = 12,
    max_iters: int = 30,
    time_budget_s: float = 60.0,
    progress: bool | None = None,
    find_casters: bool = False,
) -> tuple[FitResult, Any]:
    """Fit ``which`` to the recording; returns the result and the fitted ``ParameterDict``. ``chunk_s`` (s):
    the chunk length; None: 2 s, shorter where the recording is short (:func:`~.status.choose_chunk`)."""
    sysid = _sysid()
    t_start = time.perf_counter()
    progress = sys.stderr.isatty() if progress is None else progress
    pd, info = parameters(robot, rec, which, find_casters)
    model = robot.spec.compile()
    caster = "caster_friction" in pd.keys()  # its chatter: windowed means and a secant step (casters.py)
    chunk_s, chunk_notes = choose_chunk(rec, len(info), chunk_s, max_chunks)
    chunks = make_chunks(robot, model, rec, chunk_s, max_chunks, CASTER_WINDOW_S if caster else 0.0)
    eps = CASTER_FD_STEP if caster else FD_STEP
    n_threads = max(1, min(len(chunks.states), __import__("os").cpu_count() or 1))
    deadline = [math.inf]  # set to the time budget's end while the optimiser runs
    fn = _residual_fn(robot, chunks, n_threads, deadline)
    x0 = pd.as_vector()
    lo, hi = pd.get_bounds()
    t_roll = time.perf_counter()
    r_pub = _flat(fn, x0, pd)
    t_roll = time.perf_counter() - t_roll  # one rollout of all chunks, s
    cost_pub = float(r_pub @ r_pub)
    pd.update_from_vector(x0)
    start = pd.copy()
    notes = chunk_notes + still_note(rec, robot.layout.wheel_radius)
    guess = initial_guess(robot, rec, info, pd)
    r_guess = _flat(fn, guess, pd)
    cost_guess = float(r_guess @ r_guess)
    if caster:  # staged: a 1-D search over the caster's friction, the rest regressed around each value

        def reset() -> None:
            pd.update_from_vector(x0)
            sysid.apply_param_modifiers(pd, robot.spec)

        notes += caster_start_notes(robot, info, model)
        g, c, more = caster_start(
            robot,
            rec,
            info,
            x0,
            (lo, hi),
            lambda **kw: initial_guess(robot, rec, info, pd, **kw),
            lambda x: float(np.sum(_flat(fn, x, pd) ** 2)),
            reset,
        )
        notes += more
        if c < cost_guess:
            guess, cost_guess = g, c
    if cost_guess <= cost_pub:
        start.update_from_vector(guess)
    else:  # the regression's model (no casters, no slip) was further off than the maker's numbers
        span = hi - lo
        start.update_from_vector(np.clip(x0, lo + 1e-3 * span, hi - 1e-3 * span))
        notes.append("the fit started from the published values (the linear estimate fitted worse)")
    pd.update_from_vector(x0)
    evals = {"n": 0, "best": start.as_vector(), "best_cost": math.inf}
    stopped = ""

    def report(log) -> None:
        evals["n"] = len(log)
        e = log[-1]
        if float(e.objective) < evals["best_cost"]:
            evals["best"], evals["best_cost"] = np.asarray(e.candidate, float).ravel().copy(), float(e.objective)
        if progress:
            print(
                f"\rfit: iteration {len(log)}/{max_iters}, cost {float(e.objective):.4g} "
                f"(published {0.5 * cost_pub:.4g}), {time.perf_counter() - t_start:.0f} s",
                end="",
                file=sys.stderr,
                flush=True,
            )
        if time.perf_counter() > deadline[0]:
            raise _OutOfTime

    from absl import logging as absl_logging  # mujoco.sysid's logger: its start-at-bound notice is ours to say

    verbosity = absl_logging.get_verbosity()
    absl_logging.set_verbosity(absl_logging.ERROR)
    deadline[0] = t_start + time_budget_s
    t_opt = time.perf_counter()
    try:
        opt, _ = sysid.optimize(
            start,
            fn,
            optimizer="mujoco",
            verbose=False,
            max_iters=max_iters,
            iter_callback=report,
            eps=eps,
            xtol=X_TOL,
            output=io.StringIO(),  # the optimiser's own table: progress is report()'s one line on a terminal
        )
    except _OutOfTime:  # from report() between iterations or from a residual within one (one rollout late at most)
        opt = start.copy()
        opt.update_from_vector(evals["best"])
        stopped = (
            f"the optimiser stopped at the time budget ({time_budget_s:g} s) after {evals['n']} iterations: "
            "the best point so far is reported (a shorter --chunk or fewer --max-chunks is faster; a larger "
            "--time-budget lets it finish)"
        )
        notes.append(stopped)
    finally:
        deadline[0] = math.inf  # the Jacobian and the intervals below are not cut short
        absl_logging.set_verbosity(verbosity)
        timing = {
            "rollout_s": t_roll,
            "optimiser_start_s": t_opt - t_start,
            "optimiser_end_s": time.perf_counter() - t_start,
            "time_budget_s": float(time_budget_s),
        }
    if progress:
        print(file=sys.stderr)
    if stopped:
        print(f"warning: {stopped}", file=sys.stderr)
    x = opt.as_vector()
    r = _flat(fn, x, opt)
    if fn.diverged["n"]:
        notes.append(
            f"{fn.diverged['n']} trial parameter set(s) made the rollouts diverge (MuJoCo's 'Nan, Inf or huge value' "
            f"warnings): each was scored {DIVERGED:g} per sample, so the optimiser kept away from it"
        )
    if float(r @ r) > cost_pub:  # never report a robot that does worse than the published one
        x = x0.copy()
        opt.update_from_vector(x)
        r = _flat(fn, x, opt)
        notes.append(
            "the fit found nothing better than the published values (they are reported; the recording may not "
            "excite the robot, or the model lacks what the robot does: slip, backlash, a motor's dynamics)"
        )
    blew = np.zeros(len(x), bool)  # a column whose finite-difference trial diverged: scored DIVERGED, not a slope

    def jac_residual(X: np.ndarray) -> np.ndarray:
        RX = _flat(fn, X, opt)
        blew[:] |= np.all(RX == DIVERGED, axis=0)
        return RX

    J, rough = jacobian_at(jac_residual, x, r, eps, hi)
    opt.update_from_vector(x)
    # a diverged column is no slope: the intervals are those of the others with it held at its value (inf its own)
    ok = ~blew
    step, half, corr = np.zeros(len(x)), np.full(len(x), np.inf), np.zeros((len(x), len(x)))
    n_signals = int(np.count_nonzero(chunks.weights))
    if ok.any():  # every column diverged: no interval at all (the rows say why)
        step[ok] = remaining_step(r, J[:, ok], x[ok], lo[ok], hi[ok])  # ~0 where the optimiser converged
        half[ok], corr[np.ix_(ok, ok)] = halfwidths(r, J[:, ok], len(chunks.states), n_signals, step[ok])
    if short := [n for n, d, h in zip(pd.keys(), step, half) if abs(d) > 0.5 * h]:
        notes.append(f"the optimiser stopped short of the optimum in {', '.join(short)} ({STOPPED_SHORT})")
    names = list(opt.keys())
    if blew.any():
        notes.append(
            f"a finite-difference trial of {', '.join(n for n, b in zip(names, blew) if b)} at the optimum diverged: "
            "not identified, and the others' intervals hold it at its fitted value"
        )
    # a model that misses the recording by far is not a measurement of anything, however narrow its intervals
    miss = math.sqrt(float(r @ r) / max(1, r.size))  # weighted residual RMS, in units of each signal's RMS
    misfit = miss > MISFIT_RMS
    if misfit:
        notes.append(
            f"the calibrated model misses the recording: weighted residual RMS {miss:.2g} of the signals' own "
            f"(> {MISFIT_RMS:g}); no parameter is reported identified (the model lacks what the robot does, "
            "e.g. a dragging caster or slip, or the optimiser ended far off: see fit.png)"
        )
    too_short = too_short_why(len(chunks.states), len(names), chunk_s, max_chunks)
    if too_short:
        notes.append(f"no parameter is reported identified: {too_short}")
    rows = parameter_rows(
        info, x, half, (lo, hi), corr, rough, blew, miss if misfit else None, too_short, ROUGH_JACOBIAN
    )
    if caster:  # the chatter: intervals and statuses from the cost's profiles, not the Jacobian (casters.py)
        cost = lambda z: float(np.sum(_flat(fn, z, opt) ** 2))  # noqa: E731
        for k, p in enumerate(info):
            bounds = (float(lo[k]) * p.scale, float(hi[k]) * p.scale)
            prof = cost_profile(cost, x, k, p.scale, len(chunks.states), corr, bounds)
            profile_row(rows[k], prof, misfit or bool(too_short))
        rough[:] = 0.0
        opt.update_from_vector(x)
        notes.append(
            "every interval is from the profile of the cost of the 0.1 s means (ci95_method, profile), not the "
            "Jacobian: a sliding caster's chatter makes the residual rough at a finite-difference step"
        )
    if np.any(rough > ROUGH_JACOBIAN) and not misfit:
        notes.append(
            "the residual is not smooth in "
            + ", ".join(n for n, q in zip(names, rough) if q > ROUGH_JACOBIAN)
            + f" (Jacobian columns at finite-difference steps 1x and 10x differ by > {ROUGH_JACOBIAN:.0%}): the "
            "open-loop rollouts are chaotic there (a dragging caster's stick-slip, wheels that slip or lift, or a "
            "point far from the optimum), the optimiser cannot follow a gradient and the intervals do not hold; "
            "those parameters are not reported identified"
        )
    effects = torque_effects(rec)
    for row in rows:  # an interval that includes 0 is never "identified" (status.py)
        settle_zero(row, effects)
    notes += suspension_rule(rows, robot.layout)  # a wheel on a frozen suspension: its terms not identified
    notes += caster_notes(robot, which, names, corr, find_casters)
    result = FitResult(
        rows,
        corr,
        names,
        cost_pub,
        float(r @ r),
        time.perf_counter() - t_start,
        evals["n"],
        [
            f"{len(chunks.states)} chunks of {chunk_s:g} s (of {rec.duration:.3g} s recorded); compared: "
            f"{', '.join(chunks.measured_cols)}",
            *notes,
        ],
        timing,
        r,
        J,
        np.array([p.scale for p in info]),
        len(chunks.states),
        chunk_s,
        n_signals,
    )
    return result, opt


def simulate_chunks(robot: SimRobot, chunks: Chunks, model: mujoco.MjModel) -> list[np.ndarray]:
    """Each chunk simulated with ``model``; per chunk the sensordata at its grid times (n_grid, 8)."""
    from mujoco import rollout

    out = []
    data = mujoco.MjData(model)
    for st, ctrl, meas in zip(chunks.states, chunks.controls, chunks.measured):
        state, sens = rollout.rollout(model, data, st, ctrl.data[:-1])
        out.append(_interp(meas.times, sensor_times(state[0, :, 0], model), sens[0]))
    return out

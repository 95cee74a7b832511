"""Ground-truth dynamics parameters of a MuJoCo robot, and their check by identification.

(:class:`RobotParams` and :func:`robot_parameters` live in :mod:`bioform_mj.robot_params`, below the plant;
they are re-exported here.)

design §5/§8: ``υ̇ = a τ_a + d1``, ``ω̇ = b τ_b + d2`` with ``τ_a = τ_L + τ_R`` and
``τ_b = τ_R − τ_L`` (design §5 sign fix of the paper's eq. 34: CCW-positive ω). With rolling
without slip and the centre of mass on the axle midpoint, Lagrange's equations give

    a_eff = 1 / (m r + 2 I_w / r),      b_eff = l / (I r + 2 I_w l² / r)

(``m`` total mass, ``I`` total yaw inertia about the vertical through the axle midpoint,
``I_w`` one wheel's spin inertia including joint armature, ``r`` wheel radius, ``l`` half
track). :func:`ground_truth` reads these from a compiled model; :func:`identify` checks
them by applying constant torques from rest and fitting the accelerations.
"""

from __future__ import annotations

import logging
from dataclasses import asdict

import mujoco
import numpy as np

from bioform_mj.robot_params import COM_TOLERANCE_M, RobotParams, ground_truth, robot_parameters, robot_truth

log = logging.getLogger(__name__)

__all__ = [
    "COM_TOLERANCE_M",
    "RobotParams",
    "robot_parameters",
    "robot_truth",
    "ground_truth",
    "identify",
    "identify_main",
]

#: the turn test of :func:`identify` ends below this yaw rate, rad/s
OMEGA_ID = 2.0
#: :func:`identify` steps at most ``DRAG_STEP / k`` s for a wheel drag rate ``k`` (1/s), so that
#: MuJoCo integrates the damping finely; robot check warns when the model's own step is coarser
DRAG_STEP = 0.02


def _yaw_and_rates(qpos: np.ndarray, qvel: np.ndarray) -> tuple[float, float, float, float]:
    """Heading θ, forward speed υ, lateral speed, yaw rate ω from a free joint's qpos/qvel."""
    w, x, y, z = qpos[3:7]
    theta = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    c, s = np.cos(theta), np.sin(theta)
    v, v_lat = qvel[0] * c + qvel[1] * s, -qvel[0] * s + qvel[1] * c
    # world-z component of the body-frame angular velocity (third row of R)
    omega = (2 * (x * z - w * y)) * qvel[3] + (2 * (y * z + w * x)) * qvel[4] + (1 - 2 * (x * x + y * y)) * qvel[5]
    return float(theta), float(v), float(v_lat), float(omega)


def identify(
    model_file,
    *,
    torque: float | None = None,
    duration: float = 0.2,
    settle: float = 0.2,
    timestep: float | None = None,
    payload: tuple[float, float] | None = None,
) -> dict:
    """Identify ``(a, b)`` of one robot by constant wheel torques from rest.

    ``model_file``: a shipped name, an MJCF path or a :class:`~bioform_mj.robots.RobotRef` with a
    mapping. Drive tests ``τ_L = τ_R = T`` and ``T/2`` (``τ_a = 2T, T``), then turn tests
    ``τ_R = −τ_L = T`` and ``T/2``, each for ``duration`` s after ``settle`` s at rest on the floor,
    read through :class:`~bioform_mj.plants.mujoco_plant.MujocoPlant` (υ and ω of the axle
    midpoint). Per run a least-squares fit of ``υ̇ = α + β υ`` (likewise ω) separates the drive
    from a velocity-proportional drag (``β = −k``, joint damping); the two torque levels separate
    ``a`` from a dead band (frictionloss): ``a = (α₁ − α₂)/(τ_a1 − τ_a2)``. Without damping and
    frictionloss this is the slope of υ(t) over the torque. ``T`` defaults to half the motor limit or
    half the traction limit ``μ m g r / 2``, whichever is lower.
    ``payload`` = (mass kg, yaw inertia kg·m²) adds a payload at the axle midpoint first.

    Returns a dict with the formula values, the identified values, their relative differences,
    the identified drag and dead band beside their formulas, and the drive test's lateral drift
    and heading change.
    """
    from bioform_mj.plants.mujoco_plant import MujocoPlant  # the plant imports this module
    from bioform_mj.scene import prepare_robot

    auto_step = timestep is None
    if timestep is None:
        timestep = float(prepare_robot(model_file)[0].option.timestep)
    plant = MujocoPlant([model_file], np.zeros((1, 3)), timestep, timestep, None, slots=False)
    k_drag = max(plant.params[0].unmodelled(0.0, 0.0)["drag_rate_per_s"])
    if auto_step and k_drag * timestep > DRAG_STEP:
        # a wheel damping whose drag rate k is not small against 1/dt is integrated coarsely at the
        # model's own step (menagerie Stretch 3: k = 232 1/s, dt = 2 ms: a, b come out ~90 % high);
        # identify the continuous model at a step with k dt = DRAG_STEP (result "test.timestep_s")
        timestep = DRAG_STEP / k_drag
        plant = MujocoPlant([model_file], np.zeros((1, 3)), timestep, timestep, None, slots=False)
        duration = min(duration, max(20.0 / k_drag, 50 * timestep))
    if payload is not None:
        plant.add_payload(0, *payload)
    params = plant.params[0]
    if torque is None:  # half the motor limit, at most a quarter of the static traction limit μ N r
        for k in range(round(0.2 / timestep)):
            plant.step(np.zeros((1, 2)), k * timestep)
        traction = plant._wheel_friction(0) * float(plant.wheel_loads()[0].min()) * params.wheel_radius
        torque = min(0.5 * min(params.tau_max), 0.25 * traction)
        f = params.wheel_frictionloss
        if f > 0 and 0.5 * torque <= 1.2 * f:
            # both levels must clear the dead band (frictionloss f per wheel), else nothing moves and
            # ``a`` comes out ~0 (menagerie Stretch 3: f = 1 N·m, a quarter of traction 0.55 N·m)
            hi = min(min(params.tau_max), 0.5 * traction)
            if hi <= 1.3 * f:  # closer to the traction limit: the start risks a short skid
                hi = min(min(params.tau_max), 0.9 * traction)
            if hi <= 1.3 * f:
                raise ValueError(
                    f"cannot identify: the wheel frictionloss {f:g} N·m (dead band) leaves no torque below the "
                    f"traction limit {traction:.3g} N·m and the motor limit {min(params.tau_max):g} N·m "
                    "that turns the wheels without skidding"
                )
            torque = hi
    # the second torque level: half the first, or halfway between the dead band and the first
    f = params.wheel_frictionloss
    lo_frac = 0.5 if 0.5 * torque > 1.2 * f else (f + 0.5 * (torque - f)) / torque
    if not 0 < torque <= min(params.tau_max):
        raise ValueError(f"torque must be in (0, {min(params.tau_max)}] N·m, got {torque}")
    if not duration > 0 or settle < 0:
        raise ValueError("duration must be > 0 and settle >= 0")
    if params.motor == "dc":  # design §8.2: stay below the torque–speed line; see the drag's transient
        um = params.unmodelled(0.0, 0.0)
        w0 = 0.3 * params.motor_no_load_speed * params.wheel_radius  # 30 % of the no-load wheel speed, m/s
        duration = min(duration, w0 / (2 * params.a_eff * torque))
        k_v = um["drag_rate_per_s"][0]
        if k_v > 0:
            duration = min(duration, 3.0 / k_v)
    model, data = plant.model, plant.data
    dt = model.opt.timestep
    integ = int(model.opt.integrator)
    euler = integ == int(mujoco.mjtIntegrator.mjINT_EULER)
    eulerdamp = not (model.opt.disableflags & int(mujoco.mjtDisableBit.mjDSBL_EULERDAMP))
    implicit_damping = integ in (
        int(mujoco.mjtIntegrator.mjINT_IMPLICIT),
        int(mujoco.mjtIntegrator.mjINT_IMPLICITFAST),
    ) or (euler and eulerdamp)
    explicit = euler and not eulerdamp
    n_settle, n_run = round(settle / dt), max(round(duration / dt), 3)

    def run(tau_l: float, tau_r: float) -> dict:
        mujoco.mj_resetData(model, data)  # not plant.reset(): that would remove the payload
        mujoco.mj_forward(model, data)
        zero = np.zeros((1, 2))
        for k in range(n_settle):
            plant.step(zero, k * dt)
        pose0, _ = plant.observe()
        tau = np.array([[tau_l, tau_r]])
        z = np.empty((n_run + 1, 2))
        z[0] = plant.observe()[1][0]
        for k in range(n_run):
            plant.step(tau, k * dt)
            z[k + 1] = plant.observe()[1][0]
        pose, _ = plant.observe()
        d = pose[0, :2] - pose0[0, :2]
        th0 = pose0[0, 2]
        lateral = float(-np.sin(th0) * d[0] + np.cos(th0) * d[1])
        n_warn = sum(int(w.number) for w in data.warning)
        # υ̇ = α + β υ: forward differences against the velocity the integrator applies the drag at
        # (implicit damping: the new one, exact for v' = v + dt (α + β v'); explicit Euler: the old
        # one; RK4: the midpoint, exact for a line in t); matters once dt·k is not small (damping 30
        # on the menagerie Stretch 3: k dt ≈ 0.5)
        out = {}
        for k, name in ((0, "v"), (1, "omega")):
            rate = np.diff(z[:, k]) / dt
            if implicit_damping:
                mids = z[1:, k]
            elif explicit:
                mids = z[:-1, k]
            else:
                mids = 0.5 * (z[1:, k] + z[:-1, k])
            A = np.column_stack([np.ones_like(mids), mids])
            (alpha, beta), *_ = np.linalg.lstsq(A, rate, rcond=None)
            out[name] = (float(alpha), float(beta))
        return dict(
            fit=out,
            lateral_m=lateral,
            warnings=n_warn,
            heading_change_rad=float(np.angle(np.exp(1j * (pose[0, 2] - th0)))),
        )

    # turn torque: ω at the end at most OMEGA_ID rad/s, so the υ·ω coupling of a centre of mass
    # off the axle (∝ ω²) stays small
    t_turn = min(torque, OMEGA_ID / (2 * params.b_eff * duration))
    if params.motor == "dc":  # wheel rates l ω / r below 30 % of no-load in the turn tests too
        t_turn = min(
            t_turn,
            0.3 * params.motor_no_load_speed * params.wheel_radius / (params.half_track * 2 * params.b_eff * duration),
        )
    if f > 0 and lo_frac * t_turn < 1.1 * f:
        t_turn = torque  # the dead band needs the turn tests at the drive torque
    drive = [run(torque, torque), run(lo_frac * torque, lo_frac * torque)]
    turn = [run(-t_turn, t_turn), run(-lo_frac * t_turn, lo_frac * t_turn)]
    (al1, be1), (al2, be2) = drive[0]["fit"]["v"], drive[1]["fit"]["v"]
    (bl1, ge1), (bl2, ge2) = turn[0]["fit"]["omega"], turn[1]["fit"]["omega"]
    a_id = (al1 - al2) / (2 * torque * (1 - lo_frac))  # τ_a = τ_L + τ_R
    b_id = (bl1 - bl2) / (2 * t_turn * (1 - lo_frac))  # τ_b = τ_R − τ_L (design §5 sign fix)
    truth = params.unmodelled(0.0, 0.0)
    return {
        "model": str(plant.layouts[0].file),
        "formula": {"a": params.a_eff, "b": params.b_eff},
        "identified": {"a": a_id, "b": b_id},
        "relative_error": {"a": a_id / params.a_eff - 1, "b": b_id / params.b_eff - 1},
        "drag_rate_per_s": {"formula": truth["drag_rate_per_s"], "identified": [-(be1 + be2) / 2, -(ge1 + ge2) / 2]},
        "deadband_torque_Nm": {
            "formula": truth["deadband_torque_Nm"],
            "identified": [2 * torque - al1 / a_id, 2 * t_turn - bl1 / b_id],
        },
        "params": asdict(params),
        "layout": asdict(plant.layouts[0]),
        "test": {
            "torque_Nm": torque,
            "turn_torque_Nm": t_turn,
            "duration_s": duration,
            "settle_s": settle,
            "timestep_s": dt,
            "integrator": mujoco.mjtIntegrator(model.opt.integrator).name,
            "drive_lateral_drift_m": drive[0]["lateral_m"],
            "drive_heading_change_rad": drive[0]["heading_change_rad"],
            "mujoco_warnings": sum(r["warnings"] for r in drive + turn),
        },
    }


def identify_main(model) -> dict:
    """JSON-able identification report of one robot (name, path or RobotRef; for ``bioform identify``)."""
    return identify(model)

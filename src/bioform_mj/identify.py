"""Ground-truth dynamics parameters of a MuJoCo robot, and their check by identification.

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
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import mujoco
import numpy as np

from bioform_mj.scene import ROBOT, build_scene, compile_scene, model_path

log = logging.getLogger(__name__)

__all__ = ["RobotParams", "robot_parameters", "ground_truth", "identify", "identify_main"]

#: a centre of mass farther than this from the axle midpoint (m) makes the formula approximate
COM_TOLERANCE_M = 1e-3


@dataclass(frozen=True)
class RobotParams:
    """Physical parameters of one robot as compiled (SI units)."""

    mass: float  # m, kg: total mass of the robot subtree
    yaw_inertia: float  # I, kg·m²: about the vertical through the axle midpoint
    wheel_inertia: float  # I_w, kg·m²: one wheel's spin inertia (+ armature)
    wheel_radius: float  # r, m
    half_track: float  # l, m
    com_offset: float  # m: horizontal distance of the centre of mass from the axle midpoint
    tau_max: tuple[float, float]  # N·m: upper ctrl limit of left/right motor
    a_eff: float  # 1/(kg·m)
    b_eff: float  # 1/(kg·m²)

    @property
    def mass_eff(self) -> float:
        """``M_eff = 1/(a_eff r) = m + 2 I_w/r²``, kg (a force F gives υ̇ = F/M_eff)."""
        return 1.0 / (self.a_eff * self.wheel_radius)

    @property
    def inertia_eff(self) -> float:
        """``I_eff = l/(b_eff r) = I + 2 I_w l²/r²``, kg·m² (a yaw torque T gives ω̇ = T/I_eff)."""
        return self.half_track / (self.b_eff * self.wheel_radius)

    @property
    def traction_limit(self) -> float:
        """``μ m g r / 2`` per wheel for μ = 1, N·m (scale by the floor's μ)."""
        return self.mass * 9.81 * self.wheel_radius / 2


def _subtree(model: mujoco.MjModel, root: int) -> np.ndarray:
    """Ids of ``root`` and all its descendants."""
    ids = np.arange(model.nbody)
    inside = ids == root
    for b in ids[root + 1 :]:  # children always come after their parents
        inside[b] = inside[model.body_parentid[b]]
    return ids[inside]


def _support(model: mujoco.MjModel, data: mujoco.MjData, geom: int, direction: np.ndarray) -> float:
    """Extent of a sphere/ellipsoid geom from its centre along unit ``direction``, m."""
    size = model.geom_size[geom]
    if model.geom_type[geom] == int(mujoco.mjtGeom.mjGEOM_SPHERE):
        return float(size[0])
    local = data.geom_xmat[geom].reshape(3, 3).T @ direction
    return float(np.sqrt(np.sum((size * local) ** 2)))


def robot_parameters(
    model: mujoco.MjModel, prefix: str = "", data: mujoco.MjData | None = None
) -> RobotParams:
    """Read one robot's parameters from a compiled model (robot names start with ``prefix``).

    Evaluated at ``qpos0`` (robot level on the floor); yaw inertia uses every body's
    inertia rotated to the world frame plus the parallel-axis term about the vertical
    through the axle midpoint (midpoint of the two wheel joint anchors). ``data``: a
    scratch ``MjData`` on which ``mj_kinematics`` ran at ``qpos0`` (saves the work when
    reading many robots); by default one is made.
    """
    base = model.body(prefix + ROBOT.base).id
    jl, jr = (model.joint(prefix + n).id for n in ROBOT.wheel_joints)
    gl, gr = (model.geom(prefix + n).id for n in ROBOT.wheel_geoms)
    al, ar = (model.actuator(prefix + n).id for n in ROBOT.motors)

    if data is None:
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
    up = data.xmat[base].reshape(3, 3)[:, 2]  # robot's vertical axis
    mid = 0.5 * (data.xanchor[jl] + data.xanchor[jr])

    bodies = _subtree(model, base)
    masses = model.body_mass[bodies]
    mass = float(masses.sum())
    yaw = 0.0
    for b in bodies:
        rot = data.ximat[b].reshape(3, 3)
        n_local = rot.T @ up
        rel = data.xipos[b] - mid
        yaw += n_local @ (model.body_inertia[b] * n_local)
        yaw += model.body_mass[b] * (rel @ rel - (rel @ up) ** 2)
    com = (masses[:, None] * data.xipos[bodies]).sum(axis=0) / mass - mid
    com_offset = float(np.linalg.norm(com - (com @ up) * up))

    spins, radii = [], []
    for j, g in ((jl, gl), (jr, gr)):
        wb = model.jnt_bodyid[j]
        axis_local = data.ximat[wb].reshape(3, 3).T @ data.xaxis[j]
        spins.append(axis_local @ (model.body_inertia[wb] * axis_local) + model.dof_armature[model.jnt_dofadr[j]])
        radii.append(_support(model, data, g, up))
    i_w, r = float(np.mean(spins)), float(np.mean(radii))
    l = float(0.5 * np.linalg.norm(data.xanchor[jl] - data.xanchor[jr]))
    if abs(spins[0] - spins[1]) > 1e-9 * max(spins) or abs(radii[0] - radii[1]) > 1e-9:
        warnings.warn(f"{prefix or 'robot'}: left and right wheels differ; using their mean", stacklevel=2)
    if com_offset > COM_TOLERANCE_M:
        log.warning(
            "%s: centre of mass %.1f mm off the axle midpoint; a_eff, b_eff are approximate "
            "(unmodelled υ·ω coupling)", prefix or "robot", 1e3 * com_offset,
        )
    a_eff = 1.0 / (mass * r + 2.0 * i_w / r)  # design §8
    b_eff = l / (yaw * r + 2.0 * i_w * l**2 / r)  # design §8
    tau_max = (float(model.actuator_ctrlrange[al, 1]), float(model.actuator_ctrlrange[ar, 1]))
    return RobotParams(mass, float(yaw), i_w, r, l, com_offset, tau_max, float(a_eff), float(b_eff))


def ground_truth(model: mujoco.MjModel, prefix: str = "") -> tuple[float, float]:
    """``(a_eff, b_eff)`` of the robot named with ``prefix`` in a compiled model (design §8)."""
    p = robot_parameters(model, prefix)
    return p.a_eff, p.b_eff


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
    model_file: str | Path,
    *,
    torque: float | None = None,
    duration: float = 0.2,
    settle: float = 0.2,
    timestep: float | None = None,
    payload: tuple[float, float] | None = None,
) -> dict:
    """Identify ``(a, b)`` of one robot by constant wheel torques from rest.

    Drive test ``τ_L = τ_R = torque`` (so ``τ_a = 2 torque``), then turn test
    ``τ_R = −τ_L = torque`` (``τ_b = 2 torque``), each for ``duration`` s after ``settle``
    s at rest on the floor; a least-squares line through υ(t) resp. ω(t) gives the
    accelerations. ``torque`` defaults to half the motor limit. ``payload`` = (mass kg,
    yaw inertia kg·m²) adds a payload at the axle midpoint first.

    Returns a dict with the formula values, the identified values, their relative
    differences, and the drive test's lateral drift and heading change.
    """
    path = model_path(model_file)
    spec = build_scene(
        [path], np.zeros((1, 3)), slots=False, timestep=timestep,
        payloads=None if payload is None else [payload],
    )
    model, data = compile_scene(spec)
    prefix = "f1/"
    params = robot_parameters(model, prefix)
    if torque is None:
        torque = 0.5 * min(params.tau_max)
    if not 0 < torque <= min(params.tau_max):
        raise ValueError(f"torque must be in (0, {min(params.tau_max)}] N·m, got {torque}")
    if not duration > 0 or settle < 0:
        raise ValueError("duration must be > 0 and settle >= 0")

    root = model.joint(prefix + "root")
    qa, va = root.qposadr[0], root.dofadr[0]
    ctrl = [model.actuator(prefix + n).id for n in ROBOT.motors]
    dt = model.opt.timestep
    n_settle, n_run = round(settle / dt), max(round(duration / dt), 2)

    def run(tau_l: float, tau_r: float) -> dict:
        mujoco.mj_resetData(model, data)
        mujoco.mj_step(model, data, nstep=n_settle) if n_settle else None
        theta0, *_ = _yaw_and_rates(data.qpos[qa : qa + 7], data.qvel[va : va + 6])
        xy0 = data.qpos[qa : qa + 2].copy()
        data.ctrl[ctrl] = (tau_l, tau_r)
        t = np.empty(n_run)
        v = np.empty(n_run)
        om = np.empty(n_run)
        for k in range(n_run):
            mujoco.mj_step(model, data)
            t[k] = (k + 1) * dt
            _, v[k], _, om[k] = _yaw_and_rates(data.qpos[qa : qa + 7], data.qvel[va : va + 6])
        theta, *_ = _yaw_and_rates(data.qpos[qa : qa + 7], data.qvel[va : va + 6])
        d = data.qpos[qa : qa + 2] - xy0
        lateral = float(-np.sin(theta0) * d[0] + np.cos(theta0) * d[1])
        n_warn = sum(int(w.number) for w in data.warning)
        return dict(
            v_dot=float(np.polyfit(t, v, 1)[0]),
            omega_dot=float(np.polyfit(t, om, 1)[0]),
            lateral_m=lateral,
            heading_change_rad=float(np.angle(np.exp(1j * (theta - theta0)))),
            warnings=n_warn,
        )

    drive = run(torque, torque)
    turn = run(-torque, torque)
    a_id = drive["v_dot"] / (2 * torque)  # τ_a = τ_L + τ_R
    b_id = turn["omega_dot"] / (2 * torque)  # τ_b = τ_R − τ_L (design §5 sign fix)
    return {
        "model": str(path),
        "formula": {"a": params.a_eff, "b": params.b_eff},
        "identified": {"a": a_id, "b": b_id},
        "relative_error": {"a": a_id / params.a_eff - 1, "b": b_id / params.b_eff - 1},
        "params": asdict(params),
        "test": {
            "torque_Nm": torque,
            "duration_s": duration,
            "settle_s": settle,
            "timestep_s": dt,
            "integrator": mujoco.mjtIntegrator(model.opt.integrator).name,
            "drive_lateral_drift_m": drive["lateral_m"],
            "drive_heading_change_rad": drive["heading_change_rad"],
            "mujoco_warnings": drive["warnings"] + turn["warnings"],
        },
    }


def identify_main(model_path_: str | Path) -> dict:
    """JSON-able identification report of one model file (for ``bioform identify``)."""
    return identify(model_path_)

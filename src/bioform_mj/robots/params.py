"""The ground truth of one MuJoCo robot: its physical parameters and ``a_eff, b_eff`` (design §8, §13).

``υ̇ = a τ_a + d1``, ``ω̇ = b τ_b + d2`` (design §5) with, for rolling without slip and the centre
of mass on the axle midpoint (Lagrange's equations),

    a_eff = 1 / (m r + 2 I_w / r),      b_eff = l / (I r + 2 I_w l² / r)

(``m`` total mass, ``I`` total yaw inertia about the vertical through the axle midpoint, ``I_w``
one wheel's spin inertia about its joint axis: the wheel body, every body welded below it, and the
joint's armature; ``r`` wheel radius, ``l`` half track). This module sits on the ground floor beside
:mod:`bioform_mj.robots.scene` (STYLE item 8): :mod:`bioform_mj.plants.mujoco.plant` and
:mod:`bioform_mj.assess.identify` both import it, neither imports the other at module level.
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass

import mujoco
import numpy as np

from bioform_mj.robots.analysis import layout_of
from bioform_mj.robots.layout import DC_INPUT_VOLTAGE, dc_constants, dc_ctrl_scale, subtree, welded_to
from bioform_mj.robots.scene import build_scene, compile_scene

log = logging.getLogger(__name__)

__all__ = [
    "COM_TOLERANCE_M",
    "RobotParams",
    "robot_parameters",
    "robot_truth",
    "running_data",
    "SETTLE_S",
    "ground_truth",
    "subtree",
    "welded_to",
]

#: a centre of mass farther than this from the axle midpoint (m) makes the formula approximate
COM_TOLERANCE_M = 1e-3


@dataclass(frozen=True)
class RobotParams:
    """Physical parameters of one robot as compiled (SI units)."""

    mass: float  # m, kg: total mass of the robot subtree
    yaw_inertia: float  # I, kg·m²: about the vertical through the axle midpoint
    wheel_inertia: float  # I_w, kg·m²: one wheel's spin inertia (+ welded bodies + armature)
    wheel_radius: float  # r, m
    half_track: float  # l, m
    com_offset: float  # m: horizontal distance of the centre of mass from the axle midpoint
    tau_max: tuple[float, float]  # N·m: torque limit of left/right motor
    a_eff: float  # 1/(kg·m)
    b_eff: float  # 1/(kg·m²)
    com_xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m: CoM from the axle midpoint, base frame
    wheel_damping: float = 0.0  # N·m·s/rad per wheel joint (mean of the two)
    wheel_armature: float = 0.0  # kg·m² per wheel joint (included in wheel_inertia)
    wheel_frictionloss: float = 0.0  # N·m per wheel joint
    motor: str = "ideal"  # "ideal" (torque source) or "dc" (MuJoCo <dcmotor>, design §8.2)
    driver: str = ""  # DC motor driver: "current" or "voltage"
    motor_stall_torque: float = 0.0  # N·m at the wheel: g K V_max / R (DC motor)
    motor_no_load_speed: float = 0.0  # rad/s at the wheel: V_max / (g K) (DC motor)
    motor_damping: float = 0.0  # N·m·s/rad per wheel: back-EMF drag (g K)²/R (voltage driver; 0 otherwise)

    @property
    def c(self) -> tuple[float, float]:
        """``(a_eff, b_eff)``."""
        return (self.a_eff, self.b_eff)

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
        """``μ m g r / 2`` per wheel for μ = 1, N·m (scale by the floor's μ): an even split of the weight
        and a light rotor; :meth:`traction_torque` takes the real load and the rotor (design §13)."""
        return self.mass * 9.81 * self.wheel_radius / 2

    @property
    def floor_fraction(self) -> tuple[float, float]:
        """Fraction of a wheel's torque that reaches the floor as a force, ``(drive, turn)`` (design §13).

        Driving (``τ_L = τ_R = τ``): the wheel's own rotor takes ``I_w φ̈ = I_w υ̇ / r`` with
        ``υ̇ = 2 a τ``, so the floor force is ``F = (τ − 2 a I_w τ / r) / r`` and the fraction
        ``f_υ = 1 − 2 a I_w / r = m r² / (m r² + 2 I_w) = m r a_eff``. Turning (``τ_R = −τ_L = τ``):
        ``f_ω = I r² / (I r² + 2 I_w l²) = I r b_eff / l``. A rotor of ``I_w = 10 m r²`` passes
        ``f_υ = 1/21 ≈ 5 %``.
        """
        r, l = self.wheel_radius, self.half_track
        return (self.mass * r * self.a_eff, self.yaw_inertia * r * self.b_eff / l)

    def traction_torque(self, mu: float, load_n: float) -> float:
        """Wheel torque, N·m, at which a wheel with normal load ``load_n`` N on a floor of friction
        ``mu`` starts to skid: ``μ N r / f`` with ``f`` the larger of :attr:`floor_fraction` (the
        torque that does not reach the floor cannot skid the wheel)."""
        return mu * load_n * self.wheel_radius / max(self.floor_fraction)

    def unmodelled(self, v: float, w: float) -> dict:
        """Wheel damping and frictionloss as the paper's model sees them (design §8, issue 10).

        A joint damping ``c`` (N·m·s/rad) on each wheel is a torque ``−c φ̇`` with wheel rates
        ``φ̇_{R,L} = (υ ± l ω)/r``, so ``υ̇ = a τ_a − k_υ υ`` and ``ω̇ = b τ_b − k_ω ω`` with
        ``k_υ = 2 a c / r`` and ``k_ω = 2 b c l / r`` (1/s); at speeds ``v`` m/s, ``w`` rad/s that
        is a drag of ``k_υ v`` m/s² and ``k_ω w`` rad/s². A frictionloss ``f`` (N·m) per wheel is
        a dead band: up to ``2 f`` of ``τ_a`` resp. ``τ_b`` moves nothing, ``2 a f`` m/s² resp.
        ``2 b f`` rad/s². Neither is in ``υ̇ = a τ_a + d``: the learner meets them as a
        disturbance, and where the torque is nearly constant (cruising at ``v``, torque
        ``τ_a ≈ k_υ v / a``) it cannot tell them from ``a τ_a`` (the constant-disturbance bias of
        design §8): ``â`` then tends to ``a − k_υ v/τ_a``, which is ``0`` for pure cruising, i.e.
        it stays where the projection and the excitation put it. Armature is in ``a_eff, b_eff``.
        """
        a, b, r, l = self.a_eff, self.b_eff, self.wheel_radius, self.half_track
        c, f = self.wheel_damping + self.motor_damping, self.wheel_frictionloss
        k_v, k_w = 2 * a * c / r, 2 * b * c * l / r
        motor = {"motor": self.motor}
        if self.motor == "dc":
            ce = self.motor_damping
            motor.update(
                {
                    "driver": self.driver,
                    "stall_torque_Nm": self.motor_stall_torque,
                    "no_load_speed_rad_s": self.motor_no_load_speed,
                    "back_emf_damping_Nms_per_rad": ce,
                    "back_emf_drag_rate_per_s": [2 * a * ce / r, 2 * b * ce * l / r],
                    "ground_truth": (
                        "voltage driver: a_eff, b_eff from rest (the stall torque line); moving, back-EMF is a "
                        "viscous drag (gK)^2/R per wheel: v' = a tau_a - k_v v, w' = b tau_b - k_w w, "
                        "k_v = 2 a c/r, k_w = 2 b c l/r (c = damping + back-EMF)"
                        if self.driver == "voltage"
                        else "current driver: the commanded torque is delivered below the torque-speed line "
                        "|tau| <= stall (1 - |wheel rate|/no-load speed): a_eff, b_eff and no drag; "
                        "beyond it the torque is clipped (a saturation, not a drag)"
                    ),
                }
            )
        return {
            **motor,
            "damping_Nms_per_rad": c,
            "armature_kgm2": self.wheel_armature,
            "frictionloss_Nm": f,
            "armature_in_c_true": "I_w includes armature: a = 1/(m r + 2 I_w/r), b = l/(I r + 2 I_w l²/r)",
            "drag_rate_per_s": [k_v, k_w],
            "drag_time_constant_s": [1 / k_v if k_v else None, 1 / k_w if k_w else None],
            "at_speed": [v, w],
            "drag_accel_at_speed": [k_v * v, k_w * w],
            "deadband_torque_Nm": [2 * f, 2 * f],
            "deadband_accel": [2 * a * f, 2 * b * f],
            "c_hat_converges_to": (
                "c_true = (a_eff, b_eff) under exciting motion, the drag and dead band acting as a "
                "disturbance d; with a nearly constant torque they bias c_hat like a constant d: "
                "a_hat ~ a - (k_v v + 2 a f)/tau_a, b_hat ~ b - (k_w w + 2 b f)/tau_b"
                if (c or f)
                else "c_true = (a_eff, b_eff): no wheel damping or frictionloss"
            ),
        }


_subtree = subtree


def robot_parameters(model: mujoco.MjModel, prefix: str = "", data: mujoco.MjData | None = None) -> RobotParams:
    """Read one robot's parameters from a compiled model (robot names start with ``prefix``).

    The parts come from the robot's layout (:func:`bioform_mj.robots.analysis.layout_of`: mapping, wheel
    radius, half track, axle midpoint). Evaluated at ``qpos0``; yaw inertia uses every body's
    inertia rotated to the world frame plus the parallel-axis term about the vertical through
    the axle midpoint (midpoint of the two wheel joint anchors). ``I_w`` is a wheel's spin
    inertia about its joint axis through the joint anchor, summed over the wheel body and every
    body welded to it (:func:`welded_to`; parallel-axis term for a centre off the axis), plus the
    joint's armature (design §13). ``data``: a scratch ``MjData`` on which ``mj_kinematics`` ran
    (at ``qpos0``, or at a settled configuration: the parameters of the robot as it stands there).
    """
    lay = layout_of(model, prefix)
    base = model.body(lay.base).id
    jl, jr = (model.joint(n).id for n in lay.wheel_joints)
    al, ar = (model.actuator(n).id for n in lay.motors)

    if data is None:
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
    rot_b = data.xmat[base].reshape(3, 3)
    up = rot_b[:, 2]  # robot's vertical axis
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

    spins, damp, arm, fl = [], [], [], []
    for j in (jl, jr):
        dof = model.jnt_dofadr[j]
        ax = data.xaxis[j]
        spin = 0.0
        for wb in welded_to(model, int(model.jnt_bodyid[j])):
            axis_local = data.ximat[wb].reshape(3, 3).T @ ax
            rel = data.xipos[wb] - data.xanchor[j]
            spin += axis_local @ (model.body_inertia[wb] * axis_local) + model.body_mass[wb] * (
                rel @ rel - (rel @ ax) ** 2
            )
        spins.append(spin + model.dof_armature[dof])
        damp.append(float(model.dof_damping[dof]))
        arm.append(float(model.dof_armature[dof]))
        fl.append(float(model.dof_frictionloss[dof]))
    i_w, r, l = float(np.mean(spins)), lay.wheel_radius, lay.half_track
    if abs(spins[0] - spins[1]) > 1e-9 * max(spins):
        warnings.warn(f"{prefix or 'robot'}: left and right wheels differ; using their mean", stacklevel=2)
    if com_offset > COM_TOLERANCE_M:
        log.info(
            "%s: centre of mass %.1f mm off the axle midpoint; a_eff, b_eff hold from rest "
            "(an unmodelled υ·ω coupling acts while moving)",
            prefix or "robot",
            1e3 * com_offset,
        )
    a_eff = 1.0 / (mass * r + 2.0 * i_w / r)  # design §8
    b_eff = l / (yaw * r + 2.0 * i_w * l**2 / r)  # design §8

    dc = int(model.actuator_dyntype[al]) == int(mujoco.mjtDyn.mjDYN_DCMOTOR)

    def limit(a: int) -> float:
        if dc:  # ctrl is the driver's input: the wheel torque is ctrl / scale (design §8.2)
            lim = float(model.actuator_ctrlrange[a, 1] / dc_ctrl_scale(model, a))
            if model.actuator_forcelimited[a]:
                lim = min(lim, float(model.actuator_forcerange[a, 1] * abs(model.actuator_gear[a, 0])))
            R, K, g, vmax = dc_constants(model, a)
            return min(lim, g * K * vmax / R)
        lim = float(model.actuator_ctrlrange[a, 1] * abs(model.actuator_gear[a, 0]))
        if model.actuator_forcelimited[a]:
            lim = min(lim, float(model.actuator_forcerange[a, 1]))
        return lim

    motor: dict = {}
    if dc:
        R, K, g, vmax = dc_constants(model, al)
        voltage = int(model.actuator_ctrlspec[al]) == DC_INPUT_VOLTAGE
        motor = dict(
            motor="dc",
            driver="voltage" if voltage else "current",
            motor_stall_torque=g * K * vmax / R,
            motor_no_load_speed=vmax / (g * K),
            motor_damping=(g * K) ** 2 / R if voltage else 0.0,
        )
    return RobotParams(
        mass,
        float(yaw),
        i_w,
        r,
        l,
        com_offset,
        (limit(al), limit(ar)),
        float(a_eff),
        float(b_eff),
        tuple(float(x) for x in rot_b.T @ com),
        float(np.mean(damp)),
        float(np.mean(arm)),
        float(np.mean(fl)),
        **motor,
    )


#: seconds of zero torque after which a robot with joints beyond its wheels stands as it runs (design §13)
SETTLE_S = 0.3


def running_data(model: mujoco.MjModel, n_robots: int, seconds: float = SETTLE_S) -> mujoco.MjData:
    """A scratch ``MjData`` with ``mj_kinematics`` done for the configuration the robots run in
    (design §13: the ground truth is the robot that runs).

    Robots with no joint but their root and wheels (``model.njnt == 3 n``, every shipped robot)
    run as the file puts them: ``qpos0``. Otherwise (joints held by servos or an equality, left
    free, caster swivels) the scene settles for ``seconds`` of zero torque from ``qpos0`` and the
    kinematics are those of the settled state (an arm on weak servos has sagged, a free one dropped).
    """
    data = mujoco.MjData(model)
    if model.njnt > 3 * n_robots:
        mujoco.mj_forward(model, data)
        for _ in range(max(1, round(seconds / model.opt.timestep))):
            mujoco.mj_step(model, data)
    mujoco.mj_kinematics(model, data)
    return data


def robot_truth(entry) -> RobotParams:
    """:class:`RobotParams` of one robot entry (name, path, table or RobotRef), as the plant builds it
    (in the configuration it runs in, :func:`running_data`)."""
    model = compile_scene(build_scene([entry], np.zeros((1, 3)), slots=False))[0]
    return robot_parameters(model, "f1/", running_data(model, 1))


def ground_truth(model: mujoco.MjModel, prefix: str = "") -> tuple[float, float]:
    """``(a_eff, b_eff)`` of the robot named with ``prefix`` in a compiled model (design §8)."""
    p = robot_parameters(model, prefix)
    return p.a_eff, p.b_eff


def implausible_inertias(model: mujoco.MjModel, prefix: str, data: mujoco.MjData) -> str:
    """'' unless bodies of robot ``prefix`` have an inertia no body of their mass could have inside the
    robot: a radius of gyration ``sqrt(I_max / m)`` beyond the robot's own size (the farthest point of its
    collision geoms from its centre of mass, at ``data``'s configuration). Such an inertia is a placeholder
    (``ixx = iyy = izz = 1`` on a 10 g plate, as a published Pioneer 3-DX URDF has) that ``a_eff, b_eff``
    take as it is; the line names them with their share of the yaw inertia and of the wheels' ``I_w``."""
    lay = layout_of(model, prefix)
    bodies = subtree(model, model.body(lay.base).id)
    mass = model.body_mass[bodies]
    com = (mass[:, None] * data.xipos[bodies]).sum(axis=0) / max(float(mass.sum()), 1e-12)
    mine = set(bodies.tolist())
    size = max(
        (
            float(np.linalg.norm(data.geom_xpos[g] - com)) + float(model.geom_rbound[g])
            for g in range(model.ngeom)
            if model.geom_bodyid[g] in mine
        ),
        default=0.0,
    )
    spin = {}  # body -> wheel joint it spins with
    for jn in lay.wheel_joints:
        j = model.joint(jn).id
        spin.update({int(b): j for b in welded_to(model, int(model.jnt_bodyid[j]))})

    def about(b: int, axis: np.ndarray) -> float:
        n = data.ximat[b].reshape(3, 3).T @ axis
        return float(n @ (model.body_inertia[b] * n))

    yaw = sum(
        about(b, np.array([0.0, 0, 1])) + model.body_mass[b] * np.sum((data.xipos[b] - com)[:2] ** 2) for b in bodies
    )
    i_w = sum(about(b, data.xaxis[j]) for b, j in spin.items())
    bad = [
        b for b in bodies if model.body_mass[b] > 0 and np.sqrt(model.body_inertia[b].max() / model.body_mass[b]) > size
    ]
    if not bad or size <= 0:
        return ""
    names = [
        f"'{(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or f'#{b}').removeprefix(prefix)}' "
        f"{model.body_mass[b]:.3g} kg, {model.body_inertia[b].max():.3g} kg·m² "
        f"({np.sqrt(model.body_inertia[b].max() / model.body_mass[b]):.3g} m)"
        for b in bad
    ]
    share_yaw = sum(about(b, np.array([0.0, 0, 1])) for b in bad if b not in spin) / max(yaw, 1e-12)
    share_w = sum(about(b, data.xaxis[spin[b]]) for b in bad if b in spin) / max(i_w, 1e-12)
    return (
        f"implausible inertias (placeholders?): {', '.join(names)}: radii of gyration beyond the robot's "
        f"{size:.3g} m from its centre of mass; a_eff, b_eff take them as published ({100 * share_yaw:.0f} % of the "
        f"yaw inertia, {100 * share_w:.0f} % of the wheels' spin inertia I_w); give those links their real inertia"
    )

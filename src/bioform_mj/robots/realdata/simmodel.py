"""The robot as the fit and the replay simulate it: the project's prepared robot on a floor, with sensors.

:func:`sim_spec` loads the robot exactly as ``bioform robot check`` and ``bioform run`` do
(:func:`bioform_mj.robots.prepare.prepare_robot`, the same :class:`~bioform_mj.robots.RobotRef` mapping), puts
it on a plane and replaces its sensors by the ones a recording measures: the two wheel joints' speeds
(``jointvel``, rad/s), and at the base body's origin (ROS ``base_link``) its body-frame linear velocity
(``velocimeter``, m/s) and angular velocity (``gyro``, rad/s). The two motors take the recorded effort
about each joint's own axis, ``ctrl = s · wheel_sign · effort`` (:func:`effort_to_ctrl`): with torque motors
(the mapping's ``motor = "ideal"``, a recording of applied torques) ``s = 1`` and ``ctrl`` is N·m; with the
robot file's ``<dcmotor>`` drives (``motor = "dc"``, a recording of the torques *commanded* to them) ``s`` is
the driver's scale (design §8.2: ``R/(g K)`` V per N·m with the voltage driver, ``1/g`` with the current
driver), so the motor's back-EMF and torque–speed line are simulated as in a run.

:func:`initial_state` builds the full MuJoCo state a recording implies at one instant: the robot standing
as it settles on the floor at its recorded heading, its wheels at the recorded angles and speeds and the
body moving as the wheels roll it (design §8: no slip at the start).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from bioform_mj.robots.layout import FRICTIONLESS, RobotLayout, frictionless
from bioform_mj.robots.prepare import prepare_robot
from bioform_mj.robots.refs import RobotRef

__all__ = [
    "SimRobot",
    "sim_spec",
    "initial_state",
    "effort_to_ctrl",
    "frictionless_note",
    "sensor_times",
    "other_joints",
    "SENSOR_COLUMNS",
]

#: the sensordata columns: left, right wheel speed (rad/s), velocimeter x y z (m/s), gyro x y z (rad/s)
SENSOR_COLUMNS = ("left_speed", "right_speed", "vx", "vy", "vz", "wx", "wy", "wz")


@dataclass
class SimRobot:
    """A fit/replay model: its spec (edited by the fit's parameters), the layout, the settled rest pose."""

    spec: mujoco.MjSpec
    layout: RobotLayout
    ref: RobotRef
    rest_qpos: np.ndarray  # settled on the floor at heading 0, wheels at 0
    free_qpos: int  # qpos address of the base's free joint
    free_dof: int
    wheel_qpos: tuple[int, int]
    wheel_dof: tuple[int, int]
    axle_base: np.ndarray  # axle midpoint in the base frame, m
    notes: list[str] = field(default_factory=list)  # what sim_spec changed (fit.json's and the replay's notes)


def sim_spec(ref: RobotRef) -> SimRobot:
    """The prepared robot on a floor with the recording's sensors (module docstring); raises
    :class:`~bioform_mj.robots.layout.ModelError` (exit 2) as ``robot check`` would."""
    spec, layout, _, _ = prepare_robot(ref)
    for s in list(spec.sensors):
        spec.delete(s)
    # the floor as the scene's (robots/scene.py): MuJoCo's own contact defaults, whatever the robot file's default
    # class says. It inherited the file's: the menagerie TIAGo's (contype 0, conaffinity 1) left its four casters
    # (contype 0) without a floor, and the robot fell over backwards at rest in every chunk (residual RMS 7.2)
    spec.worldbody.add_geom(
        name="bioform_floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[0, 0, 1],
        contype=1,
        conaffinity=1,
        condim=3,
        priority=0,
        friction=[1.0, 0.005, 0.0001],
        solref=[0.02, 1.0],
        solimp=[0.9, 0.95, 0.001, 0.5, 2.0],
        margin=0.0,
        gap=0.0,
    )
    base = spec.body(layout.base)
    base.add_site(name="bioform_base_link", pos=[0, 0, 0], size=[0.005, 0, 0], group=5)
    for side, j in zip(("left", "right"), layout.wheel_joints):
        spec.add_sensor(
            name=f"bioform_{side}_speed",
            type=mujoco.mjtSensor.mjSENS_JOINTVEL,
            objtype=mujoco.mjtObj.mjOBJ_JOINT,
            objname=j,
        )
    spec.add_sensor(
        name="bioform_velocimeter",
        type=mujoco.mjtSensor.mjSENS_VELOCIMETER,
        objtype=mujoco.mjtObj.mjOBJ_SITE,
        objname="bioform_base_link",
    )
    spec.add_sensor(
        name="bioform_gyro",
        type=mujoco.mjtSensor.mjSENS_GYRO,
        objtype=mujoco.mjtObj.mjOBJ_SITE,
        objname="bioform_base_link",
    )
    model = spec.compile()
    free = [
        j
        for j in range(model.njnt)
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE and model.jnt_bodyid[j] == model.body(layout.base).id
    ]
    fj = free[0]
    wj = [model.joint(j).id for j in layout.wheel_joints]
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    for _ in range(int(0.5 / model.opt.timestep)):  # settle on the floor
        mujoco.mj_step(model, data)
    rest = data.qpos.copy()
    rest[[int(model.jnt_qposadr[j]) for j in wj]] = 0.0
    return SimRobot(
        spec,
        layout,
        ref,
        rest,
        int(model.jnt_qposadr[fj]),
        int(model.jnt_dofadr[fj]),
        tuple(int(model.jnt_qposadr[j]) for j in wj),
        tuple(int(model.jnt_dofadr[j]) for j in wj),
        np.asarray(layout.axle, float),
        frictionless_note(layout, model),
    )


def frictionless_note(layout: RobotLayout, model: mujoco.MjModel) -> list[str]:
    """fit.json's note on the geoms the robot file makes frictionless but publishes with ``condim`` above 1 (a
    URDF's ``<gazebo>`` mu1 0 imports as friction 0, condim 3): :func:`~bioform_mj.robots.prepare.prepare_robot`
    simulates them with ``condim 1`` (:func:`~bioform_mj.robots.layout.frictionless`, design §13), as ``robot
    check`` and ``bioform run`` do. With condim 3, MuJoCo's pyramidal cone at its smallest friction 1e-5 made the
    Kobuki's damped rollouts blow up (wheel damping 0.00088 N·m·s/rad: wheels at 320 rad/s)."""
    geoms = [
        g
        for g, mu, c in layout.published_contacts
        if c > 1 and frictionless(mu, c) and int(model.geom(g).condim[0]) == 1  # not a caster_friction's target
    ]
    if not geoms:
        return []
    return [
        f"frictionless contact geom(s) {', '.join(geoms)} (sliding friction below {FRICTIONLESS:g} as published, "
        "condim above 1) "
        "simulated with condim 1, as robot check and bioform run do (design §13)"
    ]


def effort_to_ctrl(robot: SimRobot, model: mujoco.MjModel, effort: np.ndarray) -> np.ndarray:
    """``ctrl`` (len, ``model.nu``) for the recorded efforts ``effort`` (len, 2; N·m about each wheel joint's
    own axis, left and right): ``wheel_sign`` turns them forward-positive, as the plant's torque ``τ``, and
    each motor takes ``dc_ctrl_scale · τ`` (1 for a torque motor; design §8.2 for a ``<dcmotor>``)."""
    from bioform_mj.robots.layout import dc_ctrl_scale

    lay = robot.layout
    sign = np.asarray(lay.wheel_sign, float)
    ctrl = np.zeros((effort.shape[0], model.nu))
    for i, m in enumerate(lay.motors):
        a = model.actuator(m).id
        ctrl[:, a] = dc_ctrl_scale(model, a) * sign[i] * effort[:, i]
    return ctrl


def _yaw_quat(yaw: float) -> np.ndarray:
    return np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])


def initial_state(
    robot: SimRobot,
    model: mujoco.MjModel,
    angle: np.ndarray,
    speed: np.ndarray,
    yaw: float = 0.0,
    others: dict[str, tuple[float, float]] | None = None,
) -> np.ndarray:
    """The full-physics state (``mjSTATE_FULLPHYSICS``) at wheel angles ``angle`` (rad) and speeds ``speed``
    (rad/s, the joints' own sense), heading ``yaw`` (rad); the body velocity that rolling implies. ``others``:
    recorded angle (rad) and speed (rad/s) of other 1-dof joints (caster swivels and rollers; NaN: as at rest):
    the TIAGo's casters, started pointing ahead in every chunk, turned round against their swivel damping
    where the robot drove otherwise, a drag no parameter of the fit holds."""
    lay = robot.layout
    data = mujoco.MjData(model)
    q = robot.rest_qpos.copy()
    a = robot.free_qpos
    mujoco.mju_mulQuat(q[a + 3 : a + 7], _yaw_quat(yaw), robot.rest_qpos[a + 3 : a + 7].copy())
    for k in range(2):
        q[robot.wheel_qpos[k]] = angle[k]
    qv = np.zeros(model.nv)
    for name, (a_j, w_j) in (others or {}).items():
        j = model.joint(name)
        if math.isfinite(a_j):
            q[int(j.qposadr[0])] = a_j
        if math.isfinite(w_j):
            qv[int(j.dofadr[0])] = w_j
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    r, l = lay.wheel_radius, lay.half_track
    fwd = np.asarray(lay.wheel_sign, float) * np.asarray(speed, float) * r  # forward rim speeds, m/s
    v, w = 0.5 * (fwd[0] + fwd[1]), (fwd[1] - fwd[0]) / (2 * l)
    base = model.body(lay.base).id
    R = data.xmat[base].reshape(3, 3)
    heading = R[:, 0] - R[2, 0] * np.array([0, 0, 1.0])
    heading /= np.linalg.norm(heading) or 1.0
    omega = np.array([0.0, 0.0, w])
    axle_world = data.xpos[base] + R @ robot.axle_base
    v_origin = v * heading + np.cross(omega, data.xpos[base] - axle_world)
    d = robot.free_dof
    qv[d : d + 3] = v_origin  # free joint: linear velocity in the world frame
    qv[d + 3 : d + 6] = R.T @ omega  # angular velocity in the body frame
    for k in range(2):
        qv[robot.wheel_dof[k]] = speed[k]
    data.qvel[:] = qv
    state = np.empty(mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_FULLPHYSICS))
    mujoco.mj_getState(model, data, state, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    return state


def sensor_times(state_times: np.ndarray, model: mujoco.MjModel) -> np.ndarray:
    """The times (s) of ``mujoco.rollout``'s sensordata rows, given its state rows' times ``state_times``.

    Row ``i`` of a rollout holds the state *after* step ``i`` (time ``t0 + (i + 1) dt``) but the sensordata
    ``mj_step`` computed *before* integrating it (time ``t0 + i dt``); ``mujoco.sysid`` labels the sensordata
    with the state's times. Compared with recorded speeds stamped when measured, the simulated ones came one
    step late: on a 60 s Kobuki recording (test recorder, no noise) that lag biased the chassis mass by −0.9 %
    (2.973 kg ± 0.016 against 3.0) and a wheel's dry friction by +4 % (0.00625 ± 0.00022 N·m against 0.006),
    both outside their intervals."""
    return np.asarray(state_times, float) - float(model.opt.timestep)


def other_joints(robot: SimRobot) -> tuple[str, ...]:
    """The robot's 1-dof joints that move in the fit's model besides the two wheels (caster swivels and
    rollers, free joints the mapping leaves free): a recording that holds them gives each chunk its start."""
    model = robot.spec.compile()
    wheels = set(robot.layout.wheel_joints)
    one_dof = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    return tuple(
        model.joint(j).name
        for j in range(model.njnt)
        if int(model.jnt_type[j]) in one_dof and model.joint(j).name not in wheels
    )

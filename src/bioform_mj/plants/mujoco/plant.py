"""MuJoCo plant: ``n`` MJCF differential-drive robots on a floor, driven by wheel torques (design §8).

Reads each robot's pose ``(x, y, θ)`` of the axle midpoint and its body-frame ``(υ, ω)``
from the free joint's ``qpos``/``qvel`` and the axle midpoint's position in the base frame
(:meth:`MujocoPlant.observe` has the formula); writes the wheel motor ``ctrl`` (N·m; the
motors' gear sign makes positive torque drive forward whichever way a joint axis points). The
disturbance accelerations ``d = (d1, d2)`` of eq. 34 enter as ``xfrc_applied`` on each
chassis: a force ``M_eff d1`` along the heading and a yaw torque ``I_eff d2``, with
``M_eff = 1/(a_eff r)``, ``I_eff = l/(b_eff r)``, so that they are accelerations as in the
paper. Torque and disturbance are held over one control period (zero-order hold at ``t``).

Every id and address is looked up once, by name, at construction; ``observe``/``step`` are
vectorised over robots through the precomputed index arrays.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from pathlib import Path

import mujoco
import numpy as np

from bioform_mj.core.equations import slip_ratio
from bioform_mj.core.errors import Diverged
from bioform_mj.core.jitwatch import precompile
from bioform_mj.core.thresholds import SLIP_RATIO, SLIP_TIME, TIP_ANGLE_DEG, slip_floor_entry
from bioform_mj.formation.disturbance import harmonic_rows
from bioform_mj.plants.mujoco.contacts import ContactReader, robot_geoms, watch_contacts, watch_proximity
from bioform_mj.plants.mujoco.kernels import (
    HAVE_MJ_STEP,
    MjIO,
    Sensors,
    Watch,
    apply_inputs,
    delivered_add,
    delivered_feed,
    new_odometry,
    observe,
    odometry_read,
    odometry_reset,
    physics_steps,
    run_chunk,
    sense,
    watch_slip,
    watch_tilt,
)
from bioform_mj.robots.analysis import layout_of
from bioform_mj.robots.layout import RobotLayout, dc_ctrl_scale
from bioform_mj.robots.params import RobotParams, robot_parameters, running_data
from bioform_mj.robots.prepare import prepare_robots
from bioform_mj.robots.scene import Markers, build_scene, compile_scene, follower_prefix, payload_inertial

log = logging.getLogger(__name__)

__all__ = ["MujocoPlant"]

_WARNING_NAMES = {int(w): w.name for w in mujoco.mjtWarning.__members__.values() if w.name != "mjNWARNING"}


class MujocoPlant:
    """A team of ``n`` MuJoCo robots behind the :class:`~bioform_mj.plants.base.Plant` interface.

    Parameters
    ----------
    robot_files : sequence of str, Path or :class:`~bioform_mj.robots.refs.RobotRef`, length n
        One robot per follower (shipped name, MJCF path, or file + mapping); robots may differ.
    initial_poses : array (n, 3)
        ``(x m, y m, θ rad)`` of each follower's axle midpoint.
    control_dt : float
        Control period, s.
    physics_dt : float
        MuJoCo time step, s; ``control_dt`` must be an integer multiple of it.
    disturbance : callable ``t -> (n, 2)`` or None
        Disturbance accelerations ``[d1 m/s², d2 rad/s²]`` at time ``t`` s (None: zero).
    slots : bool
        Show mocap markers for the formation slots.
    floor_friction : float, optional
        Override of the floor's sliding friction (see :func:`bioform_mj.robots.scene.build_scene`).
    friction_patch : (x0, y0, x1, y1, mu), optional
        A low-friction floor rectangle (see :func:`bioform_mj.robots.scene.build_scene`).
    sensing : "truth" or "odometry"
        What the controller is given (design §8.3): the simulator's pose and velocity, or each
        robot's dead reckoning from its wheel encoders and gyro (:attr:`odo`, :meth:`measurement`).
    encoder_cpr : float or array (n,)
        Encoder counts per wheel revolution (odometry only).
    sensor_dt : float
        Sensor period, s (0: every physics step); a multiple of ``physics_dt`` dividing ``control_dt``.
    gyro_noise, gyro_bias : float
        Gyro z white-noise standard deviation per sample and constant bias, rad/s.
    seed : int
        Seed of the gyro noise (a counter hash of ``(seed, robot, sample)``).

    Attributes
    ----------
    model, data, spec : the compiled ``MjModel``, its ``MjData`` and the scene ``MjSpec``.
    sensors_computed : bool, whether MuJoCo computes ``sensordata`` (only with ``sensing="odometry"``).
    n_substeps : int, physics steps per control period.
    tau_max : array (n,), torque limit of each follower's motors, N·m.
    params : list of :class:`~bioform_mj.robots.params.RobotParams`, current per follower.
    layouts : list of :class:`~bioform_mj.robots.layout.RobotLayout` (names prefixed), per follower.

    Index arrays (looked up once; read by the compiled loop kernels, keep their meaning):

    - ``_q7`` (n, 7): ``qpos`` addresses of each base's free joint (x y z, quaternion w x y z);
    - ``_v6`` (n, 6): its ``qvel`` addresses (world-frame linear velocity of the base origin,
      base-frame angular velocity);
    - ``_ctrl`` (n, 2): actuator ids of the [left, right] wheel torque motors (ctrl in N·m,
      positive = forward: the gear carries the wheel sign);
    - ``_base`` (n,): base body ids; ``_m_eff`` (n,) kg, ``_i_eff`` (n,) kg·m², ``_c`` (n, 2);
    - ``_axle`` (n, 3): the axle midpoint (midpoint of the wheel joint anchors) in the base
      body's frame, m — the reference point of pose and ``υ``;
    - ``_wheel_dof`` (n, 2): ``qvel`` addresses of the [left, right] wheel joints;
    - ``_wheel_sign`` (n, 2): ±1 such that ``sign · qvel[_wheel_dof]`` is the forward wheel rate, rad/s;
    - ``_wheel_radius`` (n,) m, ``_half_track`` (n,) m.
    """

    #: a chassis whose z axis is tilted more than this from vertical has tipped over (rad);
    #: compare ``upright()`` (cos tilt) with ``cos(TIP_ANGLE)`` (``core/thresholds.py: TIP_ANGLE_DEG``)
    TIP_ANGLE = float(np.radians(TIP_ANGLE_DEG))

    def __init__(
        self,
        robot_files: Sequence[str | Path],
        initial_poses: np.ndarray,
        control_dt: float,
        physics_dt: float,
        disturbance: Callable[[float], np.ndarray] | None = None,
        *,
        slots: bool = True,
        floor_friction: float | None = None,
        friction_patch: Sequence[float] | None = None,
        sensing: str = "truth",
        encoder_cpr: float | Sequence[float] = 4096.0,
        sensor_dt: float = 0.0,
        gyro_noise: float = 0.0,
        gyro_bias: float = 0.0,
        seed: int = 0,
        obstacles: Sequence = (),
        safety_distance: float = 0.0,
    ) -> None:
        if not (physics_dt > 0 and control_dt > 0):
            raise ValueError(f"control_dt and physics_dt must be > 0, got {control_dt}, {physics_dt}")
        if physics_dt > control_dt * (1 + 1e-9):
            raise ValueError(f"physics_dt {physics_dt} s exceeds control_dt {control_dt} s")
        n_sub = round(control_dt / physics_dt)
        if abs(n_sub * physics_dt - control_dt) > 1e-9 * control_dt:
            raise ValueError(f"control_dt {control_dt} s is not an integer multiple of physics_dt {physics_dt} s")
        self.n = len(robot_files)
        self.control_dt = float(control_dt)
        self.physics_dt = float(physics_dt)
        self.n_substeps = int(n_sub)
        self.robot_files = [str(f) for f in robot_files]
        self.initial_poses = np.array(initial_poses, dtype=float)
        self.disturbance = disturbance  # None: no disturbance (skips the xfrc_applied work)
        if sensing not in ("truth", "odometry"):
            raise ValueError(f"sensing must be 'truth' or 'odometry', got {sensing!r}")
        self.sensing = sensing
        every = 1 if not sensor_dt else round(sensor_dt / physics_dt)
        if sensor_dt and (
            every < 1 or abs(every * physics_dt - sensor_dt) > 1e-9 * sensor_dt or self.n_substeps % every
        ):
            raise ValueError(
                f"sensor_dt {sensor_dt} s must be a multiple of physics_dt {physics_dt} s "
                f"that divides control_dt {control_dt} s"
            )

        prepared = prepare_robots(robot_files)  # each distinct robot read and analysed once
        #: each robot file's own ``<option timestep>``, s (the scene runs at ``physics_dt``)
        self.file_timesteps: tuple[float, ...] = tuple(float(p[0].option.timestep) for p in prepared)
        self.spec = build_scene(
            robot_files,
            self.initial_poses,
            slots=slots,
            floor_friction=floor_friction,
            timestep=physics_dt,
            friction_patch=friction_patch,
            sensors=sensing == "odometry",
            obstacles=obstacles,
            prepared=prepared,
        )
        self.obstacles = list(obstacles)  # bioform_mj.formation.obstacles.Obstacle rows (design §19)
        self.model, self.data = compile_scene(self.spec)
        m = self.model
        #: whether MuJoCo computes the scene's sensors each step (design §8.3): only with sensing =
        #: "odometry", the one reader of ``sensordata`` in a run (the plant's dead reckoning, the full-state
        #: log's IMU columns). With "truth" the robot files' own sensors (10 per paper robot) are skipped by
        #: ``mjDSBL_SENSOR`` on the compiled model (``sensordata`` stays 0; the physics is bit-identical, the
        #: written ``scene.xml`` keeps them): 2-9 % of ``mj_step`` at 256 robots (docs/findings/performance.md)
        self.sensors_computed = sensing == "odometry"
        if not self.sensors_computed:
            m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_SENSOR)
        n = self.n
        prefixes = [follower_prefix(i) for i in range(n)]

        # ids and addresses, once, by name
        self.layouts: list[RobotLayout] = [layout_of(m, p) for p in prefixes]
        self._base = np.array([m.body(lay.base).id for lay in self.layouts])
        roots = m.body_jntadr[self._base]  # the base's free joint (checked by the scene)
        qadr = m.jnt_qposadr[roots]
        dadr = m.jnt_dofadr[roots]
        self._q7 = qadr[:, None] + np.arange(7)  # (n, 7) into qpos: x y z, quaternion w x y z
        self._v6 = dadr[:, None] + np.arange(6)  # (n, 6) into qvel: world-frame linear, body-frame angular
        # each base's first address, contiguous: observe compiles for one layout, the chunk's (issue 28)
        self._q0, self._v0 = (np.ascontiguousarray(a[:, 0], dtype=np.int64) for a in (self._q7, self._v6))
        lays = self.layouts
        self._ctrl = np.array([[m.actuator(a).id for a in lay.motors] for lay in lays])  # (n, 2)
        # ctrl per N·m of wheel torque: 1 for torque motors, the DC driver's input otherwise (§8.2)
        self._ctrl_scale = np.array([[dc_ctrl_scale(m, int(a)) for a in row] for row in self._ctrl])
        self._axle = np.array([lay.axle for lay in lays], dtype=float)  # (n, 3) base frame, m
        # DC motors (design §8.2): the learner is fed the wheel torque delivered, measured as the
        # driver would (current × k_t × gear): actuator_force × gear × wheel sign, mean over the period
        dc = int(mujoco.mjtDyn.mjDYN_DCMOTOR)
        self._feed = np.array([all(int(m.actuator_dyntype[a]) == dc for a in row) for row in self._ctrl])
        self.feed_delivered = bool(self._feed.any())  # False (all ideal): the commanded torque, as before
        self._wheel_dof = np.array([[m.jnt_dofadr[m.joint(j).id] for j in lay.wheel_joints] for lay in lays])
        self._wheel_sign = np.array([lay.wheel_sign for lay in lays], dtype=float)  # (n, 2)
        self._to_wheel = np.where(self._feed[:, None], m.actuator_gear[self._ctrl, 0] * self._wheel_sign, 0.0)
        self._dacc = np.zeros((n, 2))  # delivered wheel torque summed over the period's physics steps
        self.row_state = np.zeros((0, 0))  # (K, width): the compiled chunk copies each log row's raw state here
        self._wheel_radius = np.array([lay.wheel_radius for lay in lays], dtype=float)
        self._half_track = np.array([lay.half_track for lay in lays], dtype=float)
        self._axle_zero = not np.any(self._axle)  # shipped robots: base origin on the axle
        self._markers = Markers(m, n)
        self._heading = (self._base[:, None], np.array([0, 3]))  # (R00, R10) of each base in xmat
        self._up = np.ones(n)  # cosine of each chassis' tilt at the last observe()
        self.tip_step = np.full(n, -1, dtype=np.int64)  # first control step each robot was found tipped
        self.tilt_cos = float(np.cos(np.radians(TIP_ANGLE_DEG)))
        self.slip_run = np.zeros(n, dtype=np.int64)  # consecutive control steps with a wheel slipping
        self.slip_step = np.full(n, -1, dtype=np.int64)  # step at which a slip first lasted SLIP_TIME
        self._slip_need = max(1, int(round(SLIP_TIME / self.control_dt)))
        self._wdof = np.ascontiguousarray(self._wheel_dof, dtype=np.int64)
        self._warnings = [self.data.warning[i] for i in range(int(mujoco.mjtWarning.mjNWARNING))]
        self._warn = self.data.warning.number  # view of the warning counters, read by the compiled loop
        self._dist = self._dist_rows()
        cpr = np.broadcast_to(np.asarray(encoder_cpr, dtype=float), (n,)).copy()
        if sensing == "odometry" and not np.all(cpr >= 1):
            raise ValueError(f"encoder_cpr must be >= 1 count per revolution, got {cpr.tolist()}")
        if sensing == "odometry":
            from bioform_mj.robots.scene import SENSORS

            adr = np.array(
                [[m.sensor_adr[m.sensor(p + s_).id] for s_ in SENSORS[:3]] for p in prefixes], dtype=np.int64
            )
            enc, gyro = np.ascontiguousarray(adr[:, :2]), np.ascontiguousarray(adr[:, 2])
        else:
            enc, gyro = np.zeros((n, 2), dtype=np.int64), np.zeros(n, dtype=np.int64)
        self.sensors = Sensors(
            sensing == "odometry",
            enc,
            gyro,
            self._wheel_sign.copy(),
            self._wheel_radius.copy(),
            cpr,
            float(gyro_bias),
            float(gyro_noise),
            float(seed % 2147483647),
            int(every),
            float(every * physics_dt),
        )
        self.odo = new_odometry(n)

        # nominal inertial properties of each base, restored by reset()
        b = self._base
        self._nominal = (m.body_mass[b].copy(), m.body_ipos[b].copy(), m.body_iquat[b].copy(), m.body_inertia[b].copy())
        self._payload_added = False
        self._prefixes = prefixes
        self._update_params()
        self.tau_max = np.array([min(p.tau_max) for p in self.params])
        for i, p in enumerate(self.params):
            limit = p.traction_limit * self._wheel_friction(i)
            if max(p.tau_max) > limit:
                log.info(  # said as a RobotWarning before a run (assess.feasibility)
                    "follower %d: torque limit %.3g N·m exceeds the traction limit μ m g r/2 = %.3g N·m: "
                    "the wheels can skid",
                    i + 1,
                    max(p.tau_max),
                    limit,
                )
        from bioform_mj.robots.limits import top_speed

        #: m/s: the slip ratio's speed floor, scaled to the slowest robot's top speed (core.thresholds.slip_v_floor)
        # once per distinct robot (a URDF is read again for its <limit velocity>, a xacro one expanded again)
        speeds: dict[tuple, float | None] = {}
        for i, f in enumerate(robot_files):
            key = (f, tuple(self.layouts[i].wheel_joints), float(self.params[i].wheel_radius))
            if key not in speeds:
                speeds[key] = top_speed(f, self, i)[0]
        self.slip_floor_entry = slip_floor_entry(list(speeds.values()))  # summary.json's slip_floor (design §21)
        self.slip_floor = float(self.slip_floor_entry["value"])
        self._step_count = 0
        self._contacts_setup(float(safety_distance))
        self.reset()

    # ------------------------------------------------------------------ contacts (design §19)
    def _contacts_setup(self, safety: float) -> None:
        """The contact and proximity watch (:mod:`.mujoco_contacts`): which geom belongs to which
        follower or obstacle, each robot's collision geoms and bounding radius about its axle midpoint."""
        m, d = self.model, self.data
        mujoco.mj_forward(m, d)
        owner = np.full(m.ngeom, -1, dtype=np.int64)
        axle_w = self._axle_world(d)
        self.contact_geoms, self.footprint_radius = robot_geoms(m, d, self._base, axle_w)
        for i, gs in enumerate(self.contact_geoms):
            owner[gs] = i
        og = [m.geom(o.name).id for o in self.obstacles]
        for k, g in enumerate(og):
            owner[g] = -2 - k
        self._obstacle_geoms = og
        import numba

        self._compiled_steps = HAVE_MJ_STEP and not numba.config.DISABLE_JIT
        self.contacts = ContactReader(
            m, d, owner, self.contact_geoms, og, self.footprint_radius, safety, self.control_dt, self._q7[:, 2]
        )

    def _axle_world(self, d) -> np.ndarray:
        """(n, 2) world position of each robot's axle midpoint now, m."""
        pose = np.empty((self.n, 3))
        vel = np.empty((self.n, 2))
        observe(d.qpos, d.qvel, self._q0, self._v0, self._axle, pose, vel, np.ones(self.n))
        return pose[:, :2]

    def start_overlaps(self, tol: float = 1e-4) -> list[str]:
        """What overlaps at the initial state, one text per pair (empty: none): two followers whose
        collision geoms interpenetrate deeper than ``tol`` m, or a follower inside an obstacle
        (``mj_geomDistance`` on the composed scene; the floor is not counted)."""
        m = self.model
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        xy = self._axle_world(d)
        r = self.footprint_radius
        out = []
        for i in range(self.n):
            # the pairs whose bounding circles meet, found for all j > i at once (a Python test per pair was n²)
            near = np.hypot(xy[i + 1 :, 0] - xy[i, 0], xy[i + 1 :, 1] - xy[i, 1]) <= r[i] + r[i + 1 :]
            for j in (i + 1 + np.flatnonzero(near)).tolist():
                dist = min(
                    mujoco.mj_geomDistance(m, d, a, b, 1.0, None)
                    for a in self.contact_geoms[i]
                    for b in self.contact_geoms[j]
                )
                if dist < -tol:
                    out.append(f"followers {i + 1} and {j + 1} overlap by {-dist * 100:.3g} cm")
            for k, g in enumerate(self._obstacle_geoms):
                ob = self.obstacles[k]
                if np.hypot(xy[i, 0] - ob.x, xy[i, 1] - ob.y) > r[i] + ob.radius:
                    continue
                dist = min(mujoco.mj_geomDistance(m, d, a, g, 1.0, None) for a in self.contact_geoms[i])
                if dist < -tol:
                    out.append(f"follower {i + 1} stands inside {ob.name} (by {-dist * 100:.3g} cm)")
        return out

    def contact_watch(self):
        """What the contact and proximity watches recorded since :meth:`reset` (design §19):
        :class:`~.mujoco_contacts.Watched`, per follower."""
        return self.contacts.watched()

    # ------------------------------------------------------------------ parameters
    def _update_params(self) -> None:
        # kinematics of the configuration the robots run in (qpos0 unless they have joints beyond
        # the wheels: then settled, design §13), shared by all robots
        scratch = running_data(self.model, self.n)
        self.params: list[RobotParams] = [robot_parameters(self.model, p, scratch) for p in self._prefixes]
        self._c = np.array([[p.a_eff, p.b_eff] for p in self.params])
        self._m_eff = np.array([p.mass_eff for p in self.params])  # kg
        self._i_eff = np.array([p.inertia_eff for p in self.params])  # kg·m²

    def _wheel_friction(self, i: int) -> float:
        """Sliding friction μ of follower ``i``'s wheel–floor contact (its explicit pair's, design §13.3,
        else MuJoCo's priority/max rule)."""
        m = self.model
        floor = m.geom("floor").id
        wheel = m.geom(self.layouts[i].wheel_geoms[0]).id
        pair = np.flatnonzero((m.pair_geom1 == floor) & (m.pair_geom2 == wheel))
        if pair.size:
            return float(m.pair_friction[pair[0], 0])
        if m.geom_priority[floor] != m.geom_priority[wheel]:
            winner = floor if m.geom_priority[floor] > m.geom_priority[wheel] else wheel
            return float(m.geom_friction[winner, 0])
        return float(max(m.geom_friction[floor, 0], m.geom_friction[wheel, 0]))

    def _set_const(self) -> None:
        """Recompute the model's derived constants (subtree masses …), keeping the state."""
        m, d = self.model, self.data
        spec = int(mujoco.mjtState.mjSTATE_INTEGRATION)
        state = np.empty(mujoco.mj_stateSize(m, spec))
        mujoco.mj_getState(m, d, state, spec)
        mujoco.mj_setConst(m, d)
        mujoco.mj_setState(m, d, state, spec)
        mujoco.mj_forward(m, d)

    # ------------------------------------------------------------------ Plant interface
    def reset(self) -> None:
        """Robots at their initial poses, at rest, nominal masses (payloads removed); time 0."""
        m, d = self.model, self.data
        if self._payload_added:
            b = self._base
            m.body_mass[b], m.body_ipos[b], m.body_iquat[b], m.body_inertia[b] = (x.copy() for x in self._nominal)
            mujoco.mj_setConst(m, d)
            self._payload_added = False
            self._update_params()
        mujoco.mj_resetData(m, d)  # qpos0 = initial poses; mocap bodies at their spec positions
        mujoco.mj_forward(m, d)
        self._step_count = 0
        if self.sensors.on:  # dead reckoning starts at the true initial pose (sensordata of mj_forward)
            pose = np.empty((self.n, 3))
            vel = np.empty((self.n, 2))
            observe(d.qpos, d.qvel, self._q0, self._v0, self._axle, pose, vel, self._up)
            odometry_reset(d.sensordata, self.sensors, self.odo, pose)
        self.tip_step[:] = -1
        self.slip_run[:] = 0
        self.slip_step[:] = -1
        self._dacc[:] = 0.0
        self._push_until: np.ndarray | None = None  # pushes (faults): see push()
        if hasattr(self, "contacts"):
            self.contacts.reset()

    def observe(self) -> tuple[np.ndarray, np.ndarray]:
        """Pose (n, 3) ``[x, y, θ ∈ (−π, π]]`` and body-frame velocity (n, 2) ``[υ, ω]`` of each
        robot's axle midpoint (:func:`~bioform_mj.core.equations.planar_state`, compiled); new arrays.

        For robot ``i`` with free-joint ``q = qpos[_q7[i]]`` (position ``p``, unit quaternion
        ``(w, x, y, z)`` → rotation ``R``), ``u = qvel[_v6[i]]`` (``v = u[0:3]`` world-frame
        velocity of the base origin, ``Ω = u[3:6]`` base-frame angular velocity) and
        ``a = _axle[i]``:

        - ``R00 = w²+x²−y²−z²``, ``R01 = 2(xy−wz)``, ``R02 = 2(xz+wy)``,
          ``R10 = 2(xy+wz)``, ``R11 = w²−x²+y²−z²``, ``R12 = 2(yz−wx)``,
          ``R20 = 2(xz−wy)``, ``R21 = 2(yz+wx)``, ``R22 = w²−x²−y²+z²``;
        - position: ``x = p0 + R00 a0 + R01 a1 + R02 a2``, ``y = p1 + R10 a0 + R11 a1 + R12 a2``;
        - heading: ``θ = atan2(R10 + 0.0, R00)`` (the base's x axis; ``+ 0.0``: θ ≠ −π);
        - ``c = Ω × a = (Ω1 a2 − Ω2 a1, Ω2 a0 − Ω0 a2, Ω0 a1 − Ω1 a0)`` (base frame), the axle
          midpoint's world velocity ``v_a = v + R c``: ``vx = v0 + R00 c0 + R01 c1 + R02 c2``,
          ``vy = v1 + R10 c0 + R11 c1 + R12 c2``;
        - ``υ = (vx R00 + vy R10) / hypot(R00, R10)``, ``ω = R20 Ω0 + R21 Ω1 + R22 Ω2``.

        With ``a = 0`` (the shipped robots) this is the base origin's pose and velocity.
        """
        pose = np.empty((self.n, 3))
        vel = np.empty((self.n, 2))
        d = self.data
        observe(d.qpos, d.qvel, self._q0, self._v0, self._axle, pose, vel, self._up)
        watch_tilt(self._up, self.tilt_cos, self.tip_step, self._step_count)
        watch_slip(
            d.qvel,
            self._wdof,
            self._wheel_sign,
            self._wheel_radius,
            self._half_track,
            vel,
            SLIP_RATIO,
            self.slip_floor,
            self._slip_need,
            self.slip_run,
            self.slip_step,
            self._step_count,
        )
        return pose, vel

    @staticmethod
    def _rotations(quat: np.ndarray) -> np.ndarray:
        """(n, 3, 3) rotation matrices of unit quaternions (n, 4) ``[w, x, y, z]``."""
        w, x, y, z = quat.T
        return np.stack(
            [
                np.stack([w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                np.stack([2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)], -1),
                np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z], -1),
            ],
            axis=1,
        )

    def wheel_slip(self) -> np.ndarray:
        """(n, 2) slip ratio of the [left, right] wheels: ``|r φ̇ − v_c| / max(|r φ̇|, |v_c|, slip_floor)``
        with ``φ̇ = sign · qvel`` the forward wheel rate and ``v_c = υ ∓ l ω`` the forward speed of
        the wheel's contact point if it rolled (left: −, right: +). 0 when rolling; compare with
        ``core.thresholds.SLIP_RATIO`` held for ``SLIP_TIME`` s."""
        _, vel = self.observe()
        qv = self.data.qvel
        return np.array(
            [
                [
                    slip_ratio(
                        float(qv[self._wheel_dof[i, w]] * self._wheel_sign[i, w]),
                        float(self._wheel_radius[i]),
                        float(vel[i, 0]),
                        float(vel[i, 1]),
                        (2 * w - 1) * float(self._half_track[i]),
                        self.slip_floor,
                    )
                    for w in range(2)
                ]
                for i in range(self.n)
            ]
        )

    def wheel_loads(self, data: mujoco.MjData | None = None) -> np.ndarray:
        """(n, 2) normal force on the [left, right] wheels' floor contacts now, N (``mj_contactForce``).

        Call it after the robots settled at rest (e.g. 0.2 s of zero torque): then it says how the
        weight is shared between wheels and casters, which sets the real traction limit
        ``μ N r`` per wheel (``μ m g r / 2`` only when the wheels carry all the weight).
        """
        m, d = self.model, (self.data if data is None else data)
        gid = {m.geom(g).id: (i, k) for i, lay in enumerate(self.layouts) for k, g in enumerate(lay.wheel_geoms)}
        out = np.zeros((self.n, 2))
        f = np.zeros(6)
        for c in range(d.ncon):
            con = d.contact[c]
            hit = gid.get(int(con.geom1)) or gid.get(int(con.geom2))
            if hit is not None:
                mujoco.mj_contactForce(m, d, c, f)
                out[hit] += f[0]
        return out

    def settled_data(self, seconds: float = 0.2) -> mujoco.MjData:
        """A copy of the scene after ``seconds`` of zero torque from the initial state (the run's own
        state is untouched): its contacts say what each robot stands on (design §13)."""
        m = self.model
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        for _ in range(max(1, int(round(seconds / m.opt.timestep)))):
            mujoco.mj_step(m, d)
        return d

    def settled_wheel_loads(self, seconds: float = 0.2, data: mujoco.MjData | None = None) -> np.ndarray:
        """(n, 2) wheel loads, N, after ``seconds`` of zero torque from the initial state, computed on
        a copy (:meth:`settled_data`, or ``data`` if given): the share of the weight the wheels carry."""
        return self.wheel_loads(self.settled_data(seconds) if data is None else data)

    def unmodelled(self, v: float, w: float) -> list[dict]:
        """Per follower: wheel damping, armature and frictionloss and their size at speeds
        ``v`` m/s, ``w`` rad/s, with what ``ĉ`` should converge to
        (:meth:`~bioform_mj.robots.params.RobotParams.unmodelled`); for ``summary.json``."""
        return [p.unmodelled(v, w) for p in self.params]

    def step(self, tau: np.ndarray, t: float) -> None:
        """Apply wheel torques (n, 2) ``[τ_L, τ_R]`` N·m and ``d(t)`` for one control period."""
        m, d = self.model, self.data
        tau = np.asarray(tau, dtype=float)
        if tau.shape != (self.n, 2):
            raise ValueError(f"tau must have shape ({self.n}, 2), got {tau.shape}")
        dist = self._dist
        use = self.disturbance is not None
        if use and dist is None:  # a disturbance given as a function: its value at t, held
            vals = np.asarray(self.disturbance(t), dtype=float)
            dist = np.zeros((2, 4))
            dist[:, 0] = vals[0]
        apply_inputs(
            np.ascontiguousarray(tau),
            float(t),
            d.ctrl,
            self._ctrl,
            self._ctrl_scale,
            d.xfrc_applied,
            d.xmat,
            self._base,
            self._m_eff,
            self._i_eff,
            np.zeros((2, 4)) if dist is None else dist,
            use,
        )
        if self._push_until is not None:  # faults: an external push on some chassis (push())
            self._apply_push(t)
        self._dacc[:] = 0.0  # this period's delivered torque only (feed_delivered_torque)
        cl = self.contacts.contacts
        k0 = self._step_count * self.n_substeps
        if self.sensors.on or self.feed_delivered or not self._compiled_steps:
            for s_ in range(self.n_substeps):  # after every physics step, as in the compiled loop
                mujoco.mj_step(m, d)
                if self.sensors.on:
                    sense(d.sensordata, self.sensors, self.odo)
                if self.feed_delivered:
                    delivered_add(d.actuator_force, self._ctrl, self._to_wheel, self._dacc)
                watch_contacts(m._address, d._address, *cl, (k0 + s_ + 1) * cl.hdt)
        else:  # the same calls in one compiled loop
            physics_steps(m._address, d._address, self.n_substeps, k0, *cl)
        self._step_count += 1
        for i, w_ in enumerate(self._warnings):
            if w_.number:
                self._raise_warning(i, w_)
        if self._step_count % self.contacts.every == 0:  # as run_chunk: every PROXIMITY_DT
            pose3 = np.column_stack([self._axle_world(d), np.zeros(self.n)])
            watch_proximity(m._address, d._address, *self.contacts.proximity, pose3, self._step_count * self.control_dt)

    def _raise_warning(self, kind: int, stat) -> None:
        name = _WARNING_NAMES.get(kind, str(kind))
        where = ""
        if kind in (int(mujoco.mjtWarning.mjWARN_BADQACC), int(mujoco.mjtWarning.mjWARN_BADQVEL)):
            dof = int(stat.lastinfo)
            if 0 <= dof < self.model.nv:
                where = f" at joint '{self.model.joint(self.model.dof_jntid[dof]).name}'"
        raise Diverged(
            f"MuJoCo warning {name}{where} after control step {self._step_count} "
            f"(sim time {self._step_count * self.control_dt:.4f} s); the simulation is unstable or "
            "overflowed (MuJoCo resets the state on bad values)",
            step=self._step_count,
            time=self._step_count * self.control_dt,
        )

    def feed_delivered_torque(self, tau_body: np.ndarray) -> None:
        """Write the wheel torque delivered over the last :meth:`step` (mean of each DC motor's
        ``actuator_force`` × gear × wheel sign over the physics steps) as ``[τ_a, τ_b]`` into
        ``tau_body`` (n, 2) of the robots with DC motors (design §8.2; the loop passes the stack
        state's ``tau_body``, the learner's input). Nothing when :attr:`feed_delivered` is False."""
        if self.feed_delivered:
            delivered_feed(self._dacc, self.n_substeps, self._feed, tau_body)

    def measurement(self, pose: np.ndarray, vel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """What the controllers are given at a control step: ``(pose, vel)`` (the truth, as passed)
        with sensing = "truth"; with "odometry" the dead reckoning's pose and its mean ``[υ, ω]`` over
        the control period (:func:`~.mujoco_kernels.odometry_read`; call once per control step)."""
        if not self.sensors.on:
            return pose, vel
        odometry_read(self.odo, self.control_dt)
        return self.odo.mpose, self.odo.mvel

    def odometry_drift(self) -> np.ndarray:
        """(n, 2): each robot's odometry error now, ``[|Δ(x, y)| m, |Δθ| rad]`` against the truth."""
        pose, _ = self.observe()
        dth = np.angle(np.exp(1j * (self.odo.pose[:, 2] - pose[:, 2])))
        return np.stack([np.hypot(*(self.odo.pose[:, :2] - pose[:, :2]).T), np.abs(dth)], axis=1)

    def c_true(self) -> np.ndarray:
        """Ground truth ``[a_eff, b_eff]`` (n, 2) from the compiled model (design §8)."""
        return self._c.copy()

    def set_leader(self, pose: np.ndarray, slots: np.ndarray | None) -> None:
        """Move the ghost leader to ``pose`` (3,) ``[x, y, θ]`` and the slot markers to ``slots`` (n, 2)."""
        self._markers.place(self.data, pose, slots)

    def add_payload(self, i: int, mass_kg: float, inertia_kgm2: float) -> None:
        """Follower ``i`` (0-based) picks up a payload at its axle midpoint; ``c_true`` updates.

        ``inertia_kgm2`` is the payload's yaw inertia about its own centre (kg·m²). The
        compiled model is changed in place (mass, centre of mass, inertia of the base,
        then ``mj_setConst``); the state is kept. ``reset()`` removes payloads.
        """
        if not 0 <= i < self.n:
            raise IndexError(f"follower index {i} out of range 0..{self.n - 1}")
        m = self.model
        b = self._base[i]
        mass, ipos, iquat, inertia = payload_inertial(
            m.body_mass[b],
            m.body_ipos[b],
            m.body_iquat[b],
            m.body_inertia[b],
            float(mass_kg),
            float(inertia_kgm2),
            self._axle[i],
        )
        m.body_mass[b], m.body_ipos[b], m.body_iquat[b], m.body_inertia[b] = mass, ipos, iquat, inertia
        self._set_const()
        self._payload_added = True
        self._update_params()

    # ------------------------------------------------------------------ extras
    @property
    def time(self) -> float:
        """MuJoCo's simulation time, s."""
        return float(self.data.time)

    def model_xml(self) -> str:
        """The composed scene as MJCF (as built: payloads added later are not in it)."""
        return self.spec.to_xml()

    # ------------------------------------------------------------------ faults
    def upright(self) -> np.ndarray:
        """(n,) cosine of each chassis' tilt from upright: 1 level, 0 on its side, −1 upside down."""
        self.observe()
        return self._up.copy()

    # ------------------------------------------------------------------ compiled loop
    def _dist_rows(self) -> np.ndarray | None:
        """Rows of a harmonic disturbance for the compiled loop
        (:func:`~bioform_mj.formation.disturbance.harmonic_rows`)."""
        return harmonic_rows(self.disturbance)

    def compiled_chunk(self, ctx, record_inputs=None):
        """The compiled loop over this plant (see ``sim``); None where it cannot run
        (no libmujoco symbol, a non-harmonic disturbance, pushes)."""
        import numba

        if not HAVE_MJ_STEP or self._dist is None or numba.config.DISABLE_JIT:
            return None
        m, d = self.model, self.data
        q7, v6 = self._q0, self._v0
        ctrl_id = np.ascontiguousarray(self._ctrl, dtype=np.int64)
        base = np.ascontiguousarray(self._base, dtype=np.int64)
        rec = record_inputs if record_inputs is not None else (np.zeros((0, m.nu)), np.zeros((0, self.n, 6)))
        use = self.disturbance is not None

        watch = Watch(
            self.tilt_cos,
            self.tip_step,
            self._wdof,
            self._wheel_sign,
            self._wheel_radius,
            self._half_track,
            SLIP_RATIO,
            self.slip_floor,
            self._slip_need,
            self.slip_run,
            self.slip_step,
        )

        ahead: list[bool] = []

        def chunk(k0: int, k1: int, j: int) -> tuple[int, int, int]:
            # built per chunk: a payload event replaces m_eff, i_eff and c between chunks
            io = MjIO(
                d.qpos,
                d.qvel,
                q7,
                v6,
                self._axle,
                self._up,
                d.ctrl,
                ctrl_id,
                self._ctrl_scale,
                d.xfrc_applied,
                d.xmat,
                base,
                self._m_eff,
                self._i_eff,
                self._dist,
                use,
                self._warn,
                d.actuator_force,
                self._to_wheel,
                self._feed,
                self.feed_delivered,
                self._dacc,
            )
            done, j, status = run_chunk(
                ctx,
                k0,
                k1,
                self.n_substeps,
                m._address,
                d._address,
                io,
                watch,
                self._c,
                j,
                rec[0],
                rec[1],
                d.sensordata,
                self.sensors,
                self.odo,
                self.contacts.contacts,
                self.contacts.proximity,
                self.row_state,
            )
            if not ahead:  # after the chunk's own compile, in its burst (the line's estimate is the chunk's)
                # a later run with plant.sensing = "odometry" compiled its reset on its own (2.3 s besides the
                # chunk's 76 s, scripts/compile_time.py): compiled (or loaded) now, not called (design §2)
                precompile(odometry_reset, d.sensordata, self.sensors, self.odo, np.empty((self.n, 3)))
                ahead.append(True)
            self.contacts.check()
            self._step_count = k0 + done
            if status == 2:  # engine.PLANT_FAILED: a MuJoCo warning in step k0 + done
                self._step_count += 1
                for i, w_ in enumerate(self._warnings):
                    if w_.number:
                        self._raise_warning(i, w_)
            return done, j, status

        return chunk

    def push(self, i: int, force_xy, torque_z: float, until_t: float) -> None:
        """Push follower ``i`` (0-based): world-frame force ``force_xy`` (N) and yaw torque
        ``torque_z`` (N·m) on its chassis (at its centre of mass, ``xfrc_applied``), added to the
        disturbance in every control step that starts before ``until_t`` (s). A new push on the same
        follower replaces the old one; ``reset()`` removes all."""
        if not 0 <= i < self.n:
            raise IndexError(f"follower index {i} out of range 0..{self.n - 1}")
        if self._push_until is None:
            self._push_until = np.full(self.n, -np.inf)
            self._push_wrench = np.zeros((self.n, 6))
        self._push_wrench[i] = (force_xy[0], force_xy[1], 0.0, 0.0, 0.0, torque_z)
        self._push_until[i] = until_t

    def _apply_push(self, t: float) -> None:
        active = self._push_until > t + 1e-12
        xf = self.data.xfrc_applied
        if self.disturbance is None:
            xf[self._base] = 0.0  # nothing else writes xfrc_applied: clear the last push
        xf[self._base[active]] += self._push_wrench[active]
        if not active.any():
            self._push_until = None

"""MuJoCo plant: ``n`` MJCF differential-drive robots on a floor, driven by wheel torques (design §8).

Reads each robot's pose ``(x, y, θ)`` of the axle midpoint and its body-frame ``(υ, ω)``
from the free joint's ``qpos``/``qvel``; writes the wheel motor ``ctrl`` (N·m). The
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

from bioform_mj.disturbance import Harmonic
from bioform_mj.errors import Diverged
from bioform_mj.identify import RobotParams, robot_parameters
from bioform_mj.scene import (
    ROBOT,
    Markers,
    build_scene,
    compile_scene,
    follower_prefix,
    payload_inertial,
)

from .mujoco_kernels import HAVE_MJ_STEP, apply_inputs, observe, run_chunk, watch_tilt

log = logging.getLogger(__name__)

#: a chassis tilted further than this from upright (deg) counts as tipped over (outcome ``tipped``)
TIP_ANGLE_DEG = 45.0

__all__ = ["MujocoPlant"]

_WARNING_NAMES = {int(w): w.name for w in mujoco.mjtWarning.__members__.values() if w.name != "mjNWARNING"}


class MujocoPlant:
    """A team of ``n`` MuJoCo robots behind the :class:`~bioform_mj.plants.base.Plant` interface.

    Parameters
    ----------
    robot_files : sequence of str or Path, length n
        One MJCF file (or shipped model name) per follower; robots may differ.
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
        Override of the floor's sliding friction (see :func:`bioform_mj.scene.build_scene`).
    friction_patch : (x0, y0, x1, y1, mu), optional
        A low-friction floor rectangle (see :func:`bioform_mj.scene.build_scene`).

    Attributes
    ----------
    model, data, spec : the compiled ``MjModel``, its ``MjData`` and the scene ``MjSpec``.
    n_substeps : int, physics steps per control period.
    tau_max : array (n,), torque limit of each follower's motors, N·m.
    params : list of :class:`~bioform_mj.identify.RobotParams`, current per follower.
    """

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
    ) -> None:
        if not (physics_dt > 0 and control_dt > 0):
            raise ValueError(f"control_dt and physics_dt must be > 0, got {control_dt}, {physics_dt}")
        if physics_dt > control_dt * (1 + 1e-9):
            raise ValueError(f"physics_dt {physics_dt} s exceeds control_dt {control_dt} s")
        n_sub = round(control_dt / physics_dt)
        if abs(n_sub * physics_dt - control_dt) > 1e-9 * control_dt:
            raise ValueError(
                f"control_dt {control_dt} s is not an integer multiple of physics_dt {physics_dt} s"
            )
        self.n = len(robot_files)
        self.control_dt = float(control_dt)
        self.physics_dt = float(physics_dt)
        self.n_substeps = int(n_sub)
        self.robot_files = [str(f) for f in robot_files]
        self.initial_poses = np.array(initial_poses, dtype=float)
        self.disturbance = disturbance  # None: no disturbance (skips the xfrc_applied work)

        self.spec = build_scene(
            robot_files, self.initial_poses, slots=slots, floor_friction=floor_friction,
            timestep=physics_dt, friction_patch=friction_patch,
        )
        self.model, self.data = compile_scene(self.spec)
        m = self.model
        n = self.n
        prefixes = [follower_prefix(i) for i in range(n)]

        # ids and addresses, once, by name
        self._base = np.array([m.body(p + ROBOT.base).id for p in prefixes])
        roots = m.body_jntadr[self._base]  # the base's free joint (checked by the scene)
        qadr = m.jnt_qposadr[roots]
        dadr = m.jnt_dofadr[roots]
        self._q7 = qadr[:, None] + np.arange(7)  # (n, 7) into qpos: x y z, quaternion w x y z
        self._v6 = dadr[:, None] + np.arange(6)  # (n, 6) into qvel: world-frame linear, body-frame angular
        self._ctrl = np.array([[m.actuator(p + a).id for a in ROBOT.motors] for p in prefixes])  # (n, 2)
        self._markers = Markers(m, n)
        self._heading = (self._base[:, None], np.array([0, 3]))  # (R00, R10) of each base in xmat
        self._axle = np.zeros((n, 3))  # axle midpoint in each base's frame (m): the reference of pose and υ
        self._up = np.ones(n)  # cosine of each chassis' tilt at the last observe()
        self.tip_step = np.full(n, -1, dtype=np.int64)  # first control step each robot was found tipped
        self.tilt_cos = float(np.cos(np.radians(TIP_ANGLE_DEG)))
        self._warnings = [self.data.warning[i] for i in range(int(mujoco.mjtWarning.mjNWARNING))]
        self._warn = self.data.warning.number  # view of the warning counters, read by the compiled loop
        self._dist = self._dist_rows()

        # nominal inertial properties of each base, restored by reset()
        b = self._base
        self._nominal = (
            m.body_mass[b].copy(), m.body_ipos[b].copy(), m.body_iquat[b].copy(), m.body_inertia[b].copy()
        )
        self._payload_added = False
        self._prefixes = prefixes
        self._update_params()
        self.tau_max = np.array([min(p.tau_max) for p in self.params])
        for i, p in enumerate(self.params):
            limit = p.traction_limit * self._wheel_friction(i)
            if max(p.tau_max) > limit:
                log.warning(
                    "follower %d: torque limit %.3g N·m exceeds the traction limit μ m g r/2 = %.3g N·m: "
                    "the wheels can skid", i + 1, max(p.tau_max), limit,
                )
        self._step_count = 0
        self.reset()

    # ------------------------------------------------------------------ parameters
    def _update_params(self) -> None:
        scratch = mujoco.MjData(self.model)  # kinematics at qpos0, shared by all robots
        mujoco.mj_kinematics(self.model, scratch)
        self.params: list[RobotParams] = [robot_parameters(self.model, p, scratch) for p in self._prefixes]
        self._c = np.array([[p.a_eff, p.b_eff] for p in self.params])
        self._m_eff = np.array([p.mass_eff for p in self.params])  # kg
        self._i_eff = np.array([p.inertia_eff for p in self.params])  # kg·m²

    def _wheel_friction(self, i: int) -> float:
        """Sliding friction μ of follower ``i``'s wheel–floor contact (MuJoCo's priority/max rule)."""
        m = self.model
        floor = m.geom("floor").id
        wheel = m.geom(self._prefixes[i] + ROBOT.wheel_geoms[0]).id
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
            m.body_mass[b], m.body_ipos[b], m.body_iquat[b], m.body_inertia[b] = (
                x.copy() for x in self._nominal
            )
            mujoco.mj_setConst(m, d)
            self._payload_added = False
            self._update_params()
        mujoco.mj_resetData(m, d)  # qpos0 = initial poses; mocap bodies at their spec positions
        mujoco.mj_forward(m, d)
        self._step_count = 0
        self.tip_step[:] = -1
        self._push_until: np.ndarray | None = None  # pushes (faults): see push()

    def observe(self) -> tuple[np.ndarray, np.ndarray]:
        """Pose (n, 3) ``[x, y, θ ∈ (−π, π]]`` and body-frame velocity (n, 2) ``[υ, ω]`` of each
        axle midpoint (:func:`~bioform_mj.control.equations.planar_state`); new arrays."""
        pose = np.empty((self.n, 3))
        vel = np.empty((self.n, 2))
        d = self.data
        observe(d.qpos, d.qvel, self._q7[:, 0], self._v6[:, 0], self._axle, pose, vel, self._up)
        watch_tilt(self._up, self.tilt_cos, self.tip_step, self._step_count)
        return pose, vel

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
        apply_inputs(np.ascontiguousarray(tau), float(t), d.ctrl, self._ctrl, d.xfrc_applied, d.xmat, self._base,
                     self._m_eff, self._i_eff, np.zeros((2, 4)) if dist is None else dist, use)
        if self._push_until is not None:  # faults: an external push on some chassis (push())
            self._apply_push(t)
        mujoco.mj_step(m, d, self.n_substeps)
        self._step_count += 1
        for i, w_ in enumerate(self._warnings):
            if w_.number:
                self._raise_warning(i, w_)

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
            m.body_mass[b], m.body_ipos[b], m.body_iquat[b], m.body_inertia[b],
            float(mass_kg), float(inertia_kgm2),
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
        """(2, 4) rows of a harmonic disturbance; zeros if none; None if not harmonic."""
        d = self.disturbance
        if d is None:
            return np.zeros((2, 4))
        if isinstance(d, Harmonic):
            return np.array(d.terms, dtype=float).reshape(2, 4)
        return None

    def compiled_chunk(self, ctx, record_inputs=None):
        """The compiled loop over this plant (see ``sim``); None where it cannot run
        (no libmujoco symbol, a non-harmonic disturbance, pushes)."""
        import numba

        if not HAVE_MJ_STEP or self._dist is None or numba.config.DISABLE_JIT:
            return None
        m, d = self.model, self.data
        q7 = np.ascontiguousarray(self._q7[:, 0], dtype=np.int64)
        v6 = np.ascontiguousarray(self._v6[:, 0], dtype=np.int64)
        ctrl_id = np.ascontiguousarray(self._ctrl, dtype=np.int64)
        base = np.ascontiguousarray(self._base, dtype=np.int64)
        rec = record_inputs if record_inputs is not None else (np.zeros((0, m.nu)), np.zeros((0, self.n, 6)))
        use = self.disturbance is not None

        def chunk(k0: int, k1: int, j: int) -> tuple[int, int, int]:
            done, j, status = run_chunk(
                ctx.gains, ctx.state, ctx.comm, k0, k1, ctx.N, self.control_dt, self.n_substeps, ctx.L_pose,
                ctx.L_vel, m._address, d._address, d.qpos, d.qvel, q7, v6, self._axle, self._up, self.tilt_cos,
                self.tip_step, d.ctrl, ctrl_id,
                d.xfrc_applied, d.xmat, base, self._m_eff, self._i_eff, self._dist, use, self._warn, self._c,
                ctx.pose, ctx.vel, ctx.met, ctx.acc, ctx.log, j, ctx.stride, ctx.offsets, ctx.bounds, ctx.diag,
                rec[0], rec[1])
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

"""Prototype of the batch engine's plant side: many MuJoCo Warp worlds of one composed
scene, observed and driven by Warp kernels built from the same equation source as the
CPU engine (see :mod:`bioform_mj.batch.samesource`).

Each world is one formation (one run). Per world and robot, :func:`_observe` reads the
robot's free-joint ``qpos``/``qvel`` and computes the pose ``(x, y, θ)`` of the axle
midpoint and the body-frame ``(υ, ω)`` with the *same* ``body_state`` equation the CPU
plant uses; :func:`_apply` writes the wheel torques into ``ctrl``. :func:`_track` is a
stand-in controller (a velocity loop through ``wheel_torques``) that shows a control
law running per world on the device between physics steps, with no host round trip.

Everything here is float32 (MuJoCo Warp's precision). Nothing imports this module
unless ``warp`` and ``mujoco_warp`` are installed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import mujoco
import mujoco_warp as mjw
import numpy as np
import warp as wp

from ..control import equations as _E
from ..scene import ROBOT, follower_prefix
from .samesource import warp_equations

__all__ = ["RobotIndex", "WarpBatch", "robot_index", "HETERO_FIELDS"]

EQ = warp_equations(_E, wp.float32)
planar_state = EQ.planar_state  # module globals: Warp resolves kernel globals at build time
sliding_mode = EQ.sliding_mode
saturate = EQ.saturate

#: Model fields (and the derived fields ``mjw.set_const`` rewrites) that must be batched
#: per world for per-world masses/inertias of the robots.
HETERO_FIELDS = (
    "body_mass",
    "body_inertia",
    "body_ipos",
    "body_iquat",
    "body_subtreemass",
    "body_invweight0",
    "dof_invweight0",
)


@dataclass(frozen=True)
class RobotIndex:
    """Addresses of each follower's free joint and motors in the compiled model."""

    base: np.ndarray  # (n,) body id of each base
    qadr: np.ndarray  # (n,) first qpos index of the free joint (x y z, quaternion w x y z)
    dadr: np.ndarray  # (n,) first qvel index (world linear, body angular)
    act: np.ndarray  # (n, 2) actuator ids of [left, right] motors


def robot_index(mjm: mujoco.MjModel) -> RobotIndex:
    """Find followers ``f1/``, ``f2/``, … by name, as ``MujocoPlant`` does."""
    base, n = [], 0
    while True:
        try:
            base.append(mjm.body(follower_prefix(n) + ROBOT.base).id)
        except KeyError:
            break
        n += 1
    if n == 0:
        raise ValueError("the model has no follower bodies f1/base, f2/base, …")
    base = np.array(base)
    root = mjm.body_jntadr[base]
    if np.any(mjm.jnt_type[root] != mujoco.mjtJoint.mjJNT_FREE):
        raise ValueError("every follower base must have a free joint")
    act = np.array([[mjm.actuator(follower_prefix(i) + a).id for a in ROBOT.motors] for i in range(n)])
    return RobotIndex(base, mjm.jnt_qposadr[root].copy(), mjm.jnt_dofadr[root].copy(), act)


# ------------------------------------------------------------------------------ kernels
@wp.kernel
def _observe(
    qpos: wp.array2d(dtype=float),
    qvel: wp.array2d(dtype=float),
    qadr: wp.array(dtype=int),
    dadr: wp.array(dtype=int),
    pose: wp.array2d(dtype=wp.vec3),
    vel: wp.array2d(dtype=wp.vec2),
):
    w, r = wp.tid()
    q = qadr[r]
    v = dadr[r]
    x, y, th, ups, om, up = planar_state(
        qpos[w, q],
        qpos[w, q + 1],
        qpos[w, q + 3],
        qpos[w, q + 4],
        qpos[w, q + 5],
        qpos[w, q + 6],
        qvel[w, v],
        qvel[w, v + 1],
        qvel[w, v + 2],
        qvel[w, v + 3],
        qvel[w, v + 4],
        qvel[w, v + 5],
        0.0,
        0.0,
        0.0,
    )
    pose[w, r] = wp.vec3(x, y, th)
    vel[w, r] = wp.vec2(ups, om)


@wp.kernel
def _apply(tau: wp.array2d(dtype=wp.vec2), act: wp.array2d(dtype=int), ctrl: wp.array2d(dtype=float)):
    w, r = wp.tid()
    t = tau[w, r]
    ctrl[w, act[r, 0]] = t[0]
    ctrl[w, act[r, 1]] = t[1]


@wp.kernel
def _track(
    qpos: wp.array2d(dtype=float),
    qvel: wp.array2d(dtype=float),
    qadr: wp.array(dtype=int),
    dadr: wp.array(dtype=int),
    act: wp.array2d(dtype=int),
    cmd: wp.array2d(dtype=wp.vec2),
    gains: wp.vec4,  # â, b̂, c (both channels), φ
    lim: float,
    ctrl: wp.array2d(dtype=float),
    vel: wp.array2d(dtype=wp.vec2),
):
    """A plain velocity loop (test fixture): observe (``planar_state``), the sliding-mode
    torques with a boundary layer and zero command derivative (``sliding_mode``),
    steer-priority saturation (``saturate``), write ``ctrl``."""
    w, r = wp.tid()
    q = qadr[r]
    v = dadr[r]
    x, y, th, ups, om, up = planar_state(
        qpos[w, q],
        qpos[w, q + 1],
        qpos[w, q + 3],
        qpos[w, q + 4],
        qpos[w, q + 5],
        qpos[w, q + 6],
        qvel[w, v],
        qvel[w, v + 1],
        qvel[w, v + 2],
        qvel[w, v + 3],
        qvel[w, v + 4],
        qvel[w, v + 5],
        0.0,
        0.0,
        0.0,
    )
    c = cmd[w, r]
    r0, r1 = sliding_mode(c[0], c[1], 0.0, 0.0, ups, om, gains[0], gains[1], gains[2], gains[2], gains[3])
    tl, tr = saturate(r0, r1, lim, True)
    ctrl[w, act[r, 0]] = tl
    ctrl[w, act[r, 1]] = tr
    vel[w, r] = wp.vec2(ups, om)


# ------------------------------------------------------------------------------ engine
class WarpBatch:
    """``nworld`` copies of a composed scene on a Warp device.

    Parameters
    ----------
    mjm : the compiled scene (``MjModel``), e.g. from ``bioform run … --out DIR``'s ``scene.xml``.
    nworld : number of worlds.
    device : Warp device (``"cpu"``, ``"cuda:0"``).
    hetero : batch the fields of :data:`HETERO_FIELDS` per world, so that
        :meth:`set_base_mass` can give every world its own robot masses.
    nconmax, njmax : contact / constraint-row capacities per world. MuJoCo Warp's own
        defaults come from the initial state and are too small for many robots (the
        64-robot scene overflows ``njmax = 64`` at once, and overflowing rows are dropped
        with only a printed warning); ours: 8 contacts and 32 rows per robot, + 16.
    """

    def __init__(
        self,
        mjm: mujoco.MjModel,
        nworld: int,
        device: str = "cpu",
        *,
        hetero: bool = False,
        nconmax: int | None = None,
        njmax: int | None = None,
    ) -> None:
        self.mjm = mjm
        self.nworld = int(nworld)
        self.device = wp.get_device(device)
        self.idx = robot_index(mjm)
        self.n = len(self.idx.base)
        mjd = mujoco.MjData(mjm)
        mujoco.mj_forward(mjm, mjd)
        nconmax = 8 * self.n + 16 if nconmax is None else nconmax
        njmax = 32 * self.n + 16 if njmax is None else njmax
        self.nconmax, self.njmax = nconmax, njmax
        with wp.ScopedDevice(self.device):
            batch = {f: self.nworld for f in HETERO_FIELDS} if hetero else None
            self.m = mjw.put_model(mjm, batch_sizes=batch)
            self.d = mjw.put_data(mjm, mjd, nworld=self.nworld, nconmax=nconmax, njmax=njmax)
            self.qadr = wp.array(self.idx.qadr.astype(np.int32), dtype=int)
            self.dadr = wp.array(self.idx.dadr.astype(np.int32), dtype=int)
            self.act = wp.array(self.idx.act.astype(np.int32), dtype=int)
            self.pose = wp.zeros((self.nworld, self.n), dtype=wp.vec3)
            self.vel = wp.zeros((self.nworld, self.n), dtype=wp.vec2)
            self.tau = wp.zeros((self.nworld, self.n), dtype=wp.vec2)

    # -- heterogeneous parameters
    def set_base_mass(self, mass: np.ndarray) -> None:
        """Mass (kg) of every follower's base in every world, ``(nworld, n)``; inertia is
        scaled with it (as a payload at the centre of mass would), then ``mjw.set_const``
        recomputes the derived fields per world."""
        mass = np.asarray(mass, dtype=np.float32)
        b = self.idx.base
        bm = self.m.body_mass.numpy()
        bi = self.m.body_inertia.numpy()
        if bm.shape[0] != self.nworld:
            raise ValueError("construct with hetero=True to vary masses per world")
        scale = mass / bm[:, b]
        bm[:, b] = mass
        bi[:, b] *= scale[..., None]
        self.m.body_mass.assign(bm)
        self.m.body_inertia.assign(bi)
        with wp.ScopedDevice(self.device):
            mjw.set_const(self.m, self.d)

    # -- plant interface
    def observe(self) -> tuple[np.ndarray, np.ndarray]:
        """Pose ``(nworld, n, 3)`` and body-frame velocity ``(nworld, n, 2)`` (host copies)."""
        wp.launch(
            _observe,
            dim=(self.nworld, self.n),
            inputs=[self.d.qpos, self.d.qvel, self.qadr, self.dadr],
            outputs=[self.pose, self.vel],
            device=self.device,
        )
        return self.pose.numpy(), self.vel.numpy()

    def set_torques(self, tau: np.ndarray) -> None:
        """Wheel torques ``(nworld, n, 2)`` ``[τ_L, τ_R]`` N·m, held until changed."""
        self.tau.assign(np.asarray(tau, dtype=np.float32).reshape(self.nworld, self.n, 2))
        wp.launch(
            _apply, dim=(self.nworld, self.n), inputs=[self.tau, self.act], outputs=[self.d.ctrl], device=self.device
        )

    def step(self, nstep: int = 1) -> None:
        with wp.ScopedDevice(self.device):
            for _ in range(nstep):
                mjw.step(self.m, self.d)

    def run_tracking(self, cmd: np.ndarray, nstep: int, gains=(0.4, 10.0, 3.0, 0.1), lim: float = 20.0) -> None:
        """``nstep`` × [stand-in control kernel, physics step], all on the device."""
        c = wp.array(
            np.asarray(cmd, dtype=np.float32).reshape(self.nworld, self.n, 2), dtype=wp.vec2, device=self.device
        )
        g = wp.vec4(*[float(x) for x in gains])
        with wp.ScopedDevice(self.device):
            for _ in range(nstep):
                wp.launch(
                    _track,
                    dim=(self.nworld, self.n),
                    inputs=[self.d.qpos, self.d.qvel, self.qadr, self.dadr, self.act, c, g, float(lim)],
                    outputs=[self.d.ctrl, self.vel],
                )
                mjw.step(self.m, self.d)

    def qpos(self) -> np.ndarray:
        return self.d.qpos.numpy()

    def time_steps(self, nstep: int) -> float:
        """Wall seconds per physics step of all worlds (after one warm-up step)."""
        self.step(1)
        wp.synchronize_device(self.device)
        t0 = time.perf_counter()
        self.step(nstep)
        wp.synchronize_device(self.device)
        return (time.perf_counter() - t0) / nstep

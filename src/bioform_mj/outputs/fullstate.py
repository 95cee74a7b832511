"""What a ROS 2 bag needs beyond the planar log: the full 3-D state at every log row and at the end.

``simulate(sc, full_state=True)`` (and ``bioform run --rosbag``) runs a :class:`StateSampler` as an
observer at the log's period; ``log.npz`` then gains the channels of :data:`STATE_CHANNELS`, sampled at
each log row's time ``t_j`` and once more at the run's end ``T`` (``t_state`` has ``K + 1`` entries,
``t_state[:K] == t``), and the static :data:`STATE_STATICS`. The existing channels are not touched, and
a run without ``full_state`` writes exactly the log it wrote before (design §9).

Where the values come from (design §8, §8.3):

- MuJoCo plant: each base's free joint (``qpos``: position and unit quaternion of the base body's
  frame; ``qvel``: world-frame linear and base-frame angular velocity), the wheel hinge joints
  (``sign · qpos``, ``sign · qvel``: forward-positive, as ``tau``), and, with ``plant.sensing =
  "odometry"`` (the scene then has an IMU), the gyro and accelerometer as MuJoCo last computed them
  (at the start of the last physics step before the sample: one ``physics_dt`` behind, noise-free);
- ideal plant and any other plant: the planar state (``z``, roll, pitch, lateral and vertical
  speeds 0); no wheels (NaN), no IMU.

Read only: the sampler never calls ``plant.observe()`` (which counts tips and slips), so the run's
own numbers are those of a run without it (``tests/test_outputs_rosbag.py``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["STATE_CHANNELS", "STATE_STATICS", "StateSampler", "rpy_of_quat", "quat_of_rpy", "quat_of_yaw"]

#: The channels :class:`StateSampler` adds to the log: name → (trailing shape, meaning). Rows are the
#: log rows' times and then the end of the run (``K + 1`` rows; ``n`` = followers).
STATE_CHANNELS: dict[str, tuple[tuple[str, ...], str]] = {
    "t_state": ((), "s, time of the state sample: each log row's t, then the run's end T"),
    "pose_3d": (("n", "6"), "[x, y, z, roll, pitch, yaw] of the base body's frame (m, rad; ZYX Euler angles)"),
    "twist_3d": (("n", "6"), "[vx, vy, vz, wx, wy, wz] of the base body in its own frame (m/s, rad/s)"),
    "wheel_angle": (("n", "2"), "[left, right] wheel angle, forward-positive (rad; NaN: the plant has no wheels)"),
    "wheel_speed": (("n", "2"), "[left, right] wheel rate, forward-positive (rad/s; NaN: no wheels)"),
    "imu_gyro": (("n", "3"), "gyro [wx, wy, wz] in the IMU frame (rad/s; only where the plant has an IMU)"),
    "imu_accel": (("n", "3"), "accelerometer [ax, ay, az] in the IMU frame (m/s², gravity included; IMU only)"),
    "leader_state": (("5",), "the virtual leader [x, y, θ, υ_r, ω_r] (m, m, rad, m/s, rad/s)"),
}

#: Static entries the sampler adds beside them: name → (shape, meaning).
STATE_STATICS: dict[str, tuple[tuple[str, ...], str]] = {
    "wheel_sign": (("n", "2"), "±1: joint position · sign = the forward-positive wheel angle"),
    "wheel_joints": (("n", "2"), "[left, right] wheel joint names in the robot file (strings)"),
}


def rpy_of_quat(q: np.ndarray) -> np.ndarray:
    """ZYX Euler angles ``[roll, pitch, yaw]`` (rad) of unit quaternions ``q`` (..., 4) ``[w, x, y, z]``."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], axis=-1)


def quat_of_rpy(rpy: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) ``[w, x, y, z]`` of ZYX Euler angles ``[roll, pitch, yaw]`` (rad).

    Where every roll and pitch is +0.0 (a planar robot, a heading) only the yaw's
    cosine and sine are computed: the products below with ``cos(+0) = 1`` and ``sin(+0) = +0`` put in, the
    same operations on the same numbers (the same bits, signed zeros included), a third of the time."""
    a = np.asarray(rpy, dtype=float)
    r, p = a[..., 0], a[..., 1]  # +0.0 exactly where their halves are (or both halves are +0.0: the same bits)
    if a.size and not (r.any() or p.any() or np.signbit(r).any() or np.signbit(p).any()):
        return quat_of_yaw(a[..., 2])
    r, p, y = np.moveaxis(a * 0.5, -1, 0)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ],
        axis=-1,
    )


def quat_of_yaw(yaw: np.ndarray) -> np.ndarray:
    """:func:`quat_of_rpy` of ``[+0.0, +0.0, yaw]`` (yaw (...,) rad; quaternions (..., 4) ``[w, x, y, z]``),
    the same bits: the general formulas' products with ``cos(+0) = 1`` and ``sin(+0) = +0`` put in, the same
    operations on the same numbers (signed zeros included), written into the result (the half yaw in its
    last column, a strided array as in the general formulas): no temporaries beyond the cosine and sine."""
    q = np.empty((*np.shape(yaw), 4))
    w, x, y, z = (q[..., k] for k in range(4))
    np.multiply(np.asarray(yaw, dtype=float), 0.5, out=z)
    cy, sy = np.cos(z, out=np.empty(z.shape)), np.sin(z, out=np.empty(z.shape))  # arrays, also for one yaw
    np.multiply(1.0, cy, out=w)
    np.multiply(1.0, sy, out=z)
    z0c, z0s = np.multiply(0.0, cy, out=cy), np.multiply(0.0, sy, out=sy)  # sr·cp·cy = cr·sp·cy = (+0)·cy; …
    np.add(w, z0s, out=w)  # cr·cp·cy + sr·sp·sy
    np.subtract(z0c, z0s, out=x)  # sr·cp·cy − cr·sp·sy
    np.add(z0c, z0s, out=y)  # cr·sp·cy + sr·cp·sy
    np.subtract(z, z0c, out=z)  # cr·cp·sy − sr·sp·cy
    return q


class StateSampler:
    """Observer (``run.simulate.Observer``) that samples the full 3-D state at every log row and at the end.

    ``log_dt``, ``control_dt``: the scenario's (s); it samples at control steps ``k`` with
    ``k % stride == 0`` (the log's rows) and once in ``finish`` (the end of the run). Where it need
    not visit Python at every row, it does not (the loop then keeps its long chunks):

    - a planar plant (ideal, a user's): the rows are the log's own ``pose`` and ``vel``; only the
      start and the end are sampled;
    - MuJoCo with the compiled chunk (``in_kernel``): the chunk copies each row's ``qpos``, ``qvel``
      and ``sensordata`` into ``plant.row_state`` (``plants/mujoco/kernels.py: copy_row``);
    - MuJoCo step by step: sampled here at every row."""

    def __init__(self, log_dt: float, control_dt: float, in_kernel: bool = False) -> None:
        self.dt = float(control_dt)
        self.stride = max(1, int(round(float(log_dt) / self.dt)))
        self.period = self.stride * self.dt  # s of simulated time between samples
        self.in_kernel = bool(in_kernel)
        self.planar = False
        self._buf: np.ndarray | None = None  # MuJoCo in_kernel: (K, nq + nv [+ nsensordata]) raw rows
        self._plant: Any = None
        self.rows: dict[int, tuple[np.ndarray, ...]] = {}  # control step → sample
        self.end: tuple[int, tuple[np.ndarray, ...]] | None = None
        self._read: Any = None
        self._mj: tuple[Any, ...] | None = None  # MuJoCo: the qpos/qvel/sensordata addresses
        self.imu = False
        self.wheels = False
        self.wheel_sign = np.ones((0, 2))
        self.wheel_joints = np.zeros((0, 2), dtype="<U1")

    # -- the observer protocol --------------------------------------------------------------
    def start(self, run: Any) -> None:
        """Find what the plant offers (MuJoCo's free and wheel joints, its IMU) once."""
        plant = run.plant
        n = int(np.asarray(run.pose).shape[0]) if np.asarray(run.pose).size else int(getattr(plant, "n", 0))
        N = max(1, int(round(float(run.scenario.sim.duration) / self.dt)))  # as run.simulate._timeline
        if hasattr(plant, "model") and hasattr(plant, "data") and hasattr(plant, "_q7"):
            self._read = self._mujoco_reader(plant)
            if self.in_kernel and hasattr(plant, "row_state"):
                d = plant.data
                width = d.qpos.size + d.qvel.size + (d.sensordata.size if self.imu else 0)
                self._buf = np.full(((N - 1) // self.stride + 1, width), np.nan)
                plant.row_state = self._buf
                self._plant = plant
                self.period = (N + 1) * self.dt  # row 0 here, then none until the end
        else:  # the ideal plant, a user's: planar, what the loop measured (= the log's rows)
            self._read = lambda run: (np.array(run.pose, dtype=float), np.array(run.vel, dtype=float))
            self.planar = True
            self.period = (N + 1) * self.dt
        if not self.wheels:
            self.wheel_sign = np.ones((n, 2))
            self.wheel_joints = np.array([["left_wheel", "right_wheel"]] * n)

    def sample(self, run: Any) -> None:
        """At a log row's control step: copy the state (a few small arrays)."""
        k = int(round(run.t / self.dt))
        if k % self.stride == 0:
            self.rows[k] = self._sample(run)

    def finish(self, run: Any) -> None:
        """At the end of the run (``run.t`` = the steps done × ``control_dt``): the last sample."""
        self.end = (int(round(run.t / self.dt)), self._sample(run))
        if self._plant is not None:  # the plant's chunk copies no more rows
            self._plant.row_state = np.zeros((0, 0))
            self._plant = None

    # -- reading the plant ------------------------------------------------------------------
    def _sample(self, run: Any) -> tuple[np.ndarray, ...]:
        """Raw copies only (a few µs); the 3-D quantities are computed once, in :meth:`log_arrays`."""
        return (*self._read(run), np.array(run.leader_pose, dtype=float), np.array(run.leader_vel, dtype=float))

    def _mujoco_reader(self, plant: Any):
        """A :class:`~bioform_mj.plants.mujoco.plant.MujocoPlant`'s ``qpos``, ``qvel`` (and ``sensordata``
        with an IMU) as copies; :meth:`_convert` makes the 3-D state of them."""
        m, d = plant.model, plant.data
        lays = plant.layouts
        self.wheels = True
        self.wheel_sign = np.asarray(plant._wheel_sign, dtype=float).copy()
        prefixes = [f"f{i + 1}/" for i in range(len(lays))]
        self.wheel_joints = np.array(
            [[j[len(p) :] if j.startswith(p) else j for j in lay.wheel_joints] for p, lay in zip(prefixes, lays)]
        )
        sensors = getattr(plant, "sensors", None)
        self.imu = bool(getattr(sensors, "on", False))
        gyro = accel = None
        if self.imu:
            from bioform_mj.robots.scene import SENSORS

            gyro = np.array([m.sensor_adr[m.sensor(p + SENSORS[2]).id] for p in prefixes])[:, None] + np.arange(3)
            accel = np.array([m.sensor_adr[m.sensor(p + SENSORS[3]).id] for p in prefixes])[:, None] + np.arange(3)
        wq = np.array([[m.jnt_qposadr[m.joint(j).id] for j in lay.wheel_joints] for lay in lays])
        self._mj = (np.asarray(plant._q7), np.asarray(plant._v6), wq, np.asarray(plant._wheel_dof), gyro, accel)
        self._nq, self._nv = d.qpos.size, d.qvel.size
        if self.imu:
            return lambda run: (d.qpos.copy(), d.qvel.copy(), d.sensordata.copy())
        return lambda run: (d.qpos.copy(), d.qvel.copy(), None)

    def _convert(self, raw: list[tuple[np.ndarray, ...]]) -> tuple[np.ndarray, ...]:
        """``(pose_3d, twist_3d, wheel_angle, wheel_speed, gyro, accel)`` (rows, n, ·) of the raw samples."""
        if self._mj is None:  # planar: [x, y, θ], [υ, ω] per robot
            pose = np.stack([r[0] for r in raw])
            vel = np.stack([r[1] for r in raw])
            rows, n = pose.shape[:2]
            pose3 = np.zeros((rows, n, 6))
            pose3[..., :2], pose3[..., 5] = pose[..., :2], pose[..., 2]
            twist = np.zeros((rows, n, 6))
            twist[..., 0], twist[..., 5] = vel[..., 0], vel[..., 1]
            nan2, nan3 = np.full((rows, n, 2), np.nan), np.full((rows, n, 3), np.nan)
            return pose3, twist, nan2, nan2.copy(), nan3, nan3.copy()
        q7, v6, wq, wv, gyro, accel = self._mj
        qpos = np.stack([r[0] for r in raw])
        qvel = np.stack([r[1] for r in raw])
        q = qpos[:, q7]  # (rows, n, 7)
        u = qvel[:, v6]  # (rows, n, 6)
        w, x, y, z = np.moveaxis(q[..., 3:7], -1, 0)
        R = np.stack(  # base → world, as MujocoPlant._rotations
            [
                np.stack([w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                np.stack([2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)], -1),
                np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z], -1),
            ],
            axis=-2,
        )
        pose3 = np.concatenate([q[..., :3], rpy_of_quat(q[..., 3:7])], axis=-1)
        twist = np.concatenate([np.einsum("...ji,...j->...i", R, u[..., :3]), u[..., 3:6]], axis=-1)
        wa, ws = self.wheel_sign * qpos[:, wq], self.wheel_sign * qvel[:, wv]
        if self.imu:
            sd = np.stack([r[2] for r in raw])
            g, a = sd[:, gyro], sd[:, accel]
        else:
            g = a = np.full(q.shape[:2] + (3,), np.nan)
        return pose3, twist, wa, ws, g, a

    # -- the log's new entries -----------------------------------------------------------------
    def log_arrays(self, log: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The entries of :data:`STATE_CHANNELS` and :data:`STATE_STATICS` for the run's ``log`` (its
        rows at times ``log["t"]`` s, (K,)): row ``j`` is the state at ``t_j`` (NaN where none was
        sampled), row ``K`` the end of the run. ``imu_*`` only where the plant has an IMU."""
        t = np.asarray(log["t"])
        K = t.shape[0]
        ks = [int(round(float(tj) / self.dt)) for tj in t]
        end_k, end = self.end if self.end is not None else (ks[-1] if ks else 0, None)
        rows: list[tuple[np.ndarray, ...] | None] = []  # (raw state..., leader pose, leader velocity)
        lp, lv = np.asarray(log["leader_pose"], float), np.asarray(log["leader_vel"], float)
        pose, vel = np.asarray(log["pose"], float), np.asarray(log["vel"], float)
        buf, nq, nv = self._buf, getattr(self, "_nq", 0), getattr(self, "_nv", 0)
        for j, k in enumerate(ks):
            if self.planar:
                rows.append((pose[j], vel[j], lp[j], lv[j]))
            elif k in self.rows:
                rows.append(self.rows[k])
            elif buf is not None and j < buf.shape[0] and np.isfinite(buf[j, 0]):
                b = buf[j]
                rows.append((b[:nq], b[nq : nq + nv], b[nq + nv :] if self.imu else None, lp[j], lv[j]))
            else:
                rows.append(None)
        rows.append(end)
        like = next((r for r in rows if r is not None), None)
        out: dict[str, np.ndarray] = {"t_state": np.array([*(k * self.dt for k in ks), end_k * self.dt])}
        names = ("pose_3d", "twist_3d", "wheel_angle", "wheel_speed", "imu_gyro", "imu_accel")
        if like is None:  # nothing sampled (a run that failed before its first row)
            n = self.wheel_sign.shape[0]
            for name, w in zip(names, (6, 6, 2, 2, 3, 3)):
                out[name] = np.full((K + 1, n, w), np.nan)
            out["leader_state"] = np.full((K + 1, 5), np.nan)
        else:
            blank = tuple(None if a is None else np.full_like(a, np.nan) for a in like)
            got = [blank if r is None else r for r in rows]
            for name, arr in zip(names, self._convert([r[:-2] for r in got])):
                out[name] = arr
            out["leader_state"] = np.stack([np.concatenate(r[-2:]) for r in got])
        if not self.imu:
            del out["imu_gyro"], out["imu_accel"]
        out["wheel_sign"] = self.wheel_sign
        out["wheel_joints"] = self.wheel_joints
        return out

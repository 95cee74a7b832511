"""``bioform robot replay``: the recorded torques drive the model open loop (issue 29).

From the recording's first state (wheel angles and speeds, the body rolling with them), the robot is
simulated for the whole recording under the recorded wheel torques (no feedback: the model's own
errors accumulate, as they would in a run), and its wheel speeds (rad/s), forward speed (m/s) and yaw
rate (rad/s) are compared with the recording: RMS differences and, where the recording has odometry, the
position drift (m) at the end.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from bioform_mj.core.errors import InputError
from bioform_mj.robots.realdata.recording import Recording
from bioform_mj.robots.realdata.simmodel import SimRobot, effort_to_ctrl, initial_state, sensor_times

__all__ = ["replay", "check_replay", "compare", "plot_signals", "REPLAY_MAX_BYTES"]


#: largest open-loop replay's arrays (the rolled-out states, sensors and controls of every physics step), bytes: a
#: CSV spanning 3e5 s asked 2.2 GB for its times alone and ended in an internal MemoryError (issue 28)
REPLAY_MAX_BYTES = 2**30


def check_replay(model: mujoco.MjModel, rec: Recording) -> None:
    """Refuse (:class:`InputError`) a replay of ``rec`` whose physics steps would take longer than the automatic
    work's bound (:func:`~bioform_mj.robots.sanity.check_step_budget`) or whose arrays pass
    :data:`REPLAY_MAX_BYTES`, before anything is allocated."""
    from bioform_mj.robots.sanity import check_step_budget

    dt = float(model.opt.timestep)
    hint = "replay a shorter window of the recording"
    check_step_budget(rec.duration, dt, f"{rec.source}: replaying {rec.duration:.3g} s", hint)
    per_step = mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_FULLPHYSICS) + model.nsensordata + model.nu + 4
    need = rec.duration / dt * per_step * 8
    if need > REPLAY_MAX_BYTES:
        raise InputError(
            f"{rec.source}: replaying {rec.duration:.3g} s at {dt:g} s a step needs about {need / 2**30:.3g} GiB, "
            f"above the {REPLAY_MAX_BYTES / 2**30:g} GiB allowed; {hint}"
        )


def replay(robot: SimRobot, rec: Recording) -> dict[str, np.ndarray]:
    """Simulate the whole recording open loop; returns the times (s) and the simulated ``left_speed``,
    ``right_speed`` (rad/s), ``vx`` (m/s), ``wz`` (rad/s) at the joint-state times, and ``xy`` (m)."""
    from mujoco import rollout

    model = robot.spec.compile()
    data = mujoco.MjData(model)
    others = {n: (float(v[0, 0]), float(v[0, 1])) for n, v in rec.others.items()}
    state = initial_state(robot, model, rec.position[0], rec.velocity[:3].mean(axis=0), others=others)
    dt = float(model.opt.timestep)
    check_replay(model, rec)
    n = int(rec.duration / dt)
    tt = np.arange(n) * dt
    ctrl = effort_to_ctrl(robot, model, rec.effort_at(tt))
    st, sens = rollout.rollout(model, data, state, ctrl)
    st, sens = st[0], sens[0]
    t = st[:, 0]
    ts = sensor_times(t, model)  # the sensordata rows are one step behind the state rows
    a = robot.free_qpos
    out = {"t": rec.t.copy()}
    for k, name in ((0, "left_speed"), (1, "right_speed"), (2, "vx"), (7, "wz")):
        out[name] = np.interp(rec.t, ts, sens[:, k])
    xy = np.stack([np.interp(rec.t, t, st[:, 1 + a]), np.interp(rec.t, t, st[:, 2 + a])], axis=1)
    out["xy"] = xy - xy[0]
    return out


def measured(rec: Recording) -> dict[str, np.ndarray]:
    """The recording's signals at the joint-state times (NaN where it has none)."""
    out = {"t": rec.t, "left_speed": rec.velocity[:, 0], "right_speed": rec.velocity[:, 1]}
    nan = np.full(len(rec.t), np.nan)
    out["vx"] = np.interp(rec.t, rec.odom_t, rec.odom_twist[:, 0]) if len(rec.odom_t) else nan
    if len(rec.imu_t):
        out["wz"] = np.interp(rec.t, rec.imu_t, rec.imu_gyro[:, 2])
    else:
        out["wz"] = np.interp(rec.t, rec.odom_t, rec.odom_twist[:, 5]) if len(rec.odom_t) else nan
    if len(rec.odom_t) and np.any(rec.odom_pose[:, :2]):
        xy = np.stack([np.interp(rec.t, rec.odom_t, rec.odom_pose[:, i]) for i in range(2)], axis=1)
        out["xy"] = xy - xy[0]
    return out


def compare(meas: dict[str, np.ndarray], sim: dict[str, np.ndarray]) -> dict[str, Any]:
    """RMS differences (rad/s, m/s, rad/s) and the final position drift (m, where measured)."""
    out: dict[str, Any] = {}
    for k, _unit in (("left_speed", "rad/s"), ("right_speed", "rad/s"), ("vx", "m/s"), ("wz", "rad/s")):
        d = meas[k] - sim[k]
        out[f"{k}_rms"] = float(np.sqrt(np.mean(d**2))) if np.isfinite(d).all() else None
    if "xy" in meas:
        out["drift_m"] = float(np.linalg.norm(meas["xy"][-1] - sim["xy"][-1]))
    return out


def plot_signals(path: Path, meas: dict[str, np.ndarray], sims: dict[str, dict[str, np.ndarray]], title: str) -> None:
    """Measured against simulated wheel speeds and body velocities, one panel each, to ``path`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = (
        ("left_speed", "left wheel (rad/s)"),
        ("right_speed", "right wheel (rad/s)"),
        ("vx", "forward speed (m/s)"),
        ("wz", "yaw rate (rad/s)"),
    )
    fig, axes = plt.subplots(len(panels), 1, figsize=(10, 8), sharex=True)
    styles = {"published": ("tab:red", "--"), "calibrated": ("tab:blue", "-")}
    for ax, (k, label) in zip(axes, panels):
        ax.plot(meas["t"], meas[k], color="k", lw=0.8, label="recorded")
        for name, sim in sims.items():
            color, ls = styles.get(name, ("tab:green", "-"))
            ax.plot(sim["t"], sim[k], color=color, ls=ls, lw=0.9, label=name)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

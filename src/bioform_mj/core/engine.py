"""What every closed loop does around the control step, compiled once for all plants.

After each control step the loop accumulates the run metrics (design §7), the
anti-aliased log accumulators, and checks the one table of divergence guards
(:data:`GUARDS`); every ``stride`` steps it writes a log row. The plants' chunk kernels
(``plants/ideal.py``, ``plants/mujoco/kernels.py``) and the Python step-by-step loop of
``run/simulate.py`` call the same functions below, so both engines compute the same bits.

Log rows (design §9): states (pose, estimates, ``ĉ`` …) are point samples at the row's
time ``t_j``; signals that change every control step (commands, their derivatives,
torques, saturation) are the **mean over the steps since the previous row**
(``(t_{j−1}, t_j]``), with the minimum and maximum of the commands and torques beside
them, so a chattering torque is not shown as whatever value it had at the sample instant.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from bioform_mj.core.equations import formation_offset, njit

#: Time-series channels of ``log.npz``: name → (trailing shape, meaning). ``n`` = followers.
CHANNELS: dict[str, tuple[tuple[str, ...], str]] = {
    "t": ((), "s, time of the row"),
    "leader_pose": (("3",), "[x, y, θ] of the virtual leader (m, m, rad)"),
    "leader_vel": (("2",), "[υ_r, ω_r] (m/s, rad/s)"),
    "pose": (("n", "3"), "[x, y, θ] measured (m, m, rad), sample"),
    "vel": (("n", "2"), "[υ, ω] measured (m/s, rad/s), sample"),
    "est_pose": (("n", "3"), "P_ir, each follower's estimate of the leader's pose, sample"),
    "est_vel": (("n", "2"), "[υ_ir, ω_ir], sample"),
    "cmd": (("n", "2"), "[υ_cmd, ω_cmd], mean over the row's interval"),
    "cmd_min": (("n", "2"), "[υ_cmd, ω_cmd], minimum over the interval"),
    "cmd_max": (("n", "2"), "[υ_cmd, ω_cmd], maximum over the interval"),
    "dcmd": (("n", "2"), "[υ̇_cmd, ω̇_cmd] as used by eqs. 38–39, mean over the interval"),
    "tau": (("n", "2"), "applied [τ_L, τ_R] N·m, mean over the interval"),
    "tau_min": (("n", "2"), "applied [τ_L, τ_R] N·m, minimum over the interval"),
    "tau_max": (("n", "2"), "applied [τ_L, τ_R] N·m, maximum over the interval"),
    "tau_raw": (("n", "2"), "commanded [τ_L, τ_R] before saturation, mean over the interval"),
    "c_hat": (("n", "2"), "[â, b̂], sample"),
    "c_true": (("n", "2"), "[a, b] of the plant, sample"),
    "z_hat": (("n", "2"), "learner's velocity estimate, sample"),
    "vs": (("n",), "neuron output V_s, sample"),
    "tracking_error": (("n", "3"), "[x̃, ỹ, θ̃] body frame, sample"),
    "slots": (("n", "2"), "formation slots p_r − Δ_i of the true leader (m), sample"),
    "formation_error": (("n",), "|p_i − (p_r − Δ_i)| m against the true leader, sample"),
    "estimation_error": (("n",), "|P_ir[:2] − p_r| m, sample"),
    "saturated": (("n",), "fraction of the interval's steps with a wheel at its limit"),
    "odom_pose": (("n", "3"), "[x, y, θ] its controller used: the odometry (sensing = odometry), else = pose, sample"),
    "odom_vel": (("n", "2"), "[υ, ω] its controller used: odometry mean over the control period, else = vel, sample"),
}

#: channels that are interval means (the others are point samples)
MEAN_CHANNELS = ("cmd", "dcmd", "tau", "tau_raw", "saturated")


class LogArrays(NamedTuple):
    """The preallocated log, one field per :data:`CHANNELS` entry, ``K`` rows."""

    t: np.ndarray
    leader_pose: np.ndarray
    leader_vel: np.ndarray
    pose: np.ndarray
    vel: np.ndarray
    est_pose: np.ndarray
    est_vel: np.ndarray
    cmd: np.ndarray
    cmd_min: np.ndarray
    cmd_max: np.ndarray
    dcmd: np.ndarray
    tau: np.ndarray
    tau_min: np.ndarray
    tau_max: np.ndarray
    tau_raw: np.ndarray
    c_hat: np.ndarray
    c_true: np.ndarray
    z_hat: np.ndarray
    vs: np.ndarray
    tracking_error: np.ndarray
    slots: np.ndarray
    formation_error: np.ndarray
    estimation_error: np.ndarray
    saturated: np.ndarray
    odom_pose: np.ndarray
    odom_vel: np.ndarray


def new_log(K: int, n: int) -> LogArrays:
    """A zeroed log of ``K`` rows for ``n`` followers."""
    dims = {"n": n, "3": 3, "2": 2}
    return LogArrays(*(np.zeros((K,) + tuple(dims[s] for s in CHANNELS[f][0])) for f in LogArrays._fields))


class Metrics(NamedTuple):
    """Per-follower run metrics (n,), accumulated every control step (design §7).

    ``verr``: Σ (|υ_cmd − υ| + |ω_cmd − ω|) (× dt = the Table I metric); ``sat``: steps with a
    wheel at its limit; ``vmax``: max |υ_cmd|; ``tau``: max applied |τ|; ``tau_raw``: max commanded |τ|.
    """

    verr: np.ndarray
    sat: np.ndarray
    vmax: np.ndarray
    tau: np.ndarray
    tau_raw: np.ndarray


class Acc(NamedTuple):
    """Accumulators of the interval means of the log (reset at every row); ``count`` (1,)."""

    cmd: np.ndarray
    cmd_min: np.ndarray
    cmd_max: np.ndarray
    dcmd: np.ndarray
    tau: np.ndarray
    tau_min: np.ndarray
    tau_max: np.ndarray
    tau_raw: np.ndarray
    sat: np.ndarray
    count: np.ndarray


class Formation(NamedTuple):
    """Formation offsets ``Δ`` (n, 2) m and their frame (``leader_frame``: rotate with the
    leader's heading; else world axes, the paper), for the formation error against the true leader."""

    offsets: np.ndarray
    leader_frame: bool


class Bounds(NamedTuple):
    """Divergence limits: |position| m, |speed| m/s, |torque| N·m (``scenario.limits``)."""

    position: float
    speed: float
    torque: float


def new_metrics(n: int) -> Metrics:
    return Metrics(*(np.zeros(n) for _ in Metrics._fields))


def new_acc(n: int) -> Acc:
    z = lambda: np.zeros((n, 2))  # noqa: E731
    a = Acc(z(), z(), z(), z(), z(), z(), z(), z(), np.zeros(n), np.zeros(1, dtype=np.int64))
    _acc_reset(a)
    return a


@njit
def _acc_reset(a):
    a.count[0] = 0
    for i in range(a.sat.shape[0]):
        a.sat[i] = 0.0
        for c in range(2):
            a.cmd[i, c] = 0.0
            a.dcmd[i, c] = 0.0
            a.tau[i, c] = 0.0
            a.tau_raw[i, c] = 0.0
            a.cmd_min[i, c] = math.inf
            a.cmd_max[i, c] = -math.inf
            a.tau_min[i, c] = math.inf
            a.tau_max[i, c] = -math.inf


@njit(inline=True)
def accumulate(cmd, dcmd, tau, tau_raw, saturated, vel, met, a):
    """After a control step: the run metrics ``met`` and the log accumulators ``a`` from the stack
    state's ``cmd``, ``dcmd``, ``tau``, ``tau_raw`` (n, 2), ``saturated`` (n,) (:class:`~bioform_mj.control.
    kernel.StackState`'s fields) and the measured velocities ``vel`` (n, 2). (The fields of ``met`` and ``a``
    are read once, at the top: see ``control/kernel.py`` on reference counts.)"""
    verr, msat, vmax, mtau, mtau_raw = met.verr, met.sat, met.vmax, met.tau, met.tau_raw
    a_cmd, a_cmd_min, a_cmd_max, a_dcmd, a_tau = a.cmd, a.cmd_min, a.cmd_max, a.dcmd, a.tau
    a_tau_min, a_tau_max, a_tau_raw, a_sat, a_count = a.tau_min, a.tau_max, a.tau_raw, a.sat, a.count
    for i in range(vel.shape[0]):
        verr[i] += abs(cmd[i, 0] - vel[i, 0]) + abs(cmd[i, 1] - vel[i, 1])
        if saturated[i]:
            msat[i] += 1.0
            a_sat[i] += 1.0
        vmax[i] = max(vmax[i], abs(cmd[i, 0]))
        mtau[i] = max(mtau[i], max(abs(tau[i, 0]), abs(tau[i, 1])))
        mtau_raw[i] = max(mtau_raw[i], max(abs(tau_raw[i, 0]), abs(tau_raw[i, 1])))
        for c in range(2):
            a_cmd[i, c] += cmd[i, c]
            a_dcmd[i, c] += dcmd[i, c]
            a_tau[i, c] += tau[i, c]
            a_tau_raw[i, c] += tau_raw[i, c]
            a_cmd_min[i, c] = min(a_cmd_min[i, c], cmd[i, c])
            a_cmd_max[i, c] = max(a_cmd_max[i, c], cmd[i, c])
            a_tau_min[i, c] = min(a_tau_min[i, c], tau[i, c])
            a_tau_max[i, c] = max(a_tau_max[i, c], tau[i, c])
    a_count[0] += 1


@njit
def record(lg, j, t, lp, lv, pose, vel, s, c_true, form, a):
    """Write log row ``j`` at time ``t`` (s): samples of the leader ``lp, lv``, the measurements
    and the stack state ``s``; the slots of :class:`Formation` ``form``; interval means from
    ``a`` (then reset)."""
    lg.t[j] = t
    for c in range(3):
        lg.leader_pose[j, c] = lp[c]
    for c in range(2):
        lg.leader_vel[j, c] = lv[c]
    cnt = max(a.count[0], 1)
    for i in range(pose.shape[0]):
        for c in range(3):
            lg.pose[j, i, c] = pose[i, c]
            lg.est_pose[j, i, c] = s.est_pose[i, c]
            lg.tracking_error[j, i, c] = s.err[i, c]
        for c in range(2):
            lg.vel[j, i, c] = vel[i, c]
            lg.est_vel[j, i, c] = s.est_vel[i, c]
            lg.cmd[j, i, c] = a.cmd[i, c] / cnt
            lg.cmd_min[j, i, c] = a.cmd_min[i, c]
            lg.cmd_max[j, i, c] = a.cmd_max[i, c]
            lg.dcmd[j, i, c] = a.dcmd[i, c] / cnt
            lg.tau[j, i, c] = a.tau[i, c] / cnt
            lg.tau_min[j, i, c] = a.tau_min[i, c]
            lg.tau_max[j, i, c] = a.tau_max[i, c]
            lg.tau_raw[j, i, c] = a.tau_raw[i, c] / cnt
            lg.c_hat[j, i, c] = s.c_hat[i, c]
            lg.c_true[j, i, c] = c_true[i, c]
            lg.z_hat[j, i, c] = s.z_hat[i, c]
        lg.vs[j, i] = s.vs[i]
        ox, oy = formation_offset(form.offsets[i, 0], form.offsets[i, 1], lp[2], form.leader_frame)
        lg.slots[j, i, 0] = lp[0] - ox
        lg.slots[j, i, 1] = lp[1] - oy
        lg.formation_error[j, i] = math.hypot(pose[i, 0] - lg.slots[j, i, 0], pose[i, 1] - lg.slots[j, i, 1])
        lg.estimation_error[j, i] = math.hypot(s.est_pose[i, 0] - lp[0], s.est_pose[i, 1] - lp[1])
        lg.saturated[j, i] = a.sat[i] / cnt
    _acc_reset(a)


@njit
def record_odometry(lg, j, mpose, mvel):
    """Log row ``j``'s odometry channels: the pose and velocity the controllers were given (design §8.3)."""
    for i in range(mpose.shape[0]):
        for c in range(3):
            lg.odom_pose[j, i, c] = mpose[i, c]
        for c in range(2):
            lg.odom_vel[j, i, c] = mvel[i, c]


#: The divergence guards, in the order they are checked (code = index + 1):
#: (signal, what, limit: None = finite only, else the :class:`Bounds` field).
GUARDS: tuple[tuple[str, str, str | None], ...] = (
    ("pose", "pose", None),
    ("vel", "velocity", None),
    ("est_pose", "leader-pose estimate", None),
    ("est_vel", "leader-velocity estimate", None),
    ("cmd", "velocity command", None),
    ("tau_raw", "commanded wheel torque", None),
    ("c_hat", "learned [â, b̂]", None),
    ("vs", "neuron output V_s", None),
    ("pose", "position", "position"),
    ("est_pose", "leader-position estimate", "position"),
    ("vel", "speed υ", "speed"),
    ("cmd", "commanded speed υ_cmd", "speed"),
    ("est_vel", "leader-speed estimate υ_ir", "speed"),
    ("tau_raw", "commanded wheel torque", "torque"),
)


@njit(inline=True)
def _finite(a, b, c=0.0):
    """True if ``a``, ``b`` (and ``c``) are finite: a row of 2 (or 3) numbers (scalars: an inlined function
    taking an array copies it with a reference count, see :func:`guards`)."""
    return math.isfinite(a) and math.isfinite(b) and math.isfinite(c)


@njit(inline=True)
def check(s, pose, vel, lim, diag):
    """Check the state after a control step against :data:`GUARDS`; True if all pass.

    On failure ``diag`` (3,) receives ``(guard code, follower index, offending value)``.
    """
    return guards(pose, vel, s.est_pose, s.est_vel, s.cmd, s.tau_raw, s.c_hat, s.vs, lim, diag)


@njit(inline=True)
def guards(pose, vel, est_pose, est_vel, cmd, tau_raw, c_hat, vs, lim, diag):
    """:func:`check` on the stack state's arrays (:class:`~bioform_mj.control.kernel.StackState`'s field names).

    One return, and the second pass's loop runs zero times after a failure of the first: no array is
    released on two paths (see ``control/kernel.py`` on reference counts)."""
    n = pose.shape[0]
    bad = 0
    who = 0
    val = math.nan
    for i in range(n):  # rows of 3 (poses) and 2 numbers
        if not _finite(pose[i, 0], pose[i, 1], pose[i, 2]):
            bad = 1
        elif not _finite(vel[i, 0], vel[i, 1]):
            bad = 2
        elif not _finite(est_pose[i, 0], est_pose[i, 1], est_pose[i, 2]):
            bad = 3
        elif not _finite(est_vel[i, 0], est_vel[i, 1]):
            bad = 4
        elif not _finite(cmd[i, 0], cmd[i, 1]):
            bad = 5
        elif not _finite(tau_raw[i, 0], tau_raw[i, 1]):
            bad = 6
        elif not _finite(c_hat[i, 0], c_hat[i, 1]):
            bad = 7
        elif not math.isfinite(vs[i]):
            bad = 8
        if bad:
            who = i
            break
    for i in range(n if bad == 0 else 0):
        pmag = max(abs(pose[i, 0]), abs(pose[i, 1]))
        emag = max(abs(est_pose[i, 0]), abs(est_pose[i, 1]))
        tmag = max(abs(tau_raw[i, 0]), abs(tau_raw[i, 1]))
        if pmag > lim.position:
            bad, val = 9, pmag
        elif emag > lim.position:
            bad, val = 10, emag
        elif abs(vel[i, 0]) > lim.speed:
            bad, val = 11, abs(vel[i, 0])
        elif abs(cmd[i, 0]) > lim.speed:
            bad, val = 12, abs(cmd[i, 0])
        elif abs(est_vel[i, 0]) > lim.speed:
            bad, val = 13, abs(est_vel[i, 0])
        elif tmag > lim.torque:
            bad, val = 14, tmag
        if bad:
            who = i
            break
    if bad:
        diag[0] = bad
        diag[1] = who
        diag[2] = val
    return bad == 0


def describe(diag: np.ndarray, t: float, lim: Bounds) -> str:
    """The diagnosis of a failed :func:`check` at time ``t`` (s), from its ``diag``."""
    code, i, val = int(diag[0]), int(diag[1]), float(diag[2])
    signal, what, limit = GUARDS[code - 1]
    if limit is None:
        return f"follower {i + 1}: {what} '{signal}' is not finite at t = {t:.4f} s"
    return (
        f"follower {i + 1}: {what} |{signal}| = {val:.3g} exceeds limits.{limit} = "
        f"{getattr(lim, limit):g} at t = {t:.4f} s"
    )


#: status codes of the chunk kernels
OK, GUARD_FAILED, PLANT_FAILED = 0, 1, 2


@njit
def after_control(k, N, stride, s, pose, vel, met, acc, lg, j, L_pose, L_vel, dt, c_true, form, lim, diag):
    """After the control step of step ``k``: metrics, the guards, and the log row if due
    (``form``: the :class:`Formation`, for the slots and the formation error).

    Returns ``(next log row, status)``; on a failed guard the row is not written (the log
    ends at the last good row) and ``diag`` holds the diagnosis.
    """
    status = after_step(
        k, N, stride, pose, vel, s.est_pose, s.est_vel, s.cmd, s.dcmd, s.tau, s.tau_raw, s.saturated, s.c_hat, s.vs,
        met, acc, lim, diag,
    )  # fmt: skip
    if status == ROW:
        record(lg, j, k * dt, L_pose[k], L_vel[k], pose, vel, s, c_true, form, acc)
        return j + 1, OK
    return j, status


#: :func:`after_step`'s status when the guards passed and a log row is due
ROW = 3


@njit
def after_step(k, N, stride, pose, vel, est_pose, est_vel, cmd, dcmd, tau, tau_raw, saturated, c_hat, vs, met, acc,
               lim, diag):  # fmt: skip
    """:func:`after_control` without its log row, on the stack state's arrays (the compiled chunks, which write
    the row themselves with :func:`record` when this returns :data:`ROW`): :func:`accumulate`, then
    :func:`guards`. Returns :data:`OK`, :data:`ROW` or :data:`GUARD_FAILED` (``diag`` says which)."""
    accumulate(cmd, dcmd, tau, tau_raw, saturated, vel, met, acc)
    status = OK  # one return (see guards)
    if not guards(pose, vel, est_pose, est_vel, cmd, tau_raw, c_hat, vs, lim, diag):
        status = GUARD_FAILED
    elif k % stride == 0 and k < N:
        status = ROW
    return status


class Loop(NamedTuple):
    """What a plant's compiled chunk shares with the loop driver (``sim``); arrays updated in place.

    ``gains``, ``state``, ``comm``: the controller's kernel arguments (``control/kernel.py``);
    ``N`` control steps of ``dt`` s; ``L_pose`` (N+1, 3), ``L_vel`` (N+1, 2) the leader at every
    step; ``pose`` (n, 3), ``vel`` (n, 2) the true measurements the plant writes; ``met``, ``acc``,
    ``log`` (:class:`Metrics`, :class:`Acc`, :class:`LogArrays`), a row every ``stride`` steps;
    ``form`` (:class:`Formation`), ``bounds`` (:class:`Bounds`), ``diag`` (3,) a failed guard."""

    gains: object
    state: object
    comm: object
    N: int
    dt: float
    L_pose: np.ndarray
    L_vel: np.ndarray
    pose: np.ndarray
    vel: np.ndarray
    met: Metrics
    acc: Acc
    log: LogArrays
    stride: int
    form: Formation
    bounds: Bounds
    diag: np.ndarray

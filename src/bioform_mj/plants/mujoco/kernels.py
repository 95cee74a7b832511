"""Compiled kernels of the MuJoCo plant: observe, apply inputs, and the closed loop in chunks.

``MujocoPlant.observe``/``step`` call :func:`observe` and :func:`apply_inputs` from
Python; :func:`run_chunk` runs many control periods without returning to Python, calling
``mj_step`` of ``libmujoco`` by symbol (numba ExternalFunction, so the kernels are cached
on disk) on the very ``MjModel``/``MjData`` the Python bindings own. Both paths run the
same functions, so the step-by-step and the compiled loop compute the same bits.
"""

from __future__ import annotations

import ctypes
from typing import NamedTuple

import numpy as np

from bioform_mj.control.kernel import knobs, safety_filter, stack_head, stack_tail
from bioform_mj.core.engine import OK, PLANT_FAILED, ROW, after_step, record, record_odometry
from bioform_mj.core.equations import (
    HAVE_NUMBA,
    encoder_angle,
    gyro_reading,
    harmonic,
    njit,
    odometry_step,
    planar_state,
    slip_ratio,
)
from bioform_mj.plants.mujoco.contacts import _libmujoco_path, watch_contacts, watch_proximity

if HAVE_NUMBA:
    import numba


# ``mj_step(const mjModel*, mjData*)`` called by symbol name; pointers passed as integers (the
# same calling convention on the 64-bit platforms MuJoCo supports). The Python bindings load
# the same file, so both act on the same MjModel/MjData.
HAVE_MJ_STEP = False
if HAVE_NUMBA:
    _mj_step = numba.types.ExternalFunction("mj_step", numba.types.void(numba.types.intp, numba.types.intp))
    try:
        import llvmlite.binding as _llvm

        _lib = _libmujoco_path()
        if _lib is not None and ctypes.sizeof(ctypes.c_void_p) == 8:
            _llvm.load_library_permanently(_lib)
            HAVE_MJ_STEP = True
    except (OSError, RuntimeError, ImportError):  # pragma: no cover - the step-by-step loop still works
        HAVE_MJ_STEP = False
    # ``mj_getState``/``mj_setState(const mjModel*, mjData*, mjtNum* state, int sig)`` and
    # ``mj_copyData(mjData* dest, const mjModel*, const mjData* src)``, by symbol as ``mj_step``
    _mj_get_state = numba.types.ExternalFunction(
        "mj_getState", numba.types.void(numba.types.intp, numba.types.intp, numba.types.intp, numba.types.int32)
    )
    _mj_set_state = numba.types.ExternalFunction(
        "mj_setState", numba.types.void(numba.types.intp, numba.types.intp, numba.types.intp, numba.types.int32)
    )
    _mj_copy_data = numba.types.ExternalFunction(
        "mj_copyData", numba.types.intp(numba.types.intp, numba.types.intp, numba.types.intp)
    )


class Sensors(NamedTuple):
    """The odometry sensors of ``n`` robots (design §8.3); read by :func:`sense`.

    ``on``: sensing = "odometry" (False: nothing is sampled, the loops skip all of it);
    ``enc`` (n, 2): ``sensordata`` addresses of the [left, right] wheel ``jointpos`` sensors;
    ``gyro`` (n,): address of each gyro (3 values, site frame; z is used); ``sign`` (n, 2): ±1,
    forward wheel direction; ``radius`` (n,) m; ``cpr`` (n,) encoder counts per revolution;
    ``bias`` rad/s, ``sigma`` rad/s (gyro noise per sample), ``seed``; ``every``: physics steps per
    sensor sample; ``ts`` s: the sensor period."""

    on: bool
    enc: np.ndarray
    gyro: np.ndarray
    sign: np.ndarray
    radius: np.ndarray
    cpr: np.ndarray
    bias: float
    sigma: float
    seed: float
    every: int
    ts: float


class Odometry(NamedTuple):
    """Each follower's dead reckoning (design §8.3), updated in place.

    ``pose`` (n, 3) the odometry's ``[x, y, θ]``; ``q`` (n, 2) the last quantised forward wheel
    angles (rad); ``dist`` (n,) m and ``turn`` (n,) rad since the last control step; ``count`` (1,)
    physics steps since reset; ``mpose`` (n, 3), ``mvel`` (n, 2): what the controller is given at
    the control step (pose, and ``[Δs, Δθ]`` over the control period divided by it)."""

    pose: np.ndarray
    q: np.ndarray
    dist: np.ndarray
    turn: np.ndarray
    count: np.ndarray
    mpose: np.ndarray
    mvel: np.ndarray


def new_odometry(n: int) -> Odometry:
    return Odometry(
        np.zeros((n, 3)),
        np.zeros((n, 2)),
        np.zeros(n),
        np.zeros(n),
        np.zeros(1, dtype=np.int64),
        np.zeros((n, 3)),
        np.zeros((n, 2)),
    )


@njit
def odometry_reset(sd, sen, odo, pose):
    """Odometry at the true initial ``pose`` (n, 3), wheel angles from the current ``sensordata``."""
    odo.count[0] = 0
    for i in range(pose.shape[0]):
        for c in range(3):
            odo.pose[i, c] = pose[i, c]
            odo.mpose[i, c] = pose[i, c]
        for w in range(2):
            odo.q[i, w] = encoder_angle(sen.sign[i, w] * sd[sen.enc[i, w]], sen.cpr[i])
            odo.mvel[i, w] = 0.0
        odo.dist[i] = 0.0
        odo.turn[i] = 0.0


@njit
def sense(sd, sen, odo):
    """After one physics step: count it, and every ``sen.every`` steps sample the encoders and the
    gyro and advance each robot's dead reckoning (:func:`~..equations.odometry_step`)."""
    odo.count[0] += 1
    c = odo.count[0]
    if c % sen.every != 0:
        return
    k = float(c // sen.every)
    for i in range(odo.pose.shape[0]):
        ql = encoder_angle(sen.sign[i, 0] * sd[sen.enc[i, 0]], sen.cpr[i])
        qr = encoder_angle(sen.sign[i, 1] * sd[sen.enc[i, 1]], sen.cpr[i])
        wz = gyro_reading(sd[sen.gyro[i] + 2], sen.bias, sen.sigma, sen.seed, float(i), k)
        x, y, th, ds, dth = odometry_step(
            odo.pose[i, 0], odo.pose[i, 1], odo.pose[i, 2], odo.q[i, 0], odo.q[i, 1], ql, qr, wz, sen.radius[i], sen.ts
        )
        odo.pose[i, 0], odo.pose[i, 1], odo.pose[i, 2] = x, y, th
        odo.q[i, 0], odo.q[i, 1] = ql, qr
        odo.dist[i] += ds
        odo.turn[i] += dth


@njit
def odometry_read(odo, dt):
    """At a control step: the controller's measurement ``mpose`` = the odometry's pose, ``mvel`` =
    ``[Δs, Δθ]`` since the last control step over ``dt`` (the period's mean ``υ, ω``)."""
    for i in range(odo.pose.shape[0]):
        for c in range(3):
            odo.mpose[i, c] = odo.pose[i, c]
        odo.mvel[i, 0] = odo.dist[i] / dt
        odo.mvel[i, 1] = odo.turn[i] / dt
        odo.dist[i] = 0.0
        odo.turn[i] = 0.0


@njit
def observe(qpos, qvel, q7, v6, axle, pose, vel, up):
    """Pose ``[x, y, θ]`` and body-frame ``[υ, ω]`` of each robot's axle midpoint, and the
    cosine of its tilt ``up`` (n,), from the free joints (:func:`~..equations.planar_state`).
    ``q7`` (n,) / ``v6`` (n,): first qpos / qvel address of each base's free joint;
    ``axle`` (n, 3): the axle midpoint in the base body's frame (m)."""
    for i in range(pose.shape[0]):
        a = q7[i]
        b = v6[i]
        x, y, th, v, w, u = planar_state(
            qpos[a],
            qpos[a + 1],
            qpos[a + 3],
            qpos[a + 4],
            qpos[a + 5],
            qpos[a + 6],
            qvel[b],
            qvel[b + 1],
            qvel[b + 2],
            qvel[b + 3],
            qvel[b + 4],
            qvel[b + 5],
            axle[i, 0],
            axle[i, 1],
            axle[i, 2],
        )
        pose[i, 0], pose[i, 1], pose[i, 2] = x, y, th
        vel[i, 0], vel[i, 1] = v, w
        up[i] = u


@njit
def apply_inputs(tau, t, ctrl, ctrl_id, ctrl_scale, xfrc, xmat, base, m_eff, i_eff, dist, use_dist):
    """Wheel torques ``tau`` (n, 2) to the motors: ``ctrl[ctrl_id] = ctrl_scale · tau`` (1 for a
    torque motor; a DC motor's driver input per N·m, design §8.2); with ``use_dist`` the
    disturbance accelerations of eq. 34 at ``t`` (s) as chassis ``xfrc_applied``: a force
    ``M_eff d1`` along the heading (from ``xmat`` of the last forward pass, held over the
    period like ``d``) and a yaw torque ``I_eff d2`` (design §8)."""
    for i in range(tau.shape[0]):
        ctrl[ctrl_id[i, 0]] = ctrl_scale[i, 0] * tau[i, 0]
        ctrl[ctrl_id[i, 1]] = ctrl_scale[i, 1] * tau[i, 1]
    if use_dist:
        d0 = harmonic(dist[0, 0], dist[0, 1], dist[0, 2], dist[0, 3], t)
        d1 = harmonic(dist[1, 0], dist[1, 1], dist[1, 2], dist[1, 3], t)
        for i in range(tau.shape[0]):
            b = base[i]
            xfrc[b, 0] = xmat[b, 0] * (m_eff[i] * d0)
            xfrc[b, 1] = xmat[b, 3] * (m_eff[i] * d0)
            xfrc[b, 5] = i_eff[i] * d1


@njit
def delivered_add(force, ctrl_id, to_wheel, acc):
    """After one physics step: add each wheel motor's torque on its wheel, ``to_wheel · force[ctrl_id]``
    (``force`` = ``MjData.actuator_force`` of the step, ``to_wheel`` (n, 2) = gear × wheel sign: the
    forward wheel torque, N·m, per unit of actuator force; 0 where not fed), to ``acc`` (n, 2)."""
    for i in range(acc.shape[0]):
        acc[i, 0] += to_wheel[i, 0] * force[ctrl_id[i, 0]]
        acc[i, 1] += to_wheel[i, 1] * force[ctrl_id[i, 1]]


@njit
def delivered_feed(acc, n_sub, feed, tau_body):
    """At the end of a control period: the wheel torque delivered over it, the mean of ``acc``
    (:func:`delivered_add`, ``n_sub`` physics steps) ``[τ_L, τ_R]``, written as ``[τ_a, τ_b] =
    [τ_L + τ_R, τ_R − τ_L]`` into ``tau_body`` (n, 2) (the learner's input, design §8.2) for the
    robots with ``feed`` (n,) set; ``acc`` is cleared."""
    for i in range(acc.shape[0]):
        if feed[i]:
            tl = acc[i, 0] / n_sub
            tr = acc[i, 1] / n_sub
            tau_body[i, 0] = tl + tr  # τ_a = τ_L + τ_R
            tau_body[i, 1] = tr - tl  # τ_b = τ_R − τ_L (design §5)
        acc[i, 0] = 0.0
        acc[i, 1] = 0.0


@njit
def _warned(warn):
    for w in range(warn.shape[0]):
        if warn[w] != 0:
            return True
    return False


@njit
def watch_tilt(up, tilt_cos, tip_step, k):
    """Record in ``tip_step`` (n,) the first step ``k`` at which a chassis' tilt cosine ``up``
    fell below ``tilt_cos`` (entries still −1 have not tipped)."""
    for i in range(up.shape[0]):
        if tip_step[i] < 0 and up[i] < tilt_cos:
            tip_step[i] = k


@njit
def watch_slip(qvel, wheel_dof, wheel_sign, radius, half_track, vel, ratio, v_floor, need, slip_run, slip_step, k):
    """Wheel slip of each robot after step ``k``: :func:`~..equations.slip_ratio` per wheel
    (``φ̇ = sign · qvel`` the forward wheel rate, ``v_c = υ ∓ l ω`` its contact point's forward
    speed if it rolled). ``slip_run`` (n,) counts consecutive steps with a wheel beyond
    ``ratio``; ``slip_step`` (n,) records the step at which a run first reached ``need`` steps.
    The batch engine (``batch/step.py``, ``batch/runner.py``) runs the same watch per world."""
    for i in range(vel.shape[0]):
        worst = 0.0
        for w in range(2):
            sl = slip_ratio(
                qvel[wheel_dof[i, w]] * wheel_sign[i, w],
                radius[i],
                vel[i, 0],
                vel[i, 1],
                (2 * w - 1) * half_track[i],
                v_floor,
            )
            worst = max(worst, sl)
        if worst > ratio:
            slip_run[i] += 1
            if slip_run[i] >= need and slip_step[i] < 0:
                slip_step[i] = k
        else:
            slip_run[i] = 0


class MjIO(NamedTuple):
    """The MuJoCo arrays a chunk reads and writes (views of ``MjData`` and the plant's index
    arrays): free-joint addresses ``q7``, ``v6`` (n,), ``axle`` (n, 3), tilt cosines ``up`` (n,);
    motors ``ctrl_id`` (n, 2), ``ctrl_scale`` (n, 2); chassis ``base`` (n,), ``m_eff``, ``i_eff``
    (n,); the disturbance rows ``dist`` (2, 4) and ``use_dist``; the warning counters ``warn``;
    the delivered-torque feed of DC motors (``act_force``, ``to_wheel``, ``feed``, ``feed_on``,
    ``dacc``; design §8.2)."""

    qpos: np.ndarray
    qvel: np.ndarray
    q7: np.ndarray
    v6: np.ndarray
    axle: np.ndarray
    up: np.ndarray
    ctrl: np.ndarray
    ctrl_id: np.ndarray
    ctrl_scale: np.ndarray
    xfrc: np.ndarray
    xmat: np.ndarray
    base: np.ndarray
    m_eff: np.ndarray
    i_eff: np.ndarray
    dist: np.ndarray
    use_dist: bool
    warn: np.ndarray
    act_force: np.ndarray
    to_wheel: np.ndarray
    feed: np.ndarray
    feed_on: bool
    dacc: np.ndarray


class Watch(NamedTuple):
    """The outcome watches (tilt, wheel slip) of :func:`watch_tilt` and :func:`watch_slip`."""

    tilt_cos: float
    tip_step: np.ndarray
    wheel_dof: np.ndarray
    wheel_sign: np.ndarray
    radius: np.ndarray
    half_track: np.ndarray
    slip_ratio: float
    v_floor: float
    slip_need: int
    slip_run: np.ndarray
    slip_step: np.ndarray


@njit
def run_chunk(lp, k0, k1, n_sub, mp, dp, io, w, c_true, j0, rec_ctrl, rec_xfrc, sd, sen, odo, cl, px, rows):
    """Plant steps ``k0 … k1−1`` on MuJoCo (``n_sub`` physics steps each), each followed by the
    control step of ``k+1`` (``lp``: :class:`~bioform_mj.core.engine.Loop`; the control step of ``k0``
    must be done). ``io``: :class:`MjIO`; ``w``: :class:`Watch`; ``c_true`` (n, 2).

    Stops at the first physics step that raised a MuJoCo warning (``io.warn``): status
    ``engine.PLANT_FAILED``, with the state before MuJoCo's reset not observed. With
    ``io.feed_on`` (DC motors, design §8.2) the wheel torque each motor delivered is averaged over
    the period (:func:`delivered_add`) and written into ``tau_body`` of the robots with ``io.feed``
    before the next control step (:func:`delivered_feed`), so the learner sees it. With ``sen.on``
    the sensors are sampled after each physics step (:func:`sense`) and the controller is given the
    odometry (:func:`odometry_read`) instead of the truth; metrics, guards, the formation error and
    the outcome watches stay on the truth. ``cl``, ``px``: the contact and proximity watches
    (:mod:`.mujoco_contacts`, design §19): MuJoCo's contact list after every physics step, distances
    every ``px.ranges[3]`` control steps. If ``rec_ctrl`` has rows, the inputs of step ``k`` are
    copied to ``rec_ctrl[k]``, ``rec_xfrc[k]`` (for a bare-physics replay). If ``rows`` has rows, the
    raw state of each log row ``j`` written here (``qpos``, ``qvel``, ``sensordata``, as far as its
    width goes) is copied to ``rows[j]`` (``outputs/fullstate.py``: a bag's 3-D state). Returns
    ``(steps done, next log row, status)``.
    """
    # unpacked once, outside the step loop (see plants/ideal.py: reading a named tuple's field, or copying it,
    # takes a reference count on its arrays)
    g, s, comm, N, dt, L_pose, L_vel, pose, vel, met, acc, lg, stride, form, lim, diag = lp
    kn = knobs(g)
    est_pose, est_vel, c_hat, vs, cmd, dcmd = s.est_pose, s.est_vel, s.c_hat, s.vs, s.cmd, s.dcmd
    tau, tau_raw, saturated, tau_body = s.tau, s.tau_raw, s.saturated, s.tau_body
    cbf_par, cbf_rad, cbf_obst, cbf_A, cbf_b, cbf_lam, cbf_bad = (
        g.cbf_par, g.cbf_rad, g.cbf_obst, g.cbf_A, g.cbf_b, g.cbf_lam, g.cbf_bad,
    )  # fmt: skip
    # what the controllers are given: the truth, or the odometry (sen.on, refreshed in place each step)
    mpose, mvel = (odo.mpose, odo.mvel) if sen.on else (pose, vel)
    (
        qpos,
        qvel,
        q7,
        v6,
        axle,
        up,
        ctrl,
        ctrl_id,
        ctrl_scale,
        xfrc,
        xmat,
        base,
        m_eff,
        i_eff,
        dist,
        use_dist,
        warn,
        act_force,
        to_wheel,
        feed,
        feed_on,
        dacc,
    ) = io
    (
        tilt_cos,
        tip_step,
        wheel_dof,
        wheel_sign,
        radius,
        half_track,
        slip_ratio,
        v_floor,
        slip_need,
        slip_run,
        slip_step,
    ) = w
    ncon, con, meta, owner, ci, cf, f6, hdt = cl
    gstart, glist, ogeom, obst, rad, ranges, rf, ri, box, order = px
    px_every = int(ranges[3])
    j = j0
    for k in range(k0, k1):
        apply_inputs(tau, k * dt, ctrl, ctrl_id, ctrl_scale, xfrc, xmat, base, m_eff, i_eff, dist, use_dist)
        if rec_ctrl.shape[0] > k:
            record_inputs(rec_ctrl, rec_xfrc, k, ctrl, xfrc, base)
        for sub in range(n_sub):
            _mj_step(mp, dp)
            if _warned(warn):
                return k - k0, j, PLANT_FAILED
            if sen.on:
                sense(sd, sen, odo)
            if feed_on:
                delivered_add(act_force, ctrl_id, to_wheel, dacc)
            watch_contacts(mp, dp, ncon, con, meta, owner, ci, cf, f6, hdt, (k * n_sub + sub + 1) * hdt)
        if feed_on:
            delivered_feed(dacc, n_sub, feed, tau_body)
        observe(qpos, qvel, q7, v6, axle, pose, vel, up)
        if (k + 1) % px_every == 0:
            watch_proximity(mp, dp, gstart, glist, ogeom, obst, rad, ranges, rf, ri, box, order, pose, (k + 1) * dt)
        watch_tilt(up, tilt_cos, tip_step, k + 1)
        watch_slip(
            qvel,
            wheel_dof,
            wheel_sign,
            radius,
            half_track,
            vel,
            slip_ratio,
            v_floor,
            slip_need,
            slip_run,
            slip_step,
            k + 1,
        )
        if k + 1 < N:
            if sen.on:
                odometry_read(odo, dt)
            k_ = k + 1
            # kernel.stack_step's three lines on what the controllers measure (a copy: see plants/ideal.py)
            stack_head(kn, g, s, comm, L_pose[k_, 0], L_pose[k_, 1], L_pose[k_, 2], L_vel[k_, 0], L_vel[k_, 1], mpose,
                       mvel)  # fmt: skip
            if kn.cbf:
                safety_filter(mpose, cmd, cbf_par, cbf_rad, cbf_obst, cbf_A, cbf_b, cbf_lam, cbf_bad)
            stack_tail(kn, g, s, mpose, mvel)
            status = after_step(k_, N, stride, pose, vel, est_pose, est_vel, cmd, dcmd, tau, tau_raw, saturated, c_hat,
                                vs, met, acc, lim, diag)  # fmt: skip
            if status == ROW:
                record(lg, j, k_ * dt, L_pose[k_], L_vel[k_], pose, vel, s, c_true, form, acc)
                if sen.on:
                    record_odometry(lg, j, mpose, mvel)
                if rows.shape[0] > j:
                    copy_row(rows, j, qpos, qvel, sd)
                j += 1
            elif status != OK:
                return k_ - k0, j, status
    return k1 - k0, j, OK


@njit
def record_inputs(rec_ctrl, rec_xfrc, k, ctrl, xfrc, base):
    """``rec_ctrl[k]`` = ``ctrl``, ``rec_xfrc[k, i]`` = ``xfrc[base[i]]`` (for a bare-physics replay). Element by
    element: a slice assignment (``rec_ctrl[k, :] = ctrl``) compiles numba's shape-mismatch message formatting
    (string kernels, ~6 s of a first run's compile; issue 28) for a copy of fixed shapes."""
    for c in range(ctrl.shape[0]):
        rec_ctrl[k, c] = ctrl[c]
    for i in range(base.shape[0]):
        for c in range(xfrc.shape[1]):
            rec_xfrc[k, i, c] = xfrc[base[i], c]


@njit
def copy_row(rows, j, qpos, qvel, sd):
    """``rows[j]`` = ``qpos``, ``qvel``, then ``sensordata`` up to the row's width."""
    nq, nv = qpos.shape[0], qvel.shape[0]
    for c in range(nq):
        rows[j, c] = qpos[c]
    for c in range(nv):
        rows[j, nq + c] = qvel[c]
    for c in range(rows.shape[1] - nq - nv):
        rows[j, nq + nv + c] = sd[c]


@njit
def physics_steps(mp, dp, n_sub, k0, ncon, con, meta, owner, ci, cf, f6, hdt):
    """``n_sub`` ``mj_step`` calls, each followed by the contact watch (:func:`watch_contacts`; the
    physics steps before these: ``k0``): the step-by-step plant's period when it has no sensors and
    no DC-motor feed, as the compiled chunk runs it (one numba call, not one per physics step)."""
    for sub in range(n_sub):
        _mj_step(mp, dp)
        watch_contacts(mp, dp, ncon, con, meta, owner, ci, cf, f6, hdt, (k0 + sub + 1) * hdt)


@njit
def replay(mp, dp, n_sub, ctrl, xfrc, base, rec_ctrl, rec_xfrc, solver_niter):
    """Bare physics for the benchmark: ``n_sub`` ``mj_step`` per recorded row of ``ctrl`` and
    chassis ``xfrc_applied`` inputs. Returns the total of the solver's iterations."""
    iters = 0
    for k in range(rec_ctrl.shape[0]):
        ctrl[:] = rec_ctrl[k]
        for i in range(base.shape[0]):
            xfrc[base[i], :] = rec_xfrc[k, i]
        for _ in range(n_sub):
            _mj_step(mp, dp)
            iters += solver_niter[0]
    return iters


@njit
def state_in(mp, dp, x, sig):
    """``mj_setState(m, d, x, sig)``: the state ``x`` (the layout of ``mj_getState`` with ``sig``) into ``d``."""
    _mj_set_state(mp, dp, x.ctypes.data, numba.int32(sig))


@njit
def state_out(mp, dp, x, sig):
    """``mj_getState(m, d, x, sig)``: ``d``'s state (the components ``sig``) into ``x``."""
    _mj_get_state(mp, dp, x.ctypes.data, numba.int32(sig))


@njit
def copy_data(dst, mp, src):
    """``mj_copyData(dst, m, src)``: all of ``src`` (state, the last step's results, warnings) into ``dst``."""
    _mj_copy_data(dst, mp, src)

"""The control stack as one compiled kernel (numba), and whole-loop kernels for both plants.

Why: the numpy stack (:class:`~bioform_mj.control.stack.ControlStack`) costs about a
hundred numpy calls per control step, ~0.4 ms whatever ``n``; MuJoCo steps the paper's
three robots in ~0.03 ms. This module computes exactly the same equations, in the same
order (see ``stack.py``), as scalar loops compiled by numba:

* :class:`FusedControlStack` is a drop-in :class:`ControlStack` whose ``step`` is one
  kernel call (used when a run needs a Python hook every step, e.g. injected faults);
* :func:`run_ideal_chunk` and :func:`run_mujoco_chunk` run many control steps of the
  closed loop without returning to Python: the MuJoCo one calls ``mj_step`` of
  ``libmujoco`` by symbol (numba ExternalFunction) on the very ``MjModel``/``MjData`` the Python bindings
  own, so the state stays shared and bit-identical to stepping from Python.

Results agree with the numpy stack to rounding (the transcendental functions of numba
and numpy may differ in the last bit); a run is still bit-for-bit reproducible.
The algorithms still know nothing of the plant: the chunk kernels only move
observations in and torques out around :func:`control_step`.
"""
from __future__ import annotations

import ctypes
import math
import os

import numpy as np

try:  # numba is a dependency; the numpy stack stays the reference and the fallback
    import numba

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover - exercised only without numba
    numba = None
    HAVE_NUMBA = False

from ..graph import Graph
from .estimator import Comm
from .stack import ControlStack, StackParams

# ---- layout of the scalar parameter vector ``g`` -----------------------------------
G_K1, G_K2, G_K3, G_A, G_B, G_D, G_DT, G_TPHI = range(8)
G_EPHI = 8  # 2
G_KP = 10  # 3
G_KA = 13  # 2
G_KB = 15  # 2
G_CG = 17  # 2
G_K5 = 19  # 2 (k4 may differ per follower: it is in the state tuple)
G_KD = 21  # 2
G_FPHI = 23  # 4: filter transition matrix, row-major
G_FGAM = 27  # 2
G_BIO, G_LEARN, G_STEER = 29, 30, 31
G_SIZE = 32

# ---- columns of the per-follower metric accumulator ``met`` (n, 5) -----------------
M_VERR, M_SAT, M_VMAX, M_TAU, M_TAURAW = range(5)


def _njit(fn):
    """Compile ``fn`` (cached on disk; IEEE semantics, no fastmath); plain Python without numba."""
    return numba.njit(cache=True, nogil=True, error_model="numpy")(fn) if HAVE_NUMBA else fn


@_njit
def _wrap(a):
    """Angle to (−π, π], exactly as ``common.wrap``."""
    return math.pi - (math.pi - a) % (2.0 * math.pi)


@_njit
def _sat(x, phi):
    if phi == 0.0:
        if x > 0.0:
            return 1.0
        if x < 0.0:
            return -1.0
        return 0.0
    y = x / phi
    return min(max(y, -1.0), 1.0)


@_njit
def _clip(x, lo, hi):
    return min(max(x, lo), hi)


@_njit
def control_step(st, lp, lv, pose, vel, use_comm, ew, lw, rp, rv):
    """One control step of every follower, in place on the state tuple ``st``.

    Same order as :meth:`ControlStack.step`: learner over the last period, tracking
    error, velocity command, derivative filter, sliding-mode torques, saturation,
    estimator and neuron advance. ``lp`` (3,) and ``lv`` (2,) are the leader's pose and
    velocities, ``pose`` (n, 3) and ``vel`` (n, 2) the measurements; with ``use_comm``
    the estimator reads ``ew`` (m,), ``lw`` (n,), ``rp`` (m, 3), ``rv`` (m, 2) (see
    :class:`~bioform_mj.control.estimator.Comm`).
    """
    (g, flags, offsets, lim, src, dst, lacc,
     est_pose, est_vel, z_hat, e_int, c_hat, d_hat, c_min, c_max, fy, fdy,
     vs, err, cmd, dcmd, tau, tau_raw, tau_body, saturated, p_err, v_err, k4n) = st
    n = pose.shape[0]
    dt = g[G_DT]
    first = flags[0] == 1
    learning = g[G_LEARN] != 0.0
    bio = g[G_BIO] != 0.0
    steer = g[G_STEER] != 0.0
    k1, k2, k3 = g[G_K1], g[G_K2], g[G_K3]
    # 1. learner (eq. 37), backward Euler in closed form, with the torques applied last period
    if learning and not first:
        h = dt
        for i in range(n):
            for c in range(2):
                k4 = k4n[i, c]
                k5 = g[G_K5 + c]
                kd = g[G_KD + c]
                t_ = tau_body[i, c]
                z = vel[i, c]
                R = e_int[i, c] - h * z
                S0 = k4 * R - z
                S1 = 1.0 + h * k4
                hk4t = h * k4 * t_
                P = c_hat[i, c] - hk4t * S0
                Q = hk4t * S1
                Pd = d_hat[i, c] - h * kd * S0
                Qd = h * kd * S1
                den = 1.0 + h * k4 + h * k5 * S1 + h * t_ * Q + h * Qd
                zn = (z_hat[i, c] + h * (t_ * P + Pd + k4 * z - k5 * S0)) / den
                z_hat[i, c] = zn
                e_int[i, c] = R + h * zn
                c_hat[i, c] = _clip(P - Q * zn, c_min[i, c], c_max[i, c])
                d_hat[i, c] = Pd - Qd * zn
    f00, f01, f10, f11 = g[G_FPHI], g[G_FPHI + 1], g[G_FPHI + 2], g[G_FPHI + 3]
    g0, g1 = g[G_FGAM], g[G_FGAM + 1]
    tphi = g[G_TPHI]
    for i in range(n):
        # 2. tracking error (eqs. 27–28) and velocity command (eq. 31)
        ex = est_pose[i, 0] - pose[i, 0] - offsets[i, 0]
        ey = est_pose[i, 1] - pose[i, 1] - offsets[i, 1]
        co = math.cos(pose[i, 2])
        si = math.sin(pose[i, 2])
        e0 = co * ex + si * ey
        e1 = -si * ex + co * ey
        e2 = _wrap(est_pose[i, 2] - pose[i, 2])
        err[i, 0] = e0
        err[i, 1] = e1
        err[i, 2] = e2
        u = vs[i] if bio else e0
        v_ir = est_vel[i, 0]
        cmd[i, 0] = v_ir * math.cos(e2) + k1 * u
        cmd[i, 1] = est_vel[i, 1] + k2 * v_ir * e1 + k3 * v_ir * math.sin(e2)
        # 3. derivative filter (exact discretisation)
        for c in range(2):
            if first:
                fy[i, c] = cmd[i, c]
                fdy[i, c] = 0.0
            y = f00 * fy[i, c] + f01 * fdy[i, c] + g0 * cmd[i, c]
            fdy[i, c] = f10 * fy[i, c] + f11 * fdy[i, c] + g1 * cmd[i, c]
            fy[i, c] = y
            dcmd[i, c] = fdy[i, c]
        # 4. sliding-mode torques (eqs. 38–39) and saturation
        ua = dcmd[i, 0] + g[G_CG] * _sat(cmd[i, 0] - vel[i, 0], tphi)
        ub = dcmd[i, 1] + g[G_CG + 1] * _sat(cmd[i, 1] - vel[i, 1], tphi)
        half_a = ua / (2.0 * c_hat[i, 0])
        half_b = ub / (2.0 * c_hat[i, 1])
        r0 = half_a - half_b
        r1 = half_a + half_b
        tau_raw[i, 0] = r0
        tau_raw[i, 1] = r1
        L = lim[i]
        saturated[i] = abs(r0) > L or abs(r1) > L
        if steer:
            tb = _clip(r1 - r0, -2.0 * L, 2.0 * L)
            room = 2.0 * L - abs(tb)
            ta = _clip(r0 + r1, -room, room)
            t0 = 0.5 * (ta - tb)
            t1 = 0.5 * (ta + tb)
        else:
            t0 = _clip(r0, -L, L)
            t1 = _clip(r1, -L, L)
        tau[i, 0] = t0
        tau[i, 1] = t1
        tau_body[i, 0] = t0 + t1
        tau_body[i, 1] = t1 - t0
    flags[0] = 0
    # 5. estimator (eqs. 12–13): consensus errors over the edges, then explicit Euler
    for i in range(n):
        for c in range(3):
            p_err[i, c] = 0.0
        for c in range(2):
            v_err[i, c] = 0.0
    for e in range(src.shape[0]):
        i = src[e]
        j = dst[e]
        w = ew[e] if use_comm else 1.0
        for c in range(3):
            xj = rp[e, c] if use_comm else est_pose[j, c]
            d = est_pose[i, c] - xj
            if c == 2:
                d = _wrap(d)
            p_err[i, c] += d * w
        for c in range(2):
            xj = rv[e, c] if use_comm else est_vel[j, c]
            v_err[i, c] += (est_vel[i, c] - xj) * w
    for i in range(n):
        a = lacc[i] * lw[i] if use_comm else lacc[i]
        pe0 = a * (est_pose[i, 0] - lp[0]) + p_err[i, 0]
        pe1 = a * (est_pose[i, 1] - lp[1]) + p_err[i, 1]
        pe2 = a * _wrap(est_pose[i, 2] - lp[2]) + p_err[i, 2]
        ve0 = a * (est_vel[i, 0] - lv[0]) + v_err[i, 0]
        ve1 = a * (est_vel[i, 1] - lv[1]) + v_err[i, 1]
        th = est_pose[i, 2]
        v = est_vel[i, 0]
        d0 = v * math.cos(th) - g[G_KP] * pe0
        d1 = v * math.sin(th) - g[G_KP + 1] * pe1
        d2 = est_vel[i, 1] - g[G_KP + 2] * pe2
        dv0 = -g[G_KA] * _sat(ve0, g[G_EPHI]) - g[G_KB] * ve0
        dv1 = -g[G_KA + 1] * _sat(ve1, g[G_EPHI + 1]) - g[G_KB + 1] * ve1
        est_pose[i, 0] += dt * d0
        est_pose[i, 1] += dt * d1
        est_pose[i, 2] = _wrap(est_pose[i, 2] + dt * d2)
        est_vel[i, 0] += dt * dv0
        est_vel[i, 1] += dt * dv1
        # neuron (eq. 32), exact for the frozen input x̃
        if bio:
            x = err[i, 0]
            f = max(x, 0.0)
            gg = max(-x, 0.0)
            lam = g[G_A] + f + gg
            v_inf = (g[G_B] * f - g[G_D] * gg) / lam
            vs[i] = v_inf + (vs[i] - v_inf) * math.exp(-lam * dt)


@_njit
def _accumulate(st, vel, met):
    """Per-follower run metrics of ``sim.simulate`` (SPEC §7), in place on ``met`` (n, 5)."""
    cmd, tau, tau_raw, saturated = st[19], st[21], st[22], st[24]
    for i in range(vel.shape[0]):
        met[i, M_VERR] += abs(cmd[i, 0] - vel[i, 0]) + abs(cmd[i, 1] - vel[i, 1])
        if saturated[i]:
            met[i, M_SAT] += 1.0
        met[i, M_VMAX] = max(met[i, M_VMAX], abs(cmd[i, 0]))
        met[i, M_TAU] = max(met[i, M_TAU], max(abs(tau[i, 0]), abs(tau[i, 1])))
        met[i, M_TAURAW] = max(met[i, M_TAURAW], max(abs(tau_raw[i, 0]), abs(tau_raw[i, 1])))


#: order of the log arrays in the tuple ``lg`` the chunk kernels record into (``sim.CHANNELS``)
LOG_ORDER = ("t", "leader_pose", "leader_vel", "pose", "vel", "est_pose", "est_vel", "cmd", "dcmd", "tau",
             "tau_raw", "c_hat", "c_true", "z_hat", "vs", "tracking_error", "formation_error",
             "estimation_error", "saturated")


@_njit
def record_row(lg, j, t, lp, lv, pose, vel, st, c_true):
    """Write log sample ``j`` (as ``sim._record``): time ``t``, the leader, measurements, the stack's state."""
    (lt, llp, llv, lpose, lvel, lest, lestv, lcmd, ldcmd, ltau, ltraw, lchat, lctrue, lz, lvs, lerr, lfe, lee,
     lsat) = lg
    offsets, est_pose, est_vel, z_hat, c_hat = st[2], st[7], st[8], st[9], st[11]
    vs, err, cmd, dcmd, tau, tau_raw, saturated = st[17], st[18], st[19], st[20], st[21], st[22], st[24]
    lt[j] = t
    for c in range(3):
        llp[j, c] = lp[c]
    llv[j, 0] = lv[0]
    llv[j, 1] = lv[1]
    for i in range(pose.shape[0]):
        for c in range(3):
            lpose[j, i, c] = pose[i, c]
            lest[j, i, c] = est_pose[i, c]
            lerr[j, i, c] = err[i, c]
        for c in range(2):
            lvel[j, i, c] = vel[i, c]
            lestv[j, i, c] = est_vel[i, c]
            lcmd[j, i, c] = cmd[i, c]
            ldcmd[j, i, c] = dcmd[i, c]
            ltau[j, i, c] = tau[i, c]
            ltraw[j, i, c] = tau_raw[i, c]
            lchat[j, i, c] = c_hat[i, c]
            lctrue[j, i, c] = c_true[i, c]
            lz[j, i, c] = z_hat[i, c]
        lvs[j, i] = vs[i]
        lfe[j, i] = math.hypot(pose[i, 0] - (lp[0] - offsets[i, 0]), pose[i, 1] - (lp[1] - offsets[i, 1]))
        lee[j, i] = math.hypot(est_pose[i, 0] - lp[0], est_pose[i, 1] - lp[1])
        lsat[j, i] = saturated[i]


@_njit
def row_ok(lg, j, lim3):
    """False if log sample ``j`` holds a non-finite value or a magnitude beyond the limits
    ``lim3 = (position m, speed m/s, torque N·m)`` (the checks of ``sim._guard``)."""
    lpose, lvel, lest, lestv, lcmd, ltraw, lchat, lvs = lg[3], lg[4], lg[5], lg[6], lg[7], lg[10], lg[11], lg[14]
    P, V, T = lim3[0], lim3[1], lim3[2]
    for i in range(lpose.shape[1]):
        if not (abs(lpose[j, i, 0]) <= P and abs(lpose[j, i, 1]) <= P and math.isfinite(lpose[j, i, 2])):
            return False
        if not (abs(lest[j, i, 0]) <= P and abs(lest[j, i, 1]) <= P and math.isfinite(lest[j, i, 2])):
            return False
        if not (abs(lvel[j, i, 0]) <= V and abs(lcmd[j, i, 0]) <= V and abs(lestv[j, i, 0]) <= V):
            return False
        if not (math.isfinite(lvel[j, i, 1]) and math.isfinite(lcmd[j, i, 1]) and math.isfinite(lestv[j, i, 1])):
            return False
        if not (abs(ltraw[j, i, 0]) <= T and abs(ltraw[j, i, 1]) <= T and math.isfinite(lvs[j, i])):
            return False
        if not (math.isfinite(lchat[j, i, 0]) and math.isfinite(lchat[j, i, 1])):
            return False
    return True


@_njit
def _after_control(k, N, stride, lg, j, lim3, L_pose, L_vel, dt, pose, vel, st, c_true):
    """Log sample of step ``k`` if due; returns ``(next row, ok)``."""
    if k % stride == 0 and k < N:
        record_row(lg, j, k * dt, L_pose[k], L_vel[k], pose, vel, st, c_true)
        ok = row_ok(lg, j, lim3)
        return j + 1, ok
    return j, True


# ------------------------------------------------------------------------ ideal plant
@_njit
def _disturbance(dist, c, t):
    """Channel ``c`` of the harmonic disturbance ``bias + amp cos(freq t + phase)`` (rows of ``dist``)."""
    return dist[c, 0] + dist[c, 1] * math.cos(dist[c, 2] * t + dist[c, 3])


@_njit
def _after_plant_step(k, N, dt, st, L_pose, L_vel, pose, vel, met, ew, lw, rp, rv, lg, j, stride, lim3, c_true):
    """Common to both plants after plant step ``k`` observed ``pose``, ``vel``: stop on a
    non-finite state, else the control step of ``k+1`` (if any), its metrics and log sample.
    Returns ``(next log row, status)`` (status as in :func:`run_ideal_chunk`)."""
    if not _finite(pose, vel):
        return j, 2
    if k + 1 < N:
        control_step(st, L_pose[k + 1], L_vel[k + 1], pose, vel, False, ew, lw, rp, rv)
        _accumulate(st, vel, met)
        j, ok = _after_control(k + 1, N, stride, lg, j, lim3, L_pose, L_vel, dt, pose, vel, st, c_true)
        if not ok:
            return j, 1
    return j, 0


@_njit
def _ideal_f(x, acc, dist, t, dx):
    """RK4 right-hand side of ``IdealPlant``: unicycle kinematics, ``ż = acc + d(t)``."""
    n = x.shape[0]
    d0 = _disturbance(dist, 0, t)
    d1 = _disturbance(dist, 1, t)
    for i in range(n):
        dx[i, 0] = x[i, 3] * math.cos(x[i, 2])
        dx[i, 1] = x[i, 3] * math.sin(x[i, 2])
        dx[i, 2] = x[i, 4]
        dx[i, 3] = acc[i, 0] + d0
        dx[i, 4] = acc[i, 1] + d1


@_njit
def run_ideal_chunk(st, k0, k1, N, dt, n_sub, L_pose, L_vel, c, dist, x, pose, vel, met, ew, lw, rp, rv,
                    lg, j0, stride, lim3):
    """Plant steps ``k0 … k1−1`` of the closed loop on the ideal plant, each followed by
    the control step of ``k+1`` (if ``k+1 < N``): the control step of ``k0`` must be done.

    The plant is ``IdealPlant`` (RK4, ``n_sub`` substeps): ``x`` (n, 5) its state
    ``[x, y, θ, υ, ω]``, updated in place; ``c`` (n, 2) the true ``[a, b]``; ``dist``
    (2, 4) the harmonic disturbance ``bias, amp, freq, phase`` of each channel.
    ``pose``, ``vel`` receive the observations; ``met`` accumulates the run metrics.
    Log samples (every ``stride`` steps) go to row ``j0`` on of the arrays ``lg``.
    Returns ``(plant steps done, next log row, status)``: status 0 = ok, 1 = the last
    logged row failed the guard, 2 = the plant state became non-finite.
    """
    j = j0
    n = x.shape[0]
    tau_body = st[23]
    acc = np.empty((n, 2))
    ka = np.empty((n, 5))
    kb = np.empty((n, 5))
    kc = np.empty((n, 5))
    kd = np.empty((n, 5))
    xt = np.empty((n, 5))
    h = dt / n_sub
    for k in range(k0, k1):
        t = k * dt
        for i in range(n):
            acc[i, 0] = tau_body[i, 0] * c[i, 0]
            acc[i, 1] = tau_body[i, 1] * c[i, 1]
        for s in range(n_sub):
            tk = t + s * h
            _ideal_f(x, acc, dist, tk, ka)
            for i in range(n):
                for q in range(5):
                    xt[i, q] = x[i, q] + 0.5 * h * ka[i, q]
            _ideal_f(xt, acc, dist, tk + 0.5 * h, kb)
            for i in range(n):
                for q in range(5):
                    xt[i, q] = x[i, q] + 0.5 * h * kb[i, q]
            _ideal_f(xt, acc, dist, tk + 0.5 * h, kc)
            for i in range(n):
                for q in range(5):
                    xt[i, q] = x[i, q] + h * kc[i, q]
            _ideal_f(xt, acc, dist, tk + h, kd)
            for i in range(n):
                for q in range(5):
                    x[i, q] = x[i, q] + (h / 6.0) * (ka[i, q] + 2 * kb[i, q] + 2 * kc[i, q] + kd[i, q])
        for i in range(n):
            x[i, 2] = _wrap(x[i, 2])
            pose[i, 0] = x[i, 0]
            pose[i, 1] = x[i, 1]
            pose[i, 2] = x[i, 2]
            vel[i, 0] = x[i, 3]
            vel[i, 1] = x[i, 4]
        j, status = _after_plant_step(k, N, dt, st, L_pose, L_vel, pose, vel, met, ew, lw, rp, rv, lg, j,
                                      stride, lim3, c)
        if status:
            return k + 1 - k0, j, status
    return k1 - k0, j, 0


@_njit
def _finite(pose, vel):
    for i in range(pose.shape[0]):
        if not (math.isfinite(pose[i, 0]) and math.isfinite(pose[i, 1]) and math.isfinite(pose[i, 2])
                and math.isfinite(vel[i, 0]) and math.isfinite(vel[i, 1])):
            return False
    return True


# ----------------------------------------------------------------------- MuJoCo plant
def _libmujoco_path() -> str | None:
    """Path of the libmujoco shipped with the ``mujoco`` Python package (without importing it)."""
    import importlib.util

    spec = importlib.util.find_spec("mujoco")
    if spec is None or not spec.submodule_search_locations:
        return None
    d = list(spec.submodule_search_locations)[0]
    names = sorted(f for f in os.listdir(d) if f.startswith("libmujoco.so") or
                   (f.startswith("libmujoco.") and f.endswith(".dylib")))
    return os.path.join(d, names[-1]) if names else None


# ``mj_step(const mjModel*, mjData*)`` of that library, called from compiled code by symbol
# name (so the kernels below can be cached on disk); pointers are passed as integers, which
# is the same calling convention on the 64-bit platforms MuJoCo supports. The Python
# bindings load the same file, so both act on the same MjModel/MjData.
HAVE_MJ_STEP = False
if HAVE_NUMBA:
    _mj_step = numba.types.ExternalFunction("mj_step", numba.types.void(numba.types.intp, numba.types.intp))
    try:
        import llvmlite.binding as _llvm

        _lib = _libmujoco_path()
        if _lib is not None and ctypes.sizeof(ctypes.c_void_p) == 8:
            _llvm.load_library_permanently(_lib)
            HAVE_MJ_STEP = True
    except (OSError, RuntimeError, ImportError):  # pragma: no cover - the generic loop still works
        HAVE_MJ_STEP = False


@_njit
def mujoco_observe(qpos, qvel, q7, v6, pose, vel):
    """Pose ``[x, y, θ]`` and body-frame ``[υ, ω]`` of each robot from the free joints (as ``MujocoPlant.observe``)."""
    for i in range(q7.shape[0]):
        a = q7[i, 0]
        w, qx, qy, qz = qpos[a + 3], qpos[a + 4], qpos[a + 5], qpos[a + 6]
        r00 = w * w + qx * qx - qy * qy - qz * qz
        r10 = 2.0 * (w * qz + qx * qy)
        r20 = 2.0 * (qx * qz - w * qy)
        r21 = 2.0 * (qy * qz + w * qx)
        r22 = w * w - qx * qx - qy * qy + qz * qz
        pose[i, 0] = qpos[a]
        pose[i, 1] = qpos[a + 1]
        pose[i, 2] = math.atan2(r10 + 0.0, r00)
        b = v6[i, 0]
        vel[i, 0] = (qvel[b] * r00 + qvel[b + 1] * r10) / math.hypot(r00, r10)
        vel[i, 1] = qvel[b + 3] * r20 + qvel[b + 4] * r21 + qvel[b + 5] * r22


@_njit
def run_mujoco_chunk(st, k0, k1, N, dt, n_sub, L_pose, L_vel, mp, dp, qpos, qvel, q7, v6,
                     ctrl, ctrl_id, xfrc, xmat, base, m_eff, i_eff, dist, pose, vel, met, ew, lw, rp, rv, lg, j0, stride, lim3, c_true, rec_ctrl, rec_xfrc):
    """Plant steps ``k0 … k1−1`` on MuJoCo (``n_sub`` physics steps each), each followed by
    the control step of ``k+1`` (if ``k+1 < N``): the control step of ``k0`` must be done.

    Equivalent to ``MujocoPlant.step``/``observe`` around :func:`control_step`:
    wheel torques to ``ctrl``, the disturbance accelerations as chassis force
    ``M_eff d1`` along the heading and yaw torque ``I_eff d2`` (held over the period),
    then ``mj_step`` on the shared ``MjData``.
    Log samples as in :func:`run_ideal_chunk`; returns ``(steps done, next log row, status)``.
    If ``rec_ctrl`` has rows, the inputs of step ``k`` (``ctrl`` and each base's
    ``xfrc_applied``) are copied to ``rec_ctrl[k]``, ``rec_xfrc[k]`` (for a bare replay).
    """
    j = j0
    n = pose.shape[0]
    tau = st[21]
    for k in range(k0, k1):
        t = k * dt
        d0 = _disturbance(dist, 0, t)
        d1 = _disturbance(dist, 1, t)
        for i in range(n):
            ctrl[ctrl_id[i, 0]] = tau[i, 0]
            ctrl[ctrl_id[i, 1]] = tau[i, 1]
            b = base[i]
            xfrc[b, 0] = xmat[b, 0] * (m_eff[i] * d0)
            xfrc[b, 1] = xmat[b, 3] * (m_eff[i] * d0)
            xfrc[b, 5] = i_eff[i] * d1
        if rec_ctrl.shape[0] > k:
            rec_ctrl[k, :] = ctrl
            for i in range(n):
                rec_xfrc[k, i, :] = xfrc[base[i], :]
        for s in range(n_sub):
            _mj_step(mp, dp)
        mujoco_observe(qpos, qvel, q7, v6, pose, vel)
        j, status = _after_plant_step(k, N, dt, st, L_pose, L_vel, pose, vel, met, ew, lw, rp, rv, lg, j,
                                      stride, lim3, c_true)
        if status:
            return k + 1 - k0, j, status
    return k1 - k0, j, 0



@_njit
def mujoco_replay(mp, dp, n_sub, ctrl, xfrc, base, rec_ctrl, rec_xfrc, solver_niter):
    """Bare physics for the benchmark: ``n_sub`` ``mj_step`` per recorded row of ``ctrl`` and
    chassis ``xfrc_applied`` inputs (see ``record_inputs`` of :func:`bioform_mj.sim.simulate`).
    Returns the total of the constraint solver's iterations (``data.solver_niter[0]``)."""
    iters = 0
    for k in range(rec_ctrl.shape[0]):
        ctrl[:] = rec_ctrl[k]
        for i in range(base.shape[0]):
            xfrc[base[i], :] = rec_xfrc[k, i]
        for s in range(n_sub):
            _mj_step(mp, dp)
            iters += solver_niter[0]
    return iters


# ------------------------------------------------------------------ the stack object
def pack_scalars(p: StackParams, filt_phi: np.ndarray, filt_gam: np.ndarray) -> np.ndarray:
    """The scalar parameters of ``p`` in the layout ``G_*`` of the kernel."""
    g = np.zeros(G_SIZE)
    g[[G_K1, G_K2, G_K3, G_A, G_B, G_D, G_DT, G_TPHI]] = (p.k1, p.k2, p.k3, p.A, p.B, p.D, p.dt, p.torque_phi)
    g[G_EPHI:G_EPHI + 2] = p.est_phi
    g[G_KP:G_KP + 3] = p.kp
    g[G_KA:G_KA + 2] = p.ka
    g[G_KB:G_KB + 2] = p.kb
    g[G_CG:G_CG + 2] = p.c_gain
    g[G_K5:G_K5 + 2] = p.k5
    g[G_KD:G_KD + 2] = np.broadcast_to(p.kd, (2,))
    g[G_FPHI:G_FPHI + 4] = np.asarray(filt_phi).ravel()
    g[G_FGAM:G_FGAM + 2] = filt_gam
    g[G_BIO] = float(p.law == "bioinspired")
    g[G_LEARN] = float(p.learning)
    g[G_STEER] = float(p.steer_priority)
    return g


class FusedControlStack(ControlStack):
    """:class:`ControlStack` computed by the compiled :func:`control_step`.

    Same attributes, same meaning; every state array is updated in place, so views
    taken once (by a logger or an observer) stay valid.
    """

    def __init__(self, graph: Graph, p: StackParams) -> None:
        if not HAVE_NUMBA:
            raise RuntimeError("numba is not installed")
        super().__init__(graph, p)
        n = graph.n
        self.g = pack_scalars(p, self.dfilter.phi, self.dfilter.gam)
        self.flags = np.ones(1, dtype=np.int64)
        self._lim1 = np.ascontiguousarray(np.asarray(p.tau_max, dtype=float).reshape(n))
        self._p_err = np.zeros((n, 3))
        self._v_err = np.zeros((n, 2))
        self._k4n = np.ascontiguousarray(np.broadcast_to(np.asarray(p.k4, dtype=float), (n, 2)))
        self.saturated = np.zeros(n, dtype=np.bool_)
        m = graph.src.shape[0]
        self._no_ew = np.ones(m)
        self._no_lw = np.ones(n)
        self._no_rp = np.zeros((m, 3))
        self._no_rv = np.zeros((m, 2))
        self._pose_in = np.zeros((n, 3))
        self._vel_in = np.zeros((n, 2))
        self.st = self._state_tuple()

    def _state_tuple(self) -> tuple:
        e, ln, f = self.estimator, self.learner, self.dfilter
        gr = e.graph
        return (self.g, self.flags, np.ascontiguousarray(self.p.offsets, dtype=float), self._lim1,
                np.ascontiguousarray(gr.src, dtype=np.int64), np.ascontiguousarray(gr.dst, dtype=np.int64),
                np.ascontiguousarray(gr.leader_access, dtype=float),
                e.pose, e.vel, ln.z_hat, ln.e_int, ln.c_hat, ln.d_hat, ln.c_min, ln.c_max, f.y, f.dy,
                self.vs, self.err, self.cmd, self.dcmd, self.tau, self.tau_raw, self.tau_body, self.saturated,
                self._p_err, self._v_err, self._k4n)

    def set_tau_max(self, tau_max: np.ndarray) -> None:
        """Change the wheel torque limits (n,) N·m in place."""
        super().set_tau_max(tau_max)
        self._lim1[:] = tau_max

    def reset(self, est_pose0: np.ndarray, vel0: np.ndarray) -> None:
        """As :meth:`ControlStack.reset`, in place."""
        super().reset(est_pose0, vel0)
        self.flags[0] = 1
        self.cmd[:] = 0.0
        self.dcmd[:] = 0.0
        self.err[:] = 0.0

    def step(self, leader_pose: np.ndarray, leader_vel: np.ndarray, pose: np.ndarray, vel: np.ndarray,
             comm: Comm | None = None) -> np.ndarray:
        """Torques ``[τ_L, τ_R]`` (n, 2, N·m), one kernel call (see :meth:`ControlStack.step`)."""
        self._pose_in[:] = pose
        self._vel_in[:] = vel
        lp = np.ascontiguousarray(leader_pose, dtype=float)
        lv = np.ascontiguousarray(leader_vel, dtype=float)
        if comm is None:
            control_step(self.st, lp, lv, self._pose_in, self._vel_in, False,
                         self._no_ew, self._no_lw, self._no_rp, self._no_rv)
        else:
            m = self._no_ew.shape[0]
            ew = np.ascontiguousarray(comm.edge_w, dtype=float)
            lw = np.ascontiguousarray(comm.leader_w, dtype=float)
            rp = self.estimator.pose[self.estimator.graph.dst] if comm.recv_pose is None else comm.recv_pose
            rv = self.estimator.vel[self.estimator.graph.dst] if comm.recv_vel is None else comm.recv_vel
            control_step(self.st, lp, lv, self._pose_in, self._vel_in, True, ew, lw,
                         np.ascontiguousarray(rp, dtype=float).reshape(m, 3),
                         np.ascontiguousarray(rv, dtype=float).reshape(m, 2))
        return self.tau

    @property
    def no_comm(self) -> tuple:
        """The ``(ew, lw, rp, rv)`` arguments that mean a perfect network."""
        return self._no_ew, self._no_lw, self._no_rp, self._no_rv

"""One control step of the whole stack, compiled: the paper's controller for ``n`` followers.

The equations are those of ``equations.py`` (written once); this module only loops them
over followers and graph edges, on named structures that numba compiles:

* :class:`Gains`: every number of the stack, resolved per follower (read-only in the
  kernel, except ``lim`` which an actuator fault may change);
* :class:`StackState`: every state and every intermediate signal of the last step,
  updated in place (so views taken once by a logger stay valid);
* :class:`CommIn`: what each follower received this step (faulty networks; design §8).

Order within a step at time ``t_k`` (design §2): learner over ``(t_{k−1}, t_k]`` with
the torques applied then and the velocities measured now; tracking error from the
current estimates; velocity command from the current neuron state; command derivative;
sliding-mode torques with ``ĉ``; saturation; estimator and neuron advance to ``t_{k+1}``.
"""

from __future__ import annotations

from math import cos, sin
from typing import NamedTuple

import numpy as np

from bioform_mj.control.cbf import CBF_RESIDUAL, cbf_filter
from bioform_mj.core.equations import (
    command_derivative,
    command_rate,
    error_rate,
    estimator_euler,
    estimator_rates,
    learner_drag_step,
    learner_step,
    neuron_rate,
    neuron_step,
    njit,
    saturate,
    sliding_mode,
    slot_error,
    velocity_command,
    wrap,
)

#: ``Gains.deriv`` codes of ``torque.derivative`` (design §6)
DERIV_FILTER, DERIV_DIFFERENCE, DERIV_ANALYTIC = 0, 1, 2
DERIVATIVES = {"filter": DERIV_FILTER, "difference": DERIV_DIFFERENCE, "analytic": DERIV_ANALYTIC}


class Gains(NamedTuple):
    """Numbers of the stack (units in brackets); arrays are per follower ``(n, …)`` or per edge ``(m,)``.

    Kinematics (eq. 31–32): ``k1`` [1/s], ``k2`` [rad/m²], ``k3`` [rad/m]; neuron ``A, B, D``.
    Estimator (eqs. 12–13): ``kx, ky, kth`` [1/s]; sign gains ``ka0, ka1`` [m/s², rad/s²];
    linear gains ``kb0, kb1`` [1/s]; boundary layers ``ephi0, ephi1`` (0 = ``sgn``).
    Torque law (eqs. 38–39): ``ca, cb``; boundary layer ``tphi`` (0 = ``sgn``);
    command derivative ``deriv`` (design §6): :data:`DERIV_FILTER` (coefficients ``f00 … g1`` of
    :func:`~.equations.filter_coefficients`), :data:`DERIV_DIFFERENCE` or :data:`DERIV_ANALYTIC`.
    Learner (eq. 37): ``k4`` (n, 2), ``k5a, k5b`` [1/s], ``kda, kdb`` (0 = the paper),
    bounds ``c_min, c_max`` (n, 2). ``lim`` (n,) wheel torque limit [N·m]; ``steer``: steer-priority
    saturation; ``bio``: bioinspired law (else backstepping); ``learning``: run eq. 37.
    ``offsets`` (n, 2) [m], in the leader's frame if ``leader_frame`` (else world); graph edges
    ``src ← dst`` (m,); ``lacc`` (n,) leader access ``a_ir``.
    ``dt`` [s] the control period.
    """

    k1: float
    k2: float
    k3: float
    A: float
    B: float
    D: float
    kx: float
    ky: float
    kth: float
    ka0: float
    ka1: float
    kb0: float
    kb1: float
    ephi0: float
    ephi1: float
    ca: float
    cb: float
    tphi: float
    f00: float
    f01: float
    f10: float
    f11: float
    g0: float
    g1: float
    deriv: int
    k5a: float
    k5b: float
    kda: float
    kdb: float
    dt: float
    bio: bool
    learning: bool
    steer: bool
    leader_frame: bool
    kka: float  # learned-drag gains (design §14; 0 = the paper's learner, bit for bit)
    kkb: float
    k_max: float  # 1/s: the learned drag's projection bound
    k4: np.ndarray
    c_min: np.ndarray
    c_max: np.ndarray
    lim: np.ndarray
    offsets: np.ndarray
    src: np.ndarray
    dst: np.ndarray
    lacc: np.ndarray
    # the safety filter (design §19, control/cbf.py): on, [l, γ, d, range], radii (n,),
    # obstacle rows (m, 7), QP scratch (n + m, 2), (n + m,), (n + m,)
    cbf: bool
    cbf_par: np.ndarray
    cbf_rad: np.ndarray
    cbf_obst: np.ndarray
    cbf_A: np.ndarray
    cbf_b: np.ndarray
    cbf_lam: np.ndarray
    cbf_bad: np.ndarray  # (n,) control steps whose QP had no solution (cbf.CBF_RESIDUAL), since reset


class StackState(NamedTuple):
    """State and last-step signals of the stack, arrays over followers.

    ``est_pose`` (n,3) ``P_ir``; ``est_vel`` (n,2) ``[υ_ir, ω_ir]``; learner ``z_hat, e_int,
    c_hat, d_hat`` (n,2); command-derivative state ``fy, fdy`` (n,2) (filter output and rate; for
    ``difference`` ``fy`` is the last command); neuron ``vs`` (n,); last step's
    ``err`` (n,3) ``[x̃, ỹ, θ̃]``, ``cmd``, ``dcmd`` (n,2), ``tau`` (applied) and ``tau_raw``
    (commanded) ``[τ_L, τ_R]`` and ``tau_body`` ``[τ_a, τ_b]`` (n,2), ``saturated`` (n,);
    consensus errors ``p_err`` (n,3), ``v_err`` (n,2) of this step (eqs. 12–13, leader term included)
    and the estimator's rates from them, ``est_rate`` (n,5) ``(ẋ_ir, ẏ_ir, θ̇_ir, υ̇_ir, ω̇_ir)``
    (computed once: the analytic command derivative and the Euler step both read them);
    ``first`` (1,) 1 until the first step.
    """

    est_pose: np.ndarray
    est_vel: np.ndarray
    z_hat: np.ndarray
    e_int: np.ndarray
    c_hat: np.ndarray
    d_hat: np.ndarray
    fy: np.ndarray
    fdy: np.ndarray
    vs: np.ndarray
    err: np.ndarray
    cmd: np.ndarray
    dcmd: np.ndarray
    tau: np.ndarray
    tau_raw: np.ndarray
    tau_body: np.ndarray
    saturated: np.ndarray
    p_err: np.ndarray
    v_err: np.ndarray
    est_rate: np.ndarray
    first: np.ndarray
    k_hat: np.ndarray  # (n, 2) learned drag rates [1/s] (opt-in learner.drag, design §14; 0 otherwise)


class CommIn(NamedTuple):
    """What the network delivered this step (design §8). ``use = False``: the paper's perfect
    network (the arrays are then ignored). ``ew`` (m,) edge weights, ``lw`` (n,) leader-link
    weights, ``rp`` (m,3) / ``rv`` (m,2) the neighbour estimates as received over each edge."""

    use: bool
    ew: np.ndarray
    lw: np.ndarray
    rp: np.ndarray
    rv: np.ndarray


def new_state(n: int) -> StackState:
    """A zeroed :class:`StackState` for ``n`` followers."""
    z2 = lambda: np.zeros((n, 2))  # noqa: E731
    return StackState(
        np.zeros((n, 3)),
        z2(),
        z2(),
        z2(),
        z2(),
        z2(),
        z2(),
        z2(),
        np.zeros(n),
        np.zeros((n, 3)),
        z2(),
        z2(),
        z2(),
        z2(),
        z2(),
        np.zeros(n, dtype=np.bool_),
        np.zeros((n, 3)),
        z2(),
        np.zeros((n, 5)),
        np.ones(1, dtype=np.int64),
        z2(),
    )


def perfect_comm(n: int, m: int) -> CommIn:
    """The :class:`CommIn` of a perfect network."""
    return CommIn(False, np.ones(m), np.ones(n), np.zeros((m, 3)), np.zeros((m, 2)))


@njit
def reset_state(g, s, est_pose0, vel0, c_hat0):
    """Initial estimates ``P_ir(0)`` (n,3) (heading wrapped), ``[υ_ir, ω_ir](0) = 0`` (Remark 5),
    ``ẑ = vel0`` (measured), ``∫e = 0``, ``ĉ = clip(c_hat0)``, ``d̂ = 0``, ``V_s = 0``, no torque."""
    n = est_pose0.shape[0]
    for i in range(n):
        s.est_pose[i, 0] = est_pose0[i, 0]
        s.est_pose[i, 1] = est_pose0[i, 1]
        s.est_pose[i, 2] = wrap(est_pose0[i, 2])
        for c in range(2):
            s.est_vel[i, c] = 0.0
            s.z_hat[i, c] = vel0[i, c]
            s.e_int[i, c] = 0.0
            s.c_hat[i, c] = min(max(c_hat0[i, c], g.c_min[i, c]), g.c_max[i, c])
            s.d_hat[i, c] = 0.0
            s.k_hat[i, c] = 0.0
            s.fy[i, c] = 0.0
            s.fdy[i, c] = 0.0
            s.cmd[i, c] = 0.0
            s.dcmd[i, c] = 0.0
            s.tau[i, c] = 0.0
            s.tau_raw[i, c] = 0.0
            s.tau_body[i, c] = 0.0
        for c in range(3):
            s.err[i, c] = 0.0
        s.vs[i] = 0.0
        s.saturated[i] = False
    s.first[0] = 1


@njit
def control_step(g, s, lp, lv, pose, vel, comm):
    """One control step of every follower, in place on ``s`` (:class:`StackState`).

    ``lp`` (3,), ``lv`` (2,): the leader's pose and velocities (read only through ``a_ir``);
    ``pose`` (n,3), ``vel`` (n,2): what each follower measures of itself; ``comm``
    (:class:`CommIn`). The torques to hold over the next period are ``s.tau`` (n,2).
    """
    if g.learning and s.first[0] == 0:
        learner_update(g, s, vel)
    estimator_consensus(g, s, lp, lv, comm)
    command_and_torques(g, s, pose, vel)
    estimator_advance(g, s)


@njit(inline=True)
def learner_update(g, s, vel):
    """Eq. 37 over the last period for every follower, with the torques applied then
    (``s.tau_body``: as commanded, or what a plant with DC motors measured as delivered and wrote
    there after its step, design §8.2) and the velocities ``vel`` (n, 2) measured now."""
    dt = g.dt
    k5 = (g.k5a, g.k5b)
    kd = (g.kda, g.kdb)
    kk = (g.kka, g.kkb)
    for i in range(vel.shape[0]):
        for c in range(2):  # a, then b
            z_hat, e_int, c_hat, d_hat = s.z_hat[i, c], s.e_int[i, c], s.c_hat[i, c], s.d_hat[i, c]
            tau, z = s.tau_body[i, c], vel[i, c]
            if kk[c] > 0.0:  # opt-in learned drag (design §14); else the paper's step, unchanged
                zn, en, cn, dn, kn = learner_drag_step(
                    z_hat, e_int, c_hat, d_hat, s.k_hat[i, c], tau, z, g.k4[i, c], k5[c], kd[c], kk[c], g.c_min[i, c],
                    g.c_max[i, c], g.k_max, dt,
                )  # fmt: skip
                s.k_hat[i, c] = kn
            else:
                zn, en, cn, dn = learner_step(
                    z_hat, e_int, c_hat, d_hat, tau, z, g.k4[i, c], k5[c], kd[c], g.c_min[i, c], g.c_max[i, c], dt
                )
            s.z_hat[i, c], s.e_int[i, c], s.c_hat[i, c], s.d_hat[i, c] = zn, en, cn, dn


@njit(inline=True)
def command_and_torques(g, s, pose, vel):
    """Tracking error, velocity command (eq. 31), command derivative, sliding-mode torques
    (eqs. 38–39) and saturation for every follower, from the current estimates."""
    first = s.first[0] == 1
    for i in range(pose.shape[0]):
        e0, e1, e2, v_ref, w_ref = follower_error(g, s, i, pose)
        u = s.vs[i] if g.bio else e0
        vc, wc = velocity_command(e1, e2, u, v_ref, w_ref, g.k1, g.k2, g.k3)
        if g.cbf:  # the safety filter between eq. 31 and the torque law (design §19)
            vc, wc = cbf_filter(i, vc, wc, pose, g.cbf_rad, g.cbf_obst, g.cbf_par, g.cbf_A, g.cbf_b, g.cbf_lam)
            if g.cbf_lam[g.cbf_lam.shape[0] - 1] > CBF_RESIDUAL:  # no solution: counted, said after the run
                g.cbf_bad[i] += 1.0
        s.cmd[i, 0], s.cmd[i, 1] = vc, wc
        if g.deriv == DERIV_ANALYTIC:  # chain rule through the controller's own dynamics (design §6)
            r = s.est_rate  # this step's estimator rates (estimator_consensus)
            dpx, dpy, dpth, dv_ir, dw_ir = r[i, 0], r[i, 1], r[i, 2], r[i, 3], r[i, 4]
            ch = cos(pose[i, 2])
            sh = sin(pose[i, 2])
            dex, dey, deth = error_rate(
                e0, e1, vel[i, 0], vel[i, 1], s.est_vel[i, 0], dpth, e2, ch * dpx + sh * dpy, -sh * dpx + ch * dpy
            )
            du = neuron_rate(s.vs[i], e0, g.A, g.B, g.D) if g.bio else dex
            s.dcmd[i, 0], s.dcmd[i, 1] = command_rate(
                e1, e2, s.est_vel[i, 0], dv_ir, dw_ir, dey, deth, du, g.k1, g.k2, g.k3
            )
        else:
            for c in range(2):  # filter or backward difference (design §6)
                follower_derivative(g, s, i, c, first)
        follower_torques(g, s, i, vc, wc, vel)
    s.first[0] = 0


# Per-follower pieces shared with the learning environment (envs/kernels.py): one-line wrappers around
# equations (on scalars; the batch engine's Warp kernels call the same equations): a numba call that
# passes Gains and StackState (every array of both, ~7 words each, by value) costs more than the piece
# itself, per follower, so these and the phases of control_step are inlined (numba IR, `njit(inline=True)`):
# control_step is one call a step (issue 28, paper scene under callgrind: our code's instructions per step
# 13.1k -> 12.2k, its simulated L1i misses 716 -> 601; results bit-identical).
@njit(inline=True)
def follower_error(g, s, i, pose):
    """Follower ``i``'s :func:`slot_error` from its leader estimate and measured ``pose`` (n, 3), into
    ``s.err[i]``; returns ``(x̃, ỹ, θ̃, υ_ref, ω_ref)``."""
    e0, e1, e2, v_ref, w_ref = slot_error(
        s.est_pose[i, 0], s.est_pose[i, 1], s.est_pose[i, 2], s.est_vel[i, 0], s.est_vel[i, 1], g.offsets[i, 0],
        g.offsets[i, 1], pose[i, 0], pose[i, 1], pose[i, 2], g.leader_frame,
    )  # fmt: skip
    s.err[i, 0], s.err[i, 1], s.err[i, 2] = e0, e1, e2
    return e0, e1, e2, v_ref, w_ref


@njit(inline=True)
def follower_derivative(g, s, i, c, first):
    """:func:`command_derivative` of the command ``s.cmd[i, c]`` into ``s.dcmd[i, c]``, its state ``s.fy``,
    ``s.fdy`` advanced; ``first``: the first step."""
    s.fy[i, c], s.fdy[i, c], s.dcmd[i, c] = command_derivative(
        s.fy[i, c], s.fdy[i, c], s.cmd[i, c], first, g.deriv == DERIV_DIFFERENCE, g.f00, g.f01, g.f10, g.f11, g.g0,
        g.g1, g.dt,
    )  # fmt: skip


@njit(inline=True)
def follower_torques(g, s, i, vc, wc, vel):
    """Follower ``i``'s sliding-mode torques (eqs. 38–39) tracking ``(vc, wc)`` [m/s, rad/s] with
    ``s.dcmd[i]``, the measured ``vel`` (n, 2) and ``ĉ``; then :func:`apply_torque`."""
    r0, r1 = sliding_mode(
        vc, wc, s.dcmd[i, 0], s.dcmd[i, 1], vel[i, 0], vel[i, 1], s.c_hat[i, 0], s.c_hat[i, 1], g.ca, g.cb, g.tphi
    )
    apply_torque(g, s, i, r0, r1)


@njit(inline=True)
def apply_torque(g, s, i, r0, r1):
    """Follower ``i``'s commanded wheel torques ``(r0, r1)`` = ``[τ_L, τ_R]`` N·m into ``s.tau_raw[i]``,
    saturated at ``g.lim[i]`` (``g.steer``: steer priority) into ``s.tau[i]``, ``s.saturated[i]``, and the
    body torques ``s.tau_body[i]`` the learner reads."""
    s.tau_raw[i, 0], s.tau_raw[i, 1] = r0, r1
    L = g.lim[i]
    s.saturated[i] = abs(r0) > L or abs(r1) > L
    t0, t1 = saturate(r0, r1, L, g.steer)
    s.tau[i, 0], s.tau[i, 1] = t0, t1
    s.tau_body[i, 0] = t0 + t1  # τ_a = τ_L + τ_R
    s.tau_body[i, 1] = t1 - t0  # τ_b = τ_R − τ_L (design §5)


@njit
def estimator_update(g, s, lp, lv, comm):
    """The distributed estimator (eqs. 12–13) and the neuron (eq. 32) advanced to the next step:
    consensus errors over the graph edges (and the leader for ``a_ir = 1``), one Euler step."""
    estimator_consensus(g, s, lp, lv, comm)
    estimator_advance(g, s)


@njit(inline=True)
def estimator_consensus(g, s, lp, lv, comm):
    """Consensus errors of eqs. 12–13 into ``s.p_err`` (n,3) and ``s.v_err`` (n,2): over the graph
    edges, plus ``a_ir (P_ir − P_r)`` for the leader link; from the estimates before they advance.
    Then the estimator's rates from them into ``s.est_rate`` (n,5) (``estimator_rates``)."""
    n = s.est_pose.shape[0]
    for i in range(n):
        for c in range(3):
            s.p_err[i, c] = 0.0
        for c in range(2):
            s.v_err[i, c] = 0.0
    for e in range(g.src.shape[0]):
        i = g.src[e]
        j = g.dst[e]
        w = comm.ew[e] if comm.use else 1.0
        for c in range(3):
            xj = comm.rp[e, c] if comm.use else s.est_pose[j, c]
            d = s.est_pose[i, c] - xj
            if c == 2:
                d = wrap(d)
            s.p_err[i, c] += d * w
        for c in range(2):
            xj = comm.rv[e, c] if comm.use else s.est_vel[j, c]
            s.v_err[i, c] += (s.est_vel[i, c] - xj) * w
    for i in range(n):
        a = g.lacc[i] * comm.lw[i] if comm.use else g.lacc[i]
        s.p_err[i, 0] = a * (s.est_pose[i, 0] - lp[0]) + s.p_err[i, 0]
        s.p_err[i, 1] = a * (s.est_pose[i, 1] - lp[1]) + s.p_err[i, 1]
        s.p_err[i, 2] = a * wrap(s.est_pose[i, 2] - lp[2]) + s.p_err[i, 2]
        s.v_err[i, 0] = a * (s.est_vel[i, 0] - lv[0]) + s.v_err[i, 0]
        s.v_err[i, 1] = a * (s.est_vel[i, 1] - lv[1]) + s.v_err[i, 1]
        r = s.est_rate
        r[i, 0], r[i, 1], r[i, 2], r[i, 3], r[i, 4] = estimator_rates(
            s.est_pose[i, 2],
            s.est_vel[i, 0],
            s.est_vel[i, 1],
            s.p_err[i, 0],
            s.p_err[i, 1],
            s.p_err[i, 2],
            s.v_err[i, 0],
            s.v_err[i, 1],
            g.kx,
            g.ky,
            g.kth,
            g.ka0,
            g.ka1,
            g.kb0,
            g.kb1,
            g.ephi0,
            g.ephi1,
        )


@njit(inline=True)
def estimator_advance(g, s):
    """One Euler step of the estimator (eqs. 12–13) with the rates :func:`estimator_consensus`
    computed (``s.est_rate``), and the neuron (eq. 32) for the frozen input ``x̃``."""
    n = s.est_pose.shape[0]
    dt = g.dt
    r = s.est_rate
    for i in range(n):
        px, py, pth, v, w = estimator_euler(
            s.est_pose[i, 0],
            s.est_pose[i, 1],
            s.est_pose[i, 2],
            s.est_vel[i, 0],
            s.est_vel[i, 1],
            r[i, 0],
            r[i, 1],
            r[i, 2],
            r[i, 3],
            r[i, 4],
            dt,
        )
        s.est_pose[i, 0], s.est_pose[i, 1], s.est_pose[i, 2] = px, py, pth
        s.est_vel[i, 0], s.est_vel[i, 1] = v, w
        if g.bio:  # neuron (eq. 32), exact for the frozen input x̃
            s.vs[i] = neuron_step(s.vs[i], s.err[i, 0], g.A, g.B, g.D, dt)

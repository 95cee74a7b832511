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
from typing import NamedTuple, get_type_hints

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


#: :class:`Gains`' numbers (its fields that are not arrays), in order: the fields of :class:`Knobs`
_HINTS = get_type_hints(Gains)
KNOBS = tuple(f for f in Gains._fields if _HINTS[f] is not np.ndarray)
_LEAD = KNOBS.index("cbf")  # Gains' numbers before its first array; ``cbf`` is the one after
assert Gains._fields[:_LEAD] == KNOBS[:_LEAD] and KNOBS[_LEAD:] == ("cbf",)

#: :class:`Gains` without its arrays: a tuple of numbers, which numba copies into an inlined function
#: without a reference count (a tuple holding arrays takes one on each of them, issue 28)
Knobs = NamedTuple("Knobs", [(f, _HINTS[f]) for f in KNOBS])  # type: ignore[misc]


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
def knobs(g):
    """The :class:`Knobs` of :class:`Gains` ``g`` (a call: numba's inliner takes no ``*args``)."""
    return Knobs(*g[:_LEAD], g.cbf)


@njit
def control_step(g, s, lp, lv, pose, vel, comm):
    """One control step of every follower, in place on ``s`` (:class:`StackState`).

    ``lp`` (3,), ``lv`` (2,): the leader's pose and velocities (read only through ``a_ir``);
    ``pose`` (n,3), ``vel`` (n,2): what each follower measures of itself; ``comm``
    (:class:`CommIn`). The torques to hold over the next period are ``s.tau`` (n,2).
    """
    stack_step(knobs(g), g, s, comm, lp[0], lp[1], lp[2], lv[0], lv[1], pose, vel)


# The step's pieces take the numbers of the gains as :class:`Knobs` and only the arrays they read, one by one
# (issue 28): numba takes a reference count on every array of a named tuple it copies (into a function,
# inlined or not) and on the array of every field it reads, and releases them where the copy or the field's
# name is last used; LLVM's pruning removes a count and its release only where the release post-dominates it
# and nothing else is released between them. The ~400 counts a step of the paper scene (15 % of our code's
# instructions) came from fields of Gains and StackState read in the per-follower helpers and under
# conditions, and from pairs spanning the call of cbf_filter (a call numba cannot see through: its error
# return is a path that skips the release). Now the pieces read only arrays they were given, none only under
# a condition of their own (an array released on two paths is not pruned: so the learner's loop runs zero
# times rather than being skipped), and the safety filter is a pass of its own between stack_head and
# stack_tail, which the compiled chunks call on arrays bound once per chunk (49 counts a step left, mostly in
# the plant's calls: docs/findings/performance.md). stack_head/stack_tail are calls, not inlined into the
# chunks: inlined, L1i misses 483 -> 324 a step but +16 s of cold compile. (Numba's inliner takes at most 30
# arguments: CPython passes more as *args.)
# The chunks repeat this function's three lines on their own bound arrays rather than call one shared helper
# (design §2): a helper inlined into their step loop binds each array it takes (those of
# Gains, StackState and CommIn counting one by one) to a name of its own at every step, and the calls of
# stack_head, stack_tail and cbf_filter inside keep LLVM from pruning those counts. Measured (session 13, an
# inlined `stack_pass(kn, g, s, comm, ..., pose, vel, cmd, cbf_par, ..., cbf_bad)` used by this function and
# both chunks; scripts/bench_callgrind.py, paper, MuJoCo, 1 s): refcount calls 49 -> 149 a step (one pair per
# array argument: 50), our code's instructions 8,946 -> 9,615 a step; the same bits, the same cold compile.
# tests/test_control_sequence.py checks the copies against this function, by their code and by their bits.
@njit(inline=True)
def stack_step(kn, g, s, comm, lx, ly, lth, lv0, lw0, pose, vel):
    """:func:`control_step` with the gains' :class:`Knobs` ``kn``, the leader's pose ``(lx, ly, lth)`` (m, m,
    rad) and velocities ``(lv0, lw0)`` (m/s, rad/s): :func:`stack_head`, the safety filter, :func:`stack_tail`."""
    stack_head(kn, g, s, comm, lx, ly, lth, lv0, lw0, pose, vel)
    if kn.cbf:  # the safety filter between eq. 31 and the torque law (design §19)
        safety_filter(pose, s.cmd, g.cbf_par, g.cbf_rad, g.cbf_obst, g.cbf_A, g.cbf_b, g.cbf_lam, g.cbf_bad)
    stack_tail(kn, g, s, pose, vel)


@njit
def stack_head(kn, g, s, comm, lx, ly, lth, lv0, lw0, pose, vel):
    """A control step up to the velocity commands (:func:`stack_step` without the safety filter and
    :func:`stack_tail`): the learner (eq. 37; its loop runs zero times when off: see above), the estimator's
    consensus and rates, every follower's tracking error and velocity command (eq. 31)."""
    learner_update(kn, kn.learning and s.first[0] == 0, vel, s.z_hat, s.e_int, s.c_hat, s.d_hat, s.k_hat, s.tau_body,
                   g.k4, g.c_min, g.c_max)  # fmt: skip
    estimator_consensus(kn, lx, ly, lth, lv0, lw0, s.est_pose, s.est_vel, s.p_err, s.v_err, s.est_rate, g.src, g.dst,
                        g.lacc, comm.use, comm.ew, comm.lw, comm.rp, comm.rv)  # fmt: skip
    velocity_commands(kn, pose, s.est_pose, s.est_vel, g.offsets, s.err, s.vs, s.cmd)


@njit
def stack_tail(kn, g, s, pose, vel):
    """A control step after the velocity commands (and the safety filter): command derivatives, torques
    (eqs. 38–39) with saturation, and the estimator and neuron advanced to the next step."""
    torques(kn, pose, vel, s.est_vel, s.err, s.vs, s.cmd, s.dcmd, s.fy, s.fdy, s.est_rate, s.c_hat, s.tau, s.tau_raw,
            s.tau_body, s.saturated, s.first, g.lim)  # fmt: skip
    estimator_advance(kn, s.est_pose, s.est_vel, s.est_rate, s.vs, s.err)


@njit(inline=True)
def learner_update(kn, on, vel, z_hat, e_int, c_hat, d_hat, k_hat, tau_body, k4, c_min, c_max):
    """Eq. 37 over the last period for every follower (``on``; else nothing), with the torques applied then
    (``tau_body`` (n, 2): as commanded, or what a plant with DC motors measured as delivered and wrote
    there after its step, design §8.2) and the velocities ``vel`` (n, 2) measured now; the learner's state
    ``z_hat, e_int, c_hat, d_hat, k_hat`` (n, 2) in place."""
    dt = kn.dt
    k5 = (kn.k5a, kn.k5b)
    kd = (kn.kda, kn.kdb)
    kk = (kn.kka, kn.kkb)
    for i in range(vel.shape[0] if on else 0):  # zero times when off: see above
        for c in range(2):  # a, then b
            z, tq = vel[i, c], tau_body[i, c]
            if kk[c] > 0.0:  # opt-in learned drag (design §14); else the paper's step, unchanged
                zn, en, cn, dn, kh = learner_drag_step(
                    z_hat[i, c], e_int[i, c], c_hat[i, c], d_hat[i, c], k_hat[i, c], tq, z, k4[i, c], k5[c], kd[c],
                    kk[c], c_min[i, c], c_max[i, c], kn.k_max, dt,
                )  # fmt: skip
                k_hat[i, c] = kh
            else:
                zn, en, cn, dn = learner_step(
                    z_hat[i, c], e_int[i, c], c_hat[i, c], d_hat[i, c], tq, z, k4[i, c], k5[c], kd[c], c_min[i, c],
                    c_max[i, c], dt,
                )  # fmt: skip
            z_hat[i, c], e_int[i, c], c_hat[i, c], d_hat[i, c] = zn, en, cn, dn


@njit(inline=True)
def velocity_commands(kn, pose, est_pose, est_vel, offsets, err, vs, cmd):
    """Every follower's tracking error into ``err`` (n, 3) (:func:`follower_error`) and velocity command
    (eq. 31) into ``cmd`` (n, 2), from the current estimates ``est_pose``, ``est_vel`` and neuron ``vs``."""
    for i in range(pose.shape[0]):
        e0, e1, e2, v_ref, w_ref = follower_error(kn, i, pose, est_pose, est_vel, offsets, err)
        u = vs[i] if kn.bio else e0
        cmd[i, 0], cmd[i, 1] = velocity_command(e1, e2, u, v_ref, w_ref, kn.k1, kn.k2, kn.k3)


@njit(inline=True)
def safety_filter(pose, cmd, cbf_par, cbf_rad, cbf_obst, cbf_A, cbf_b, cbf_lam, cbf_bad):
    """The safety filter (design §19, :func:`~.cbf.cbf_filter`) on every follower's command ``cmd`` (n, 2) in
    place; a step whose QP had no solution is counted in ``cbf_bad`` (n,) (said after the run). Its own pass
    over the followers (each one's filter reads the poses, not the others' commands: the same bits as
    filtering each command as it is made): the only call here that numba cannot see through (it could raise),
    which keeps LLVM from pruning the reference counts of arrays bound across it."""
    for i in range(pose.shape[0]):
        cmd[i, 0], cmd[i, 1] = cbf_filter(i, cmd[i, 0], cmd[i, 1], pose, cbf_rad, cbf_obst, cbf_par, cbf_A, cbf_b,
                                          cbf_lam)  # fmt: skip
        if cbf_lam[cbf_lam.shape[0] - 1] > CBF_RESIDUAL:  # no solution
            cbf_bad[i] += 1.0


@njit(inline=True)
def torques(kn, pose, vel, est_vel, err, vs, cmd, dcmd, fy, fdy, est_rate, c_hat, tau, tau_raw, tau_body, saturated,
            first, lim):  # fmt: skip
    """Every follower's command derivative (design §6) and sliding-mode torques (eqs. 38–39) with saturation,
    tracking ``cmd`` (n, 2) from the errors ``err`` (n, 3) of :func:`velocity_commands` (the arrays of
    :class:`StackState` and :class:`Gains` by their field names); then ``first[0] = 0``."""
    first_step = first[0] == 1
    for i in range(pose.shape[0]):
        vc, wc = cmd[i, 0], cmd[i, 1]
        if kn.deriv == DERIV_ANALYTIC:  # chain rule through the controller's own dynamics (design §6)
            e0, e1, e2 = err[i, 0], err[i, 1], err[i, 2]
            # this step's estimator rates (estimator_consensus)
            dpx, dpy, dpth = est_rate[i, 0], est_rate[i, 1], est_rate[i, 2]
            dv_ir, dw_ir = est_rate[i, 3], est_rate[i, 4]
            ch = cos(pose[i, 2])
            sh = sin(pose[i, 2])
            dex, dey, deth = error_rate(
                e0, e1, vel[i, 0], vel[i, 1], est_vel[i, 0], dpth, e2, ch * dpx + sh * dpy, -sh * dpx + ch * dpy
            )
            du = neuron_rate(vs[i], e0, kn.A, kn.B, kn.D) if kn.bio else dex
            dcmd[i, 0], dcmd[i, 1] = command_rate(
                e1, e2, est_vel[i, 0], dv_ir, dw_ir, dey, deth, du, kn.k1, kn.k2, kn.k3
            )
        else:
            for c in range(2):  # filter or backward difference (design §6)
                follower_derivative(kn, i, c, first_step, fy, fdy, cmd, dcmd)
        follower_torques(kn, i, vc, wc, vel, dcmd, c_hat, lim, tau, tau_raw, tau_body, saturated)
    first[0] = 0


# Per-follower pieces shared with the learning environment (envs/kernels.py): one-line wrappers around
# equations (on scalars; the batch engine's Warp kernels call the same equations), inlined (numba IR,
# `njit(inline=True)`): a numba call passes every array by value (~7 words each), which costs more than the
# piece itself, per follower (issue 28: the stack's phases and these inlined, our code's instructions per step
# 13.1k -> 12.2k, its simulated L1i misses 716 -> 601; results bit-identical). Each reads every array it takes
# (none under a condition of its own: see stack_step).
@njit(inline=True)
def follower_error(kn, i, pose, est_pose, est_vel, offsets, err):
    """Follower ``i``'s :func:`slot_error` from its leader estimate ``est_pose``, ``est_vel`` and measured ``pose``
    (n, 3), the slot ``offsets`` (n, 2) m, into ``err[i]``; returns ``(x̃, ỹ, θ̃, υ_ref, ω_ref)``."""
    e0, e1, e2, v_ref, w_ref = slot_error(
        est_pose[i, 0], est_pose[i, 1], est_pose[i, 2], est_vel[i, 0], est_vel[i, 1], offsets[i, 0], offsets[i, 1],
        pose[i, 0], pose[i, 1], pose[i, 2], kn.leader_frame,
    )  # fmt: skip
    err[i, 0], err[i, 1], err[i, 2] = e0, e1, e2
    return e0, e1, e2, v_ref, w_ref


@njit(inline=True)
def follower_derivative(kn, i, c, first, fy, fdy, cmd, dcmd):
    """:func:`command_derivative` of the command ``cmd[i, c]`` into ``dcmd[i, c]``, its state ``fy``, ``fdy``
    (n, 2) advanced; ``first``: the first step."""
    fy[i, c], fdy[i, c], dcmd[i, c] = command_derivative(
        fy[i, c], fdy[i, c], cmd[i, c], first, kn.deriv == DERIV_DIFFERENCE, kn.f00, kn.f01, kn.f10, kn.f11, kn.g0,
        kn.g1, kn.dt,
    )  # fmt: skip


@njit(inline=True)
def follower_torques(kn, i, vc, wc, vel, dcmd, c_hat, lim, tau, tau_raw, tau_body, saturated):
    """Follower ``i``'s sliding-mode torques (eqs. 38–39) tracking ``(vc, wc)`` [m/s, rad/s] with
    ``dcmd[i]``, the measured ``vel`` (n, 2) and ``ĉ`` (``c_hat``); then :func:`apply_torque`."""
    r0, r1 = sliding_mode(
        vc, wc, dcmd[i, 0], dcmd[i, 1], vel[i, 0], vel[i, 1], c_hat[i, 0], c_hat[i, 1], kn.ca, kn.cb, kn.tphi
    )
    apply_torque(kn, i, r0, r1, lim, tau, tau_raw, tau_body, saturated)


@njit(inline=True)
def apply_torque(kn, i, r0, r1, lim, tau, tau_raw, tau_body, saturated):
    """Follower ``i``'s commanded wheel torques ``(r0, r1)`` = ``[τ_L, τ_R]`` N·m into ``tau_raw[i]``,
    saturated at ``lim[i]`` (``kn.steer``: steer priority) into ``tau[i]``, ``saturated[i]``, and the
    body torques ``tau_body[i]`` the learner reads (arrays (n, 2), ``saturated`` (n,))."""
    tau_raw[i, 0], tau_raw[i, 1] = r0, r1
    L = lim[i]
    saturated[i] = abs(r0) > L or abs(r1) > L
    t0, t1 = saturate(r0, r1, L, kn.steer)
    tau[i, 0], tau[i, 1] = t0, t1
    tau_body[i, 0] = t0 + t1  # τ_a = τ_L + τ_R
    tau_body[i, 1] = t1 - t0  # τ_b = τ_R − τ_L (design §5)


@njit
def estimator_update(g, s, lp, lv, comm):
    """The distributed estimator (eqs. 12–13) and the neuron (eq. 32) advanced to the next step:
    consensus errors over the graph edges (and the leader for ``a_ir = 1``), one Euler step."""
    kn = knobs(g)
    estimator_consensus(kn, lp[0], lp[1], lp[2], lv[0], lv[1], s.est_pose, s.est_vel, s.p_err, s.v_err, s.est_rate,
                        g.src, g.dst, g.lacc, comm.use, comm.ew, comm.lw, comm.rp, comm.rv)  # fmt: skip
    estimator_advance(kn, s.est_pose, s.est_vel, s.est_rate, s.vs, s.err)


@njit(inline=True)
def estimator_consensus(kn, lx, ly, lth, lv0, lw0, est_pose, est_vel, p_err, v_err, est_rate, src, dst, lacc, use,
                        ew, lw, rp, rv):  # fmt: skip
    """Consensus errors of eqs. 12–13 into ``p_err`` (n,3) and ``v_err`` (n,2): over the graph edges
    ``src ← dst`` (m,), plus ``a_ir (P_ir − P_r)`` for the leader link (``lacc`` (n,); the leader's pose
    ``(lx, ly, lth)``, velocities ``(lv0, lw0)``); from the estimates ``est_pose``, ``est_vel`` before they
    advance; ``use``: the network's delivery (:class:`CommIn`: ``ew``, ``lw``, ``rp``, ``rv``). Then the
    estimator's rates from them into ``est_rate`` (n,5) (``estimator_rates``)."""
    n = est_pose.shape[0]
    for i in range(n):
        for c in range(3):
            p_err[i, c] = 0.0
        for c in range(2):
            v_err[i, c] = 0.0
    for e in range(src.shape[0]):
        i = src[e]
        j = dst[e]
        w = ew[e] if use else 1.0
        for c in range(3):
            xj = rp[e, c] if use else est_pose[j, c]
            d = est_pose[i, c] - xj
            if c == 2:
                d = wrap(d)
            p_err[i, c] += d * w
        for c in range(2):
            xj = rv[e, c] if use else est_vel[j, c]
            v_err[i, c] += (est_vel[i, c] - xj) * w
    for i in range(n):
        a = lacc[i] * lw[i] if use else lacc[i]
        p_err[i, 0] = a * (est_pose[i, 0] - lx) + p_err[i, 0]
        p_err[i, 1] = a * (est_pose[i, 1] - ly) + p_err[i, 1]
        p_err[i, 2] = a * wrap(est_pose[i, 2] - lth) + p_err[i, 2]
        v_err[i, 0] = a * (est_vel[i, 0] - lv0) + v_err[i, 0]
        v_err[i, 1] = a * (est_vel[i, 1] - lw0) + v_err[i, 1]
        est_rate[i, 0], est_rate[i, 1], est_rate[i, 2], est_rate[i, 3], est_rate[i, 4] = estimator_rates(
            est_pose[i, 2], est_vel[i, 0], est_vel[i, 1], p_err[i, 0], p_err[i, 1], p_err[i, 2], v_err[i, 0],
            v_err[i, 1], kn.kx, kn.ky, kn.kth, kn.ka0, kn.ka1, kn.kb0, kn.kb1, kn.ephi0, kn.ephi1,
        )  # fmt: skip


@njit(inline=True)
def estimator_advance(kn, est_pose, est_vel, est_rate, vs, err):
    """One Euler step of the estimator (eqs. 12–13) with the rates :func:`estimator_consensus`
    computed (``est_rate``), and the neuron ``vs`` (eq. 32) for the frozen input ``x̃`` (``err[:, 0]``)."""
    n = est_pose.shape[0]
    dt = kn.dt
    for i in range(n):
        px, py, pth, v, w = estimator_euler(
            est_pose[i, 0], est_pose[i, 1], est_pose[i, 2], est_vel[i, 0], est_vel[i, 1], est_rate[i, 0],
            est_rate[i, 1], est_rate[i, 2], est_rate[i, 3], est_rate[i, 4], dt,
        )  # fmt: skip
        est_pose[i, 0], est_pose[i, 1], est_pose[i, 2] = px, py, pth
        est_vel[i, 0], est_vel[i, 1] = v, w
        if kn.bio:  # neuron (eq. 32), exact for the frozen input x̃
            vs[i] = neuron_step(vs[i], err[i, 0], kn.A, kn.B, kn.D, dt)

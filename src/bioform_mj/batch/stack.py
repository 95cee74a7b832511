"""The control stack's steps as Warp device functions for one world ``w``, written once for the batch
engine's kernels: :func:`~.step._control` (the closed loop) and :func:`~.env._env_sense`/``_env_act``
(the batched environment) call them.

Each is the Warp form of a numba kernel of ``control/kernel.py`` (named in its docstring) or of the
plant glue of ``plants/mujoco/kernels.py``, on the world's rows of :class:`~.device.BatchGains` and
:class:`~.device.BatchState`; the equations are ``core/equations.py``'s, translated by
:mod:`.samesource`. Only loops, indexing and bookkeeping are written here.
"""

from __future__ import annotations

import warp as wp

from bioform_mj.batch.device import (
    A_,
    B_,
    CA,
    CB,
    D_,
    DD0,
    DE0,
    DERIV,
    DERIV_D,
    EPHI0,
    EPHI1,
    F00,
    F01,
    F10,
    F11,
    G0,
    G1,
    K5A,
    KA0,
    KA1,
    KB0,
    KB1,
    KDA,
    KTH,
    KX,
    KY,
    TPHI,
    BatchGains,
    BatchState,
    CommFaults,
    F,
    command_derivative,
    estimator_euler,
    estimator_rates,
    formation_offset,
    harmonic,
    learner_step,
    neuron_step,
    planar_state,
    saturate,
    sliding_mode,
    slot_error,
    wrap,
)


@wp.func
def observe(
    s: BatchState,
    w: int,
    i: int,
    qpos: wp.array2d(dtype=float),
    qvel: wp.array2d(dtype=float),
    qadr: wp.array(dtype=int),
    dadr: wp.array(dtype=int),
    axle: wp.array2d(dtype=F),
) -> F:
    """``mujoco_kernels.observe`` of follower ``i``: its true planar pose and ``[υ, ω]`` at the axle
    point ``axle[i]`` from its free joint (``qpos`` address ``qadr[i]``, ``qvel`` address ``dadr[i]``)
    into ``s.pose[w, i]``, ``s.vel[w, i]``; returns the chassis up-axis' z component (tilt watch)."""
    qa = qadr[i]
    qb = dadr[i]
    x, y, th, v, om, up = planar_state(
        F(qpos[w, qa]),
        F(qpos[w, qa + 1]),
        F(qpos[w, qa + 3]),
        F(qpos[w, qa + 4]),
        F(qpos[w, qa + 5]),
        F(qpos[w, qa + 6]),
        F(qvel[w, qb]),
        F(qvel[w, qb + 1]),
        F(qvel[w, qb + 2]),
        F(qvel[w, qb + 3]),
        F(qvel[w, qb + 4]),
        F(qvel[w, qb + 5]),
        axle[i, 0],
        axle[i, 1],
        axle[i, 2],
    )
    s.pose[w, i, 0] = x
    s.pose[w, i, 1] = y
    s.pose[w, i, 2] = th
    s.vel[w, i, 0] = v
    s.vel[w, i, 1] = om
    return up


@wp.func
def reset(g: BatchGains, s: BatchState, w: int, n: int):
    """``kernel.reset_state`` for world ``w``: the initial estimates (heading wrapped), ``[υ_ir, ω_ir] = 0``,
    ``ẑ`` = the measured velocities ``s.vel``, ``ĉ = clip(ĉ(0))``, the rest of the stack zeroed; the
    world marked running (``s.status = 0``) before its first step (``s.first = 1``)."""
    zero = F(0.0)
    for i in range(n):
        s.est_pose[w, i, 0] = g.est0[w, i, 0]
        s.est_pose[w, i, 1] = g.est0[w, i, 1]
        s.est_pose[w, i, 2] = wrap(g.est0[w, i, 2])
        for c in range(2):
            s.est_vel[w, i, c] = zero
            s.z_hat[w, i, c] = s.vel[w, i, c]
            s.e_int[w, i, c] = zero
            s.c_hat[w, i, c] = wp.min(wp.max(g.c_hat0[w, i, c], g.c_min[w, i, c]), g.c_max[w, i, c])
            s.d_hat[w, i, c] = zero
            s.fy[w, i, c] = zero
            s.fdy[w, i, c] = zero
            s.cmd[w, i, c] = zero
            s.dcmd[w, i, c] = zero
            s.tau[w, i, c] = zero
            s.tau_raw[w, i, c] = zero
            s.tau_body[w, i, c] = zero
        for c in range(3):
            s.err[w, i, c] = zero
        s.vs[w, i] = zero
        s.saturated[w, i] = 0
    s.first[w] = 1
    s.status[w] = 0


@wp.func
def learn(g: BatchGains, s: BatchState, w: int, n: int, dt: F):
    """``kernel.learner_update`` for world ``w``: eq. 37 over the last period with the torques applied
    then (``s.tau_body``) and the velocities measured now (``s.mvel``)."""
    for i in range(n):
        for c in range(2):  # a (k5a, kda), then b (k5b, kdb): adjacent columns of SCALARS
            zn, en, cn, dn = learner_step(
                s.z_hat[w, i, c],
                s.e_int[w, i, c],
                s.c_hat[w, i, c],
                s.d_hat[w, i, c],
                s.tau_body[w, i, c],
                s.mvel[w, i, c],
                g.k4[w, i, c],
                g.sc[w, K5A + c],
                g.sc[w, KDA + c],
                g.c_min[w, i, c],
                g.c_max[w, i, c],
                dt,
            )
            s.z_hat[w, i, c] = zn
            s.e_int[w, i, c] = en
            s.c_hat[w, i, c] = cn
            s.d_hat[w, i, c] = dn


@wp.func
def consensus(
    g: BatchGains,
    s: BatchState,
    f: CommFaults,
    w: int,
    n: int,
    comm: bool,
    recv: bool,
    lp0: F,
    lp1: F,
    lp2: F,
    lv0: F,
    lv1: F,
):
    """``kernel.estimator_consensus`` for world ``w``: the consensus errors ``s.p_err``, ``s.v_err`` of this
    step over the graph edges, plus ``a_ir (P_ir − P_r)`` for the leader link with the leader's state
    ``(lp0, lp1, lp2)``, ``(lv0, lv1)`` as received; then the estimator's rates ``s.est_rate``. On the
    paper's perfect network (``comm`` false) every weight is 1 and the neighbours' estimates are their
    current ones; with network faults (``faults.Faults.comm``) the weights are ``f.ew``, ``f.lw``, and with
    ``recv`` (loss or delay) the neighbours' estimates are those received (``f.hp``, ``f.hv``)."""
    zero = F(0.0)
    for i in range(n):
        for c in range(3):
            s.p_err[w, i, c] = zero
        for c in range(2):
            s.v_err[w, i, c] = zero
    for e in range(g.src.shape[0]):
        i = g.src[e]
        j = g.dst[e]
        we = F(1.0)
        if comm:
            we = f.ew[w, e]
        for c in range(3):
            xj = s.est_pose[w, j, c]
            if recv:
                xj = f.hp[w, e, c]
            d = s.est_pose[w, i, c] - xj
            if c == 2:
                d = wrap(d)
            s.p_err[w, i, c] = s.p_err[w, i, c] + d * we
        for c in range(2):
            xj = s.est_vel[w, j, c]
            if recv:
                xj = f.hv[w, e, c]
            s.v_err[w, i, c] = s.v_err[w, i, c] + (s.est_vel[w, i, c] - xj) * we
    for i in range(n):
        ai = g.lacc[w, i]
        if comm:
            ai = ai * f.lw[w, i]
        s.p_err[w, i, 0] = ai * (s.est_pose[w, i, 0] - lp0) + s.p_err[w, i, 0]
        s.p_err[w, i, 1] = ai * (s.est_pose[w, i, 1] - lp1) + s.p_err[w, i, 1]
        s.p_err[w, i, 2] = ai * wrap(s.est_pose[w, i, 2] - lp2) + s.p_err[w, i, 2]
        s.v_err[w, i, 0] = ai * (s.est_vel[w, i, 0] - lv0) + s.v_err[w, i, 0]
        s.v_err[w, i, 1] = ai * (s.est_vel[w, i, 1] - lv1) + s.v_err[w, i, 1]
        # the estimator's rates from them, once: the analytic derivative and the Euler step both read them
        q0, q1, q2, q3, q4 = estimator_rates(
            s.est_pose[w, i, 2],
            s.est_vel[w, i, 0],
            s.est_vel[w, i, 1],
            s.p_err[w, i, 0],
            s.p_err[w, i, 1],
            s.p_err[w, i, 2],
            s.v_err[w, i, 0],
            s.v_err[w, i, 1],
            g.sc[w, KX],
            g.sc[w, KY],
            g.sc[w, KTH],
            g.sc[w, KA0],
            g.sc[w, KA1],
            g.sc[w, KB0],
            g.sc[w, KB1],
            g.sc[w, EPHI0],
            g.sc[w, EPHI1],
        )
        s.est_rate[w, i, 0] = q0
        s.est_rate[w, i, 1] = q1
        s.est_rate[w, i, 2] = q2
        s.est_rate[w, i, 3] = q3
        s.est_rate[w, i, 4] = q4


@wp.func
def follower_error(g: BatchGains, s: BatchState, w: int, i: int, lframe: bool):
    """``kernel.follower_error`` of follower ``i``: its ``slot_error`` (eqs. 27–28; with ``lframe``, offsets
    in the leader's frame, against the slot's own pose, design §4) from its own leader estimate and its
    measurement ``s.mpose``, into ``s.err[w, i]``. Returns ``(x̃, ỹ, θ̃, υ_ref, ω_ref)``."""
    e0, e1, e2, v_ref, w_ref = slot_error(
        s.est_pose[w, i, 0],
        s.est_pose[w, i, 1],
        s.est_pose[w, i, 2],
        s.est_vel[w, i, 0],
        s.est_vel[w, i, 1],
        g.offsets[w, i, 0],
        g.offsets[w, i, 1],
        s.mpose[w, i, 0],
        s.mpose[w, i, 1],
        s.mpose[w, i, 2],
        lframe,
    )
    s.err[w, i, 0] = e0
    s.err[w, i, 1] = e1
    s.err[w, i, 2] = e2
    return e0, e1, e2, v_ref, w_ref


@wp.func
def follower_derivative(g: BatchGains, s: BatchState, w: int, i: int, c: int, first: bool, dt: F):
    """``kernel.follower_derivative``: the ``command_derivative`` of the command ``s.cmd[w, i, c]`` into
    ``s.dcmd`` by the world's filter or backward difference (its ``deriv`` code, design §6), its state
    ``s.fy``, ``s.fdy`` advanced; ``first``: the world's first step (the state starts at the command)."""
    y, dy, dd = command_derivative(
        s.fy[w, i, c],
        s.fdy[w, i, c],
        s.cmd[w, i, c],
        first,
        g.sc[w, DERIV] == DERIV_D,
        g.sc[w, F00],
        g.sc[w, F01],
        g.sc[w, F10],
        g.sc[w, F11],
        g.sc[w, G0],
        g.sc[w, G1],
        dt,
    )
    s.fy[w, i, c] = y
    s.fdy[w, i, c] = dy
    s.dcmd[w, i, c] = dd


@wp.func
def torque_law(g: BatchGains, s: BatchState, w: int, i: int, vc: F, wc: F):
    """The sliding-mode wheel torques ``[τ_L, τ_R]`` (eqs. 38–39, as in ``kernel.follower_torques``) of follower ``i``
    tracking the command ``(vc, wc)`` with its derivative ``s.dcmd``, the measured ``s.mvel`` and ``ĉ``."""
    r0, r1 = sliding_mode(
        vc,
        wc,
        s.dcmd[w, i, 0],
        s.dcmd[w, i, 1],
        s.mvel[w, i, 0],
        s.mvel[w, i, 1],
        s.c_hat[w, i, 0],
        s.c_hat[w, i, 1],
        g.sc[w, CA],
        g.sc[w, CB],
        g.sc[w, TPHI],
    )
    return r0, r1


@wp.func
def apply_torque(s: BatchState, w: int, i: int, r0: F, r1: F, L: F, steer: bool):
    """``kernel.apply_torque``: the commanded ``[τ_L, τ_R] = (r0, r1)`` N·m into ``s.tau_raw``, saturated
    at ``L`` (``steer``: steer priority) into ``s.tau``, ``s.saturated``, and the body torques
    ``s.tau_body`` (``[τ_L + τ_R, τ_R − τ_L]``, design §5) the learner reads."""
    s.tau_raw[w, i, 0] = r0
    s.tau_raw[w, i, 1] = r1
    sat = wp.int32(0)
    if wp.abs(r0) > L or wp.abs(r1) > L:
        sat = 1
    s.saturated[w, i] = sat
    t0, t1 = saturate(r0, r1, L, steer)
    s.tau[w, i, 0] = t0
    s.tau[w, i, 1] = t1
    s.tau_body[w, i, 0] = t0 + t1
    s.tau_body[w, i, 1] = t1 - t0


@wp.func
def advance(g: BatchGains, s: BatchState, w: int, n: int, dt: F, bio: bool):
    """``kernel.estimator_advance`` for world ``w``: one Euler step of the estimator with this step's
    rates ``s.est_rate``, and with ``bio`` the neuron (eq. 32) for the frozen input ``x̃``."""
    for i in range(n):
        px, py, pth, v, om = estimator_euler(
            s.est_pose[w, i, 0],
            s.est_pose[w, i, 1],
            s.est_pose[w, i, 2],
            s.est_vel[w, i, 0],
            s.est_vel[w, i, 1],
            s.est_rate[w, i, 0],
            s.est_rate[w, i, 1],
            s.est_rate[w, i, 2],
            s.est_rate[w, i, 3],
            s.est_rate[w, i, 4],
            dt,
        )
        s.est_pose[w, i, 0] = px
        s.est_pose[w, i, 1] = py
        s.est_pose[w, i, 2] = pth
        s.est_vel[w, i, 0] = v
        s.est_vel[w, i, 1] = om
        if bio:
            s.vs[w, i] = neuron_step(s.vs[w, i], s.err[w, i, 0], g.sc[w, A_], g.sc[w, B_], g.sc[w, D_], dt)


@wp.func
def formation_error(g: BatchGains, s: BatchState, w: int, i: int, lx: F, ly: F, lth: F, lframe: bool):
    """``engine.record``'s formation error of follower ``i`` into ``s.ferr[w, i]`` (m): the distance of its
    true pose ``s.pose`` from its slot about the true leader at ``(lx, ly)`` m, heading ``lth`` rad (with
    ``lframe``, the offsets in the leader's frame: ``formation_offset``, design §4)."""
    ox, oy = formation_offset(g.offsets[w, i, 0], g.offsets[w, i, 1], lth, lframe)
    dx = s.pose[w, i, 0] - (lx - ox)
    dy = s.pose[w, i, 1] - (ly - oy)
    s.ferr[w, i] = wp.sqrt(dx * dx + dy * dy)


@wp.func
def disturbance(g: BatchGains, w: int, t: F):
    """The eq. 34 disturbance rows of world ``w`` at time ``t`` (s): ``(d_υ(t), d_ω(t))``, the
    accelerations ``mujoco_kernels.apply_inputs`` scales by each robot's effective mass and inertia."""
    d0 = harmonic(g.sc[w, DD0], g.sc[w, DD0 + 1], g.sc[w, DD0 + 2], g.sc[w, DD0 + 3], t)
    d1 = harmonic(g.sc[w, DE0], g.sc[w, DE0 + 1], g.sc[w, DE0 + 2], g.sc[w, DE0 + 3], t)
    return d0, d1

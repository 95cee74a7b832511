"""Compiled pieces of the learning environment's control step (design §20).

The environment runs the paper's distributed estimator for every follower (so each agent's
observation holds what the communication graph gives it), and, in ``action = "velocity"``,
the paper's sliding-mode torque law with the online learner tracking the agent's
``(υ_cmd, ω_cmd)``. Everything here calls the equations of ``core/equations.py`` and the
kernels of ``control/kernel.py`` (written once); only the order differs: the agent, not the
kinematic controller, supplies the velocity command.
"""

from __future__ import annotations

import math

from bioform_mj.control.kernel import (
    apply_torque,
    estimator_advance,
    estimator_consensus,
    follower_derivative,
    follower_error,
    follower_torques,
    knobs,
    learner_update,
)
from bioform_mj.core.equations import njit

# The stack's pieces take the gains' numbers (Knobs) and only the arrays they read (control/kernel.py, issue 28):
# the functions here read each field of Gains and StackState they need once, at their top.
# Counted per environment step (scripts/bench_callgrind_env.py, paper, MuJoCo, 1 ms; session 13): 243 reference
# counts, 175.5 of them in envs/fast.py's mujoco_period (the episode's named tuples read from its PeriodArgs), 43
# in control_phase (one per array of its arguments), none in sense_errors. Tried here and measured worse, so not
# kept: every field bound once at the entries' tops with the torque law, direct torques and Table I's summand as
# inlined helpers taking arrays (243 -> 251 a step); the same with knobs inlined field by
# field so that control_phase calls nothing (43 -> 50): its counts are not the calls' doing.


@njit
def sense_errors(g, s, lp, lv, pose, vel, comm, learn):
    """At control step ``k``: the learner over the last period (``learn``), the estimator's
    consensus with the leader ``lp`` (3,), ``lv`` (2,) through ``a_ir`` and the graph, and each
    follower's tracking error ``s.err`` (n, 3) from its own leader estimate (eqs. 27-28, or the
    slot's own pose for leader-frame offsets, design §4). ``pose`` (n,3), ``vel`` (n,2): measured."""
    kn = knobs(g)
    learner_update(kn, learn and kn.learning and s.first[0] == 0, vel, s.z_hat, s.e_int, s.c_hat, s.d_hat, s.k_hat,
                   s.tau_body, g.k4, g.c_min, g.c_max)  # fmt: skip
    est_pose, est_vel, err, offsets = s.est_pose, s.est_vel, s.err, g.offsets
    estimator_consensus(kn, lp[0], lp[1], lp[2], lv[0], lv[1], est_pose, est_vel, s.p_err, s.v_err, s.est_rate, g.src,
                        g.dst, g.lacc, comm.use, comm.ew, comm.lw, comm.rp, comm.rv)  # fmt: skip
    for i in range(pose.shape[0]):
        follower_error(kn, i, pose, est_pose, est_vel, offsets, err)


@njit
def track_velocity(g, s, vel, cmd):
    """The paper's torque law (eqs. 38-39) tracking the agents' commands ``cmd`` (n, 2)
    ``[υ_cmd m/s, ω_cmd rad/s]`` with ``ĉ``: command derivative by the configured filter (the
    analytic mode of design §6 needs the kinematic law's own dynamics and falls back to the
    filter) or backward difference, sliding mode, saturation; writes ``s.cmd``, ``s.dcmd``,
    ``s.tau_raw``, ``s.tau``, ``s.tau_body``, ``s.saturated``."""
    kn = knobs(g)
    scmd, dcmd, fy, fdy, c_hat, lim = s.cmd, s.dcmd, s.fy, s.fdy, s.c_hat, g.lim
    tau, tau_raw, tau_body, saturated = s.tau, s.tau_raw, s.tau_body, s.saturated
    first = s.first[0] == 1
    for i in range(vel.shape[0]):
        for c in range(2):
            scmd[i, c] = cmd[i, c]
            follower_derivative(kn, i, c, first, fy, fdy, scmd, dcmd)
        follower_torques(kn, i, cmd[i, 0], cmd[i, 1], vel, dcmd, c_hat, lim, tau, tau_raw, tau_body, saturated)
    s.first[0] = 0


@njit
def direct_torque(g, s, tau):
    """``action = "torque"``: the agents' wheel torques ``tau`` (n, 2) N·m, already within the
    action space ``±τ_max``; the same bookkeeping as the torque law (``s.tau_body`` feeds the learner)."""
    kn = knobs(g)
    lim, stau, tau_raw, tau_body, saturated = g.lim, s.tau, s.tau_raw, s.tau_body, s.saturated
    for i in range(tau.shape[0]):
        apply_torque(kn, i, tau[i, 0], tau[i, 1], lim, stau, tau_raw, tau_body, saturated)
    s.first[0] = 0


@njit
def formation_error(pose, lp, off, leader_frame, out):
    """True formation error (n,) m of each follower, written to ``out``: ``|p_i − (p_r − Δ_i)|`` with the
    leader's pose ``lp`` (3,), offsets ``off`` (n, 2) m (rotated by the leader's heading when
    ``leader_frame``); the arithmetic of :func:`bioform_mj.outcomes.slots_of` and ``np.hypot``."""
    c, s_ = math.cos(lp[2]), math.sin(lp[2])
    for i in range(pose.shape[0]):
        ox, oy = off[i, 0], off[i, 1]
        if leader_frame:
            ox, oy = c * ox - s_ * oy, s_ * ox + c * oy
        out[i] = math.hypot(pose[i, 0] - (lp[0] - ox), pose[i, 1] - (lp[1] - oy))


@njit
def velocity_error(verr, cmd, vel):
    """Table I's metric summand: ``verr += |υ_cmd − υ| + |ω_cmd − ω|`` per follower (true velocities)."""
    for i in range(verr.shape[0]):
        verr[i] += abs(cmd[i, 0] - vel[i, 0]) + abs(cmd[i, 1] - vel[i, 1])


@njit
def step_rewards(fe, tau, tau_max, newly, hits, w_form, w_eff, w_tip, w_col, dt, out):
    """Per-agent reward of a period without the terminal term (1/s weights as ``REWARD_WEIGHTS``):
    ``−dt·(w_f·e_i + w_e·((τ_L/τ_max)² + (τ_R/τ_max)²)/2) − w_tip·[tipped now] − w_col·hits_i``;
    a non-finite ``e_i`` counts 0."""
    for i in range(fe.shape[0]):
        e = fe[i] if math.isfinite(fe[i]) else 0.0
        a, b = tau[i, 0] / tau_max[i], tau[i, 1] / tau_max[i]
        eff = (a * a + b * b) / 2.0
        out[i] = -dt * (w_form * e + w_eff * eff) - w_tip * newly[i] - w_col * hits[i]


@njit
def relative(out, j, p, v, own_p, own_v, c, s_):
    """``out[j:j+6] = [1, Δx, Δy, Δθ, Δυ, Δω]`` of ``(p, v)`` minus the own estimate, positions in the
    body frame ``(c, s) = (cos θ, sin θ)``, ``Δθ`` wrapped into [−π, π)."""
    dx, dy = p[0] - own_p[0], p[1] - own_p[1]
    out[j] = 1.0
    out[j + 1] = c * dx + s_ * dy
    out[j + 2] = -s_ * dx + c * dy
    out[j + 3] = (p[2] - own_p[2] + math.pi) % (2 * math.pi) - math.pi
    out[j + 4] = v[0] - own_v[0]
    out[j + 5] = v[1] - own_v[1]


@njit
def observations(out, mp, mv, err, est_pose, est_vel, slots, ew, rp, rv, lacc, lp, lv, bound):
    """Every agent's observation (n, 7 + 6K + 6) into ``out`` (zeroed by the caller), the layout of
    ``OBS_FIELDS``: own velocities ``mv``, slot error ``err``, own leader-estimate velocities, per
    in-neighbour slot (``slots`` (n, K): edge index or −1) the neighbour's estimate as received
    (``rp``, ``rv`` per edge, delivered where ``ew > 0``), the leader where ``lacc > 0``; clipped to ±``bound``."""
    n, K = slots.shape
    for i in range(n):
        o = out[i]
        o[0], o[1] = mv[i, 0], mv[i, 1]
        o[2], o[3], o[4] = err[i, 0], err[i, 1], err[i, 2]
        o[5], o[6] = est_vel[i, 0], est_vel[i, 1]
        c, s_ = math.cos(mp[i, 2]), math.sin(mp[i, 2])
        for q in range(K):
            e = slots[i, q]
            if e >= 0 and ew[e] > 0:
                relative(o, 7 + 6 * q, rp[e], rv[e], est_pose[i], est_vel[i], c, s_)
        if lacc[i] > 0:
            relative(o, 7 + 6 * K, lp, lv, est_pose[i], est_vel[i], c, s_)
        for j in range(o.shape[0]):
            o[j] = min(max(o[j], -bound), bound)


@njit
def actions_within(u, lo, hi):
    """True when every action (n, 2) is finite and within ``[lo, hi]`` (the float32-rounded bounds)."""
    for i in range(u.shape[0]):
        for j in range(u.shape[1]):
            x = u[i, j]
            if not (math.isfinite(x) and lo[i, j] <= x <= hi[i, j]):
                return False
    return True


@njit
def clip_into(u, lo, hi):
    """``u`` (n, 2) clipped onto ``[lo, hi]`` in place (an action within float32 rounding of a bound: onto it)."""
    for i in range(u.shape[0]):
        for j in range(u.shape[1]):
            u[i, j] = min(max(u[i, j], lo[i, j]), hi[i, j])
    return u


@njit
def control_phase(g, s, mv, u, velocity, verr, vel, tau):
    """One call for the period's control (the stack's state is unboxed once, not three times): the
    agents' actions ``u`` (n, 2) through :func:`track_velocity` (``velocity``) or
    :func:`direct_torque`, Table I's summand (:func:`velocity_error`, true ``vel``), the torques
    copied to ``tau`` (n, 2), then the estimator's advance over the period."""
    if velocity:
        track_velocity(g, s, mv, u)
    else:
        direct_torque(g, s, u)
    velocity_error(verr, s.cmd, vel)
    stau = s.tau
    for i in range(tau.shape[0]):
        tau[i, 0] = stau[i, 0]
        tau[i, 1] = stau[i, 1]
    estimator_advance(knobs(g), s.est_pose, s.est_vel, s.est_rate, s.vs, s.err)

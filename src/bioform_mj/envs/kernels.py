"""Compiled pieces of the learning environment's control step (design §20).

The environment runs the paper's distributed estimator for every follower (so each agent's
observation holds what the communication graph gives it), and, in ``action = "velocity"``,
the paper's sliding-mode torque law with the online learner tracking the agent's
``(υ_cmd, ω_cmd)``. Everything here calls the equations of ``control/equations.py`` and the
kernels of ``control/kernel.py`` (written once); only the order differs: the agent, not the
kinematic controller, supplies the velocity command.
"""

from __future__ import annotations

from ..control.equations import (
    backward_difference,
    filter_derivative,
    njit,
    saturate,
    sliding_mode,
    slot_reference,
    tracking_error,
)
from ..control.kernel import DERIV_DIFFERENCE, estimator_consensus, learner_update


@njit
def sense_errors(g, s, lp, lv, pose, vel, comm, learn):
    """At control step ``k``: the learner over the last period (``learn``), the estimator's
    consensus with the leader ``lp`` (3,), ``lv`` (2,) through ``a_ir`` and the graph, and each
    follower's tracking error ``s.err`` (n, 3) from its own leader estimate (eqs. 27-28, or the
    slot's own pose for leader-frame offsets, design §4). ``pose`` (n,3), ``vel`` (n,2): measured."""
    if learn and g.learning and s.first[0] == 0:
        learner_update(g, s, vel)
    estimator_consensus(g, s, lp, lv, comm)
    for i in range(pose.shape[0]):
        if g.leader_frame:
            xs, ys, ths, _v, _w = slot_reference(
                s.est_pose[i, 0],
                s.est_pose[i, 1],
                s.est_pose[i, 2],
                s.est_vel[i, 0],
                s.est_vel[i, 1],
                g.offsets[i, 0],
                g.offsets[i, 1],
            )
            e0, e1, e2 = tracking_error(xs, ys, ths, pose[i, 0], pose[i, 1], pose[i, 2], 0.0, 0.0)
        else:
            e0, e1, e2 = tracking_error(
                s.est_pose[i, 0],
                s.est_pose[i, 1],
                s.est_pose[i, 2],
                pose[i, 0],
                pose[i, 1],
                pose[i, 2],
                g.offsets[i, 0],
                g.offsets[i, 1],
            )
        s.err[i, 0], s.err[i, 1], s.err[i, 2] = e0, e1, e2


@njit
def track_velocity(g, s, vel, cmd):
    """The paper's torque law (eqs. 38-39) tracking the agents' commands ``cmd`` (n, 2)
    ``[υ_cmd m/s, ω_cmd rad/s]`` with ``ĉ``: command derivative by the configured filter (the
    analytic mode of design §6 needs the kinematic law's own dynamics and falls back to the
    filter) or backward difference, sliding mode, saturation; writes ``s.cmd``, ``s.dcmd``,
    ``s.tau_raw``, ``s.tau``, ``s.tau_body``, ``s.saturated``."""
    first = s.first[0] == 1
    for i in range(vel.shape[0]):
        for c in range(2):
            s.cmd[i, c] = cmd[i, c]
            if first:
                s.fy[i, c] = cmd[i, c]
                s.fdy[i, c] = 0.0
            if g.deriv == DERIV_DIFFERENCE:
                s.dcmd[i, c] = backward_difference(cmd[i, c], s.fy[i, c], g.dt)
                s.fy[i, c] = cmd[i, c]
            else:
                y, dy, d = filter_derivative(
                    s.fy[i, c], s.fdy[i, c], cmd[i, c], g.f00, g.f01, g.f10, g.f11, g.g0, g.g1, g.dt
                )
                s.fy[i, c], s.fdy[i, c] = y, dy
                s.dcmd[i, c] = d
        r0, r1 = sliding_mode(
            cmd[i, 0], cmd[i, 1], s.dcmd[i, 0], s.dcmd[i, 1], vel[i, 0], vel[i, 1], s.c_hat[i, 0], s.c_hat[i, 1],
            g.ca, g.cb, g.tphi,
        )  # fmt: skip
        _apply_torque(g, s, i, r0, r1)
    s.first[0] = 0


@njit
def direct_torque(g, s, tau):
    """``action = "torque"``: the agents' wheel torques ``tau`` (n, 2) N·m, already within the
    action space ``±τ_max``; the same bookkeeping as the torque law (``s.tau_body`` feeds the learner)."""
    for i in range(tau.shape[0]):
        _apply_torque(g, s, i, tau[i, 0], tau[i, 1])
    s.first[0] = 0


@njit
def _apply_torque(g, s, i, r0, r1):
    s.tau_raw[i, 0], s.tau_raw[i, 1] = r0, r1
    L = g.lim[i]
    s.saturated[i] = abs(r0) > L or abs(r1) > L
    t0, t1 = saturate(r0, r1, L, g.steer)
    s.tau[i, 0], s.tau[i, 1] = t0, t1
    s.tau_body[i, 0] = t0 + t1  # τ_a = τ_L + τ_R (design §5)
    s.tau_body[i, 1] = t1 - t0  # τ_b = τ_R − τ_L

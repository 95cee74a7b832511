"""Compiled pieces of the learning environment's control step (design §20).

The environment runs the paper's distributed estimator for every follower (so each agent's
observation holds what the communication graph gives it), and, in ``action = "velocity"``,
the paper's sliding-mode torque law with the online learner tracking the agent's
``(υ_cmd, ω_cmd)``. Everything here calls the equations of ``core/equations.py`` and the
kernels of ``control/kernel.py`` (written once); only the order differs: the agent, not the
kinematic controller, supplies the velocity command.
"""

from __future__ import annotations

from bioform_mj.control.kernel import (
    apply_torque,
    estimator_consensus,
    follower_derivative,
    follower_error,
    follower_torques,
    learner_update,
)
from bioform_mj.core.equations import njit


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
        follower_error(g, s, i, pose)


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
            follower_derivative(g, s, i, c, first)
        follower_torques(g, s, i, cmd[i, 0], cmd[i, 1], vel)
    s.first[0] = 0


@njit
def direct_torque(g, s, tau):
    """``action = "torque"``: the agents' wheel torques ``tau`` (n, 2) N·m, already within the
    action space ``±τ_max``; the same bookkeeping as the torque law (``s.tau_body`` feeds the learner)."""
    for i in range(tau.shape[0]):
        apply_torque(g, s, i, tau[i, 0], tau[i, 1])
    s.first[0] = 0

"""Distributed leader estimator (paper eqs. 11–13, SPEC §3).

Follower ``i`` keeps an estimate ``P_ir = [x, y, θ]`` of the leader's pose and
``[υ_ir, ω_ir]`` of its velocities. It reads its neighbours' estimates, and the
leader's true state only if ``a_ir = 1``: locality is built into the sums below,
which run over graph edges (``O(edges)``) and the leader-access vector.
"""
from __future__ import annotations

import numpy as np

from ..graph import Graph
from .common import sat_sign, wrap


def consensus_error(graph: Graph, est: np.ndarray, ref: np.ndarray, angle_cols: tuple[int, ...] = ()) -> np.ndarray:
    """``Σ_j a_ij (X_i − X_j) + a_ir (X_i − X_r)`` for every follower.

    Parameters
    ----------
    est : (n, k) follower estimates ``X_i``.
    ref : (k,) the leader's true value ``X_r`` (only read through ``a_ir``).
    angle_cols : columns holding angles; their differences are wrapped to (−π, π].
    """
    diff = est[graph.src] - est[graph.dst]
    lead = est - ref
    for c in angle_cols:
        diff[:, c] = wrap(diff[:, c])
        lead[:, c] = wrap(lead[:, c])
    out = graph.leader_access[:, None] * lead
    for c in range(est.shape[1]):
        out[:, c] += np.bincount(graph.src, weights=diff[:, c], minlength=graph.n)
    return out


class Estimator:
    """State and update of the distributed estimator for ``n`` followers.

    Parameters
    ----------
    kp : (3,) gains ``k_x, k_y, k_θ`` (1/s) of eq. 12.
    ka : (2,) sign-term gains ``k_a1, k_a2`` (m/s², rad/s²) of eq. 13.
    kb : (2,) linear gains ``k_b1, k_b2`` (1/s) of eq. 13.
    phi : (2,) boundary-layer widths for ``υ`` (m/s) and ``ω`` (rad/s); 0 = the paper's ``sgn``.
    """

    def __init__(self, graph: Graph, kp, ka, kb, phi) -> None:
        self.graph = graph
        self.kp = np.asarray(kp, dtype=float)
        self.ka = np.asarray(ka, dtype=float)
        self.kb = np.asarray(kb, dtype=float)
        self.phi = np.asarray(phi, dtype=float)
        n = graph.n
        self.pose = np.zeros((n, 3))  # P_ir
        self.vel = np.zeros((n, 2))  # [υ_ir, ω_ir]; zero at t = 0 (Remark 5)

    def reset(self, pose0: np.ndarray) -> None:
        """Initial pose estimates (n, 3); velocity estimates start at zero (Remark 5)."""
        self.pose[:] = pose0
        self.pose[:, 2] = wrap(self.pose[:, 2])
        self.vel[:] = 0.0

    def step(self, leader_pose: np.ndarray, leader_vel: np.ndarray, dt: float) -> None:
        """Advance estimates by ``dt`` (s) with explicit Euler, reading the leader at the step start."""
        p_err = consensus_error(self.graph, self.pose, leader_pose, angle_cols=(2,))  # P̃_i
        v_err = consensus_error(self.graph, self.vel, leader_vel)  # [e_iυ, e_iω]
        th = self.pose[:, 2]
        v = self.vel[:, 0]
        dpose = np.empty_like(self.pose)
        dpose[:, 0] = v * np.cos(th) - self.kp[0] * p_err[:, 0]  # eq. 12
        dpose[:, 1] = v * np.sin(th) - self.kp[1] * p_err[:, 1]
        dpose[:, 2] = self.vel[:, 1] - self.kp[2] * p_err[:, 2]
        dvel = np.empty_like(self.vel)
        for c in range(2):  # eq. 13, two channels
            dvel[:, c] = -self.ka[c] * sat_sign(v_err[:, c], float(self.phi[c])) - self.kb[c] * v_err[:, c]
        self.pose += dt * dpose
        self.pose[:, 2] = wrap(self.pose[:, 2])
        self.vel += dt * dvel

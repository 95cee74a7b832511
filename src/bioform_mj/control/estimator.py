"""Distributed leader estimator (paper eqs. 11–13, SPEC §3).

Follower ``i`` keeps an estimate ``P_ir = [x, y, θ]`` of the leader's pose and
``[υ_ir, ω_ir]`` of its velocities. It reads its neighbours' estimates, and the
leader's true state only if ``a_ir = 1``: locality is built into the sums below,
which run over graph edges (``O(edges)``) and the leader-access vector.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..graph import Graph
from .common import sat_sign, wrap


@dataclass
class Comm:
    """What each follower received this control step, for faulty communication.

    The default (no ``Comm``) is the paper's perfect network: follower ``i`` reads
    its neighbours' current estimates and, if ``a_ir = 1``, the leader's current state.

    edge_w : (m,) weight of each graph edge ``src ← dst`` this step (1 = link up, 0 = link down).
    leader_w : (n,) weight of each follower's leader link (multiplies ``a_ir``).
    recv_pose : (m, 3) or None: the pose estimate of ``dst`` as ``src`` last received it
        (delayed or held after packet loss); None = ``dst``'s current estimate.
    recv_vel : (m, 2) or None: the same for the velocity estimates.
    """

    edge_w: np.ndarray
    leader_w: np.ndarray
    recv_pose: np.ndarray | None = None
    recv_vel: np.ndarray | None = None


def consensus_error(graph: Graph, est: np.ndarray, ref: np.ndarray, angle_cols: tuple[int, ...] = (),
                    recv: np.ndarray | None = None, edge_w: np.ndarray | None = None,
                    leader_w: np.ndarray | None = None) -> np.ndarray:
    """``Σ_j a_ij (X_i − X_j) + a_ir (X_i − X_r)`` for every follower.

    Parameters
    ----------
    est : (n, k) follower estimates ``X_i``.
    ref : (k,) the leader's value ``X_r`` (only read through ``a_ir``).
    angle_cols : columns holding angles; their differences are wrapped to (−π, π].
    recv : (m, k) ``X_j`` as received over each edge (default: ``est[dst]``).
    edge_w : (m,) per-edge weights (default 1); leader_w : (n,) leader-link weights (default 1).
    """
    diff = est[graph.src] - (est[graph.dst] if recv is None else recv)
    lead = est - ref
    for c in angle_cols:
        diff[:, c] = wrap(diff[:, c])
        lead[:, c] = wrap(lead[:, c])
    if edge_w is not None:
        diff *= edge_w[:, None]
    acc = graph.leader_access if leader_w is None else graph.leader_access * leader_w
    out = acc[:, None] * lead
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

    def step(self, leader_pose: np.ndarray, leader_vel: np.ndarray, dt: float, comm: Comm | None = None) -> None:
        """Advance estimates by ``dt`` (s) with explicit Euler, reading the leader at the step start.

        ``comm`` (optional) describes a faulty network this step (see :class:`Comm`).
        """
        if comm is None:
            p_err = consensus_error(self.graph, self.pose, leader_pose, angle_cols=(2,))  # P̃_i
            v_err = consensus_error(self.graph, self.vel, leader_vel)  # [e_iυ, e_iω]
        else:
            p_err = consensus_error(self.graph, self.pose, leader_pose, (2,), comm.recv_pose, comm.edge_w, comm.leader_w)
            v_err = consensus_error(self.graph, self.vel, leader_vel, (), comm.recv_vel, comm.edge_w, comm.leader_w)
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

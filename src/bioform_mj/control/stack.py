"""One vectorised control step of the whole stack, for any plant.

Order within a step at time ``t_k`` (inputs: leader state at ``t_k`` for the
leader-connected followers, measured poses and velocities at ``t_k``):

1. learner: backward-Euler step over ``(t_{k−1}, t_k]`` with the torques applied
   then and the velocities measured now (learning methods only);
2. kinematics: tracking error from the current estimates, ``[υ_cmd, ω_cmd]``
   from the current neuron state ``V_s`` (so ``υ_cmd(0) = 0`` for the bioinspired law);
3. filtered command derivative;
4. sliding-mode torques with ``ĉ``, saturated at the actuator limits;
5. estimator and neuron advance to ``t_{k+1}``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..graph import Graph
from .estimator import Comm, Estimator
from .kinematic import shunting_step, tracking_error, velocity_command
from .learning import Learner
from .torque import DerivativeFilter, saturate, sliding_mode_torques, wheel_to_body

METHODS = ("backstepping", "bioinspired", "backstepping-learning", "bioinspired-learning")


def parse_method(method: str) -> tuple[str, bool]:
    """``'bioinspired-learning'`` → ``('bioinspired', True)``; ValueError if unknown."""
    if method not in METHODS:
        raise ValueError(f"unknown method '{method}' (expected one of: {', '.join(METHODS)})")
    law, _, learn = method.partition("-")
    return law, bool(learn)


@dataclass(frozen=True)
class StackParams:
    """Numbers of the control stack, already resolved per follower. Units in brackets.

    offsets (n,2) [m]: formation offsets ``(Δx, Δy)`` in the world frame.
    kp (3,) [1/s], ka (2,) [m/s², rad/s²], kb (2,) [1/s], est_phi (2,) [m/s, rad/s]: estimator.
    k1 [1/s], k2 [1/m²·…], k3 [1/m]: kinematic gains of eq. 31; A, B, D: neuron (eq. 32).
    law: 'bioinspired' or 'backstepping'; learning: run eq. 37 or keep ``ĉ = ĉ(0)``.
    c_gain (2,) [m/s², rad/s²]: ``c_a, c_b``; torque_phi: boundary layer of eqs. 38–39 (0 = sgn).
    tau_max (n,) [N·m]: wheel torque limit; steer_priority: keep τ_b when saturating; deriv_wn [rad/s]: command-derivative filter.
    k4 (2,) or (n,2), k5 (2,) [1/s]: learner gains; kd (2,): disturbance-estimate gain (0 = the paper); c_hat0, c_min, c_max (n,2): initial estimate and bounds.
    dt [s]: control period.
    """

    offsets: np.ndarray
    kp: np.ndarray
    ka: np.ndarray
    kb: np.ndarray
    est_phi: np.ndarray
    k1: float
    k2: float
    k3: float
    A: float
    B: float
    D: float
    law: str
    learning: bool
    c_gain: np.ndarray
    torque_phi: float
    tau_max: np.ndarray
    steer_priority: bool
    deriv_wn: float
    k4: np.ndarray
    k5: np.ndarray
    kd: np.ndarray
    c_hat0: np.ndarray
    c_min: np.ndarray
    c_max: np.ndarray
    dt: float


class ControlStack:
    """The distributed formation controller of all ``n`` followers.

    Knows nothing of the plant: it maps measured ``pose`` (n,3) and ``vel`` (n,2)
    to wheel torques ``[τ_L, τ_R]`` (n,2). Every intermediate signal of the last
    step is kept as an attribute for logging.
    """

    def __init__(self, graph: Graph, p: StackParams) -> None:
        n = graph.n
        self.n = n
        self.p = p
        self.estimator = Estimator(graph, p.kp, p.ka, p.kb, p.est_phi)
        self.learner = Learner(n, p.k4, p.k5, p.c_min, p.c_max, p.kd)
        self.dfilter = DerivativeFilter(n, p.deriv_wn, p.dt)
        self.vs = np.zeros(n)
        self.err = np.zeros((n, 3))
        self.cmd = np.zeros((n, 2))
        self.dcmd = np.zeros((n, 2))
        self.tau = np.zeros((n, 2))  # applied (saturated) [τ_L, τ_R]
        self.tau_raw = np.zeros((n, 2))  # before saturation
        self._lim = np.asarray(p.tau_max, dtype=float)[:, None]
        self.tau_body = np.zeros((n, 2))
        self.saturated = np.zeros(n, dtype=bool)
        self._first = True

    @property
    def c_hat(self) -> np.ndarray:
        """Current ``[â, b̂]`` (n, 2)."""
        return self.learner.c_hat

    def set_tau_max(self, tau_max: np.ndarray) -> None:
        """Change the wheel torque limits (n,) N·m in place (e.g. an actuator fault mid-run)."""
        self._lim[:, 0] = tau_max

    def reset(self, est_pose0: np.ndarray, vel0: np.ndarray) -> None:
        """Initial estimates ``P_ir(0)`` (n,3), measured velocities (n,2); ``V_s(0) = 0``."""
        self.estimator.reset(est_pose0)
        self.learner.reset(vel0, self.p.c_hat0)
        self.vs[:] = 0.0
        self.tau[:] = 0.0
        self.tau_body[:] = 0.0
        self._first = True

    def step(self, leader_pose: np.ndarray, leader_vel: np.ndarray, pose: np.ndarray, vel: np.ndarray,
             comm: Comm | None = None) -> np.ndarray:
        """Torques ``[τ_L, τ_R]`` (n, 2, N·m) to hold over the next control period.

        ``comm`` (optional): link weights and received neighbour estimates of a faulty
        network for this step's estimator update; None = the paper's perfect network.
        """
        p = self.p
        if p.learning and not self._first:
            self.learner.step(self.tau_body, vel, p.dt)
        est = self.estimator
        self.err = err = tracking_error(est.pose, pose, p.offsets)
        u = self.vs if p.law == "bioinspired" else err[:, 0]
        self.cmd = velocity_command(err, est.vel, u, p.k1, p.k2, p.k3)
        if self._first:
            self.dfilter.reset(self.cmd)
            self._first = False
        self.dcmd = self.dfilter.step(self.cmd)
        self.tau_raw = sliding_mode_torques(self.cmd, self.dcmd, vel, self.learner.c_hat, p.c_gain, p.torque_phi)
        self.saturated = np.any(np.abs(self.tau_raw) > self._lim, axis=1)
        self.tau = saturate(self.tau_raw, self._lim, p.steer_priority)
        self.tau_body = wheel_to_body(self.tau)
        est.step(leader_pose, leader_vel, p.dt, comm)
        if p.law == "bioinspired":
            self.vs = shunting_step(self.vs, err[:, 0], p.A, p.B, p.D, p.dt)
        return self.tau

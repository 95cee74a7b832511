"""Vectorised numpy forms of the control equations: independent test oracles only.

These are the numpy implementations the project shipped before the equations were
written once (src/bioform_mj/core/equations.py). They are kept here, outside the
package, to check the compiled equations against a second, independent reading of the
paper, with stated tolerances (numpy and libm may differ in the last bit, and do on
CPUs with AVX-512).
"""

from __future__ import annotations

import math

import numpy as np

from bioform_mj.control.base import Comm
from bioform_mj.formation.graph import Graph

TWO_PI = 2.0 * np.pi


def wrap(angle: np.ndarray | float) -> np.ndarray:
    """Wrap angles (rad) to (−π, π]. design §3: every heading difference is wrapped."""
    return np.pi - np.mod(np.pi - np.asarray(angle, dtype=float), TWO_PI)


def sat_sign(x: np.ndarray, phi: float) -> np.ndarray:
    """``sgn(x)`` for ``phi == 0`` (the paper), else the boundary layer ``clip(x/phi, −1, 1)``.

    ``phi`` has the units of ``x``. In discrete time with step ``dt`` a term
    ``−k·sat(x/phi)`` is stable only while ``k·dt/phi < 2``.
    """
    if phi == 0.0:
        return np.sign(x)
    return np.clip(x / phi, -1.0, 1.0)


def consensus_error(
    graph: Graph,
    est: np.ndarray,
    ref: np.ndarray,
    angle_cols: tuple[int, ...] = (),
    recv: np.ndarray | None = None,
    edge_w: np.ndarray | None = None,
    leader_w: np.ndarray | None = None,
) -> np.ndarray:
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
            p_err = consensus_error(
                self.graph, self.pose, leader_pose, (2,), comm.recv_pose, comm.edge_w, comm.leader_w
            )
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


def tracking_error(est_pose: np.ndarray, pose: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Body-frame tracking error ``[x̃, ỹ, θ̃]`` (n, 3) of eqs. 27–28 (m, m, rad).

    ``e_x = x_ir − x_i − Δx_i``, ``e_y = y_ir − y_i − Δy_i`` (world-frame offsets),
    ``e_θ = θ_ir − θ_i`` wrapped to (−π, π].
    """
    ex = est_pose[:, 0] - pose[:, 0] - offsets[:, 0]
    ey = est_pose[:, 1] - pose[:, 1] - offsets[:, 1]
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    out = np.empty_like(pose)
    out[:, 0] = c * ex + s * ey
    out[:, 1] = -s * ex + c * ey
    out[:, 2] = wrap(est_pose[:, 2] - pose[:, 2])
    return out


def shunting_step(vs: np.ndarray, x: np.ndarray, A: float, B: float, D: float, dt: float) -> np.ndarray:
    """Advance the shunting neuron (eq. 32) by ``dt`` (s) for a frozen input ``x``.

    ``V̇ = −A V + (B − V) f(x) − (D + V) g(x)``, ``f = max(x, 0)``, ``g = max(−x, 0)``
    (the paper's ``V_s1`` is a typo for ``V_si``). For frozen ``x`` the equation is
    linear in ``V`` and is integrated exactly, so ``V`` stays in ``(−D, B)`` for any
    step size and input.
    """
    f = np.maximum(x, 0.0)
    g = np.maximum(-x, 0.0)
    lam = A + f + g
    v_inf = (B * f - D * g) / lam
    return v_inf + (vs - v_inf) * np.exp(-lam * dt)


def velocity_command(
    err: np.ndarray, est_vel: np.ndarray, u: np.ndarray, k1: float, k2: float, k3: float
) -> np.ndarray:
    """``[υ_cmd, ω_cmd]`` (n, 2) of eq. 31.

    ``υ_cmd = υ_ir cos θ̃ + k1 u``, ``ω_cmd = ω_ir + k2 υ_ir ỹ + k3 υ_ir sin θ̃``, with
    ``u = V_s`` (bioinspired) or ``u = x̃`` (conventional backstepping).
    """
    v_ir = est_vel[:, 0]
    out = np.empty((err.shape[0], 2))
    out[:, 0] = v_ir * np.cos(err[:, 2]) + k1 * u
    out[:, 1] = est_vel[:, 1] + k2 * v_ir * err[:, 1] + k3 * v_ir * np.sin(err[:, 2])
    return out


class Learner:
    """Learner state for ``n`` followers; arrays (n, 2) with columns ``[υ-channel, ω-channel]``.

    Parameters
    ----------
    k4, k5 : (2,) diagonal gains of eq. 37 (1/s).
    c_min, c_max : (n, 2) projection bounds of ``ĉ``.
    """

    def __init__(self, n: int, k4, k5, c_min: np.ndarray, c_max: np.ndarray, kd=(0.0, 0.0)) -> None:
        self.k4 = np.asarray(k4, dtype=float)
        self.k5 = np.asarray(k5, dtype=float)
        self.kd = np.asarray(kd, dtype=float)
        self.d_hat = np.zeros((n, 2))
        self.c_min = np.broadcast_to(np.asarray(c_min, dtype=float), (n, 2)).copy()
        self.c_max = np.broadcast_to(np.asarray(c_max, dtype=float), (n, 2)).copy()
        self.z_hat = np.zeros((n, 2))
        self.e_int = np.zeros((n, 2))
        self.c_hat = np.zeros((n, 2))

    def reset(self, z0: np.ndarray, c_hat0: np.ndarray) -> None:
        """Start with ``ẑ = z0`` (measured velocities), ``∫e = 0`` and ``ĉ = ĉ0``."""
        self.z_hat[:] = z0
        self.e_int[:] = 0.0
        self.c_hat[:] = np.clip(c_hat0, self.c_min, self.c_max)
        self.d_hat[:] = 0.0

    def step(self, tau: np.ndarray, z: np.ndarray, dt: float) -> None:
        """One backward-Euler step of eq. 37 over ``dt`` (s).

        ``tau`` (n, 2) are ``[τ_a, τ_b]`` (N·m) actually applied during the step,
        ``z`` (n, 2) the velocities measured at its end (so the implicit step uses
        them consistently).
        """
        h, k4, k5, kd = dt, self.k4, self.k5, self.kd
        # Unknowns at the step end: ẑ, E = R + h ẑ, S = S0 + S1 ẑ, ĉ = P − Q ẑ, d̂ = Pd − Qd ẑ.
        R = self.e_int - h * z
        S0 = k4 * R - z
        S1 = 1.0 + h * k4
        hk4t = h * k4 * tau
        P = self.c_hat - hk4t * S0
        Q = hk4t * S1
        Pd = self.d_hat - h * kd * S0
        Qd = h * kd * S1
        den = 1.0 + h * k4 + h * k5 * S1 + h * tau * Q + h * Qd
        z_new = (self.z_hat + h * (tau * P + Pd + k4 * z - k5 * S0)) / den
        self.z_hat = z_new
        self.e_int = R + h * z_new
        self.c_hat = np.clip(P - Q * z_new, self.c_min, self.c_max)  # projection onto the bounds
        self.d_hat = Pd - Qd * z_new


class DerivativeFilter:
    """Critically damped second-order filter giving a smooth derivative of ``[υ_cmd, ω_cmd]``.

    ``ÿ_f = ω_n² (u − y_f) − 2 ω_n ẏ_f``; the derivative estimate is the output's change over
    the step, ``(y_f[k+1] − y_f[k])/dt`` (tends to the backward difference as ``ω_n → ∞``). It is
    discretised exactly (zero-order hold on ``u``), so it is stable for every step.
    The paper does not say how ``υ̇_cmd, ω̇_cmd`` are obtained (design §6); a raw
    difference of a signal that carries the estimator's sign term would turn its
    chatter into torque chatter. Its gain to an alternating input (period ``2 dt``)
    is about ``ω_n² dt / 2``, against ``1/dt`` for a raw difference.

    Parameters
    ----------
    wn : natural frequency (rad/s); the derivative lags by about ``2/ω_n`` s.
    dt : control period (s).
    """

    def __init__(self, n: int, wn: float, dt: float) -> None:
        a = math.exp(-wn * dt)
        # Exact discretisation of x' = [[0, 1], [-wn², -2wn]] x + [0, wn²] u.
        self.phi = np.array([[a * (1 + wn * dt), a * dt], [-(wn**2) * dt * a, a * (1 - wn * dt)]])
        self.gam = np.array([1.0 - a * (1 + wn * dt), wn * wn * dt * a])
        self.dt = dt
        self.y = np.zeros((n, 2))
        self.dy = np.zeros((n, 2))

    def reset(self, u0: np.ndarray) -> None:
        """Start at rest on ``u0`` (n, 2): the first derivative estimate is 0."""
        self.y[:] = u0
        self.dy[:] = 0.0

    def step(self, u: np.ndarray) -> np.ndarray:
        """Feed ``u`` (n, 2) held over the next step; returns the derivative estimate (n, 2)."""
        p, g = self.phi, self.gam
        y = p[0, 0] * self.y + p[0, 1] * self.dy + g[0] * u
        self.dy = p[1, 0] * self.y + p[1, 1] * self.dy + g[1] * u
        d = (y - self.y) / self.dt
        self.y = y
        return d


class BackwardDifference:
    """``(u[k] − u[k−1])/dt`` of ``[υ_cmd, ω_cmd]`` (``torque.derivative = "difference"``)."""

    def __init__(self, n: int, dt: float) -> None:
        self.dt = dt
        self.prev = np.zeros((n, 2))

    def reset(self, u0: np.ndarray) -> None:
        self.prev = np.array(u0, dtype=float)

    def step(self, u: np.ndarray) -> np.ndarray:
        d = (u - self.prev) / self.dt
        self.prev = np.array(u, dtype=float)
        return d


def sliding_mode_torques(
    cmd: np.ndarray, dcmd: np.ndarray, vel: np.ndarray, c_hat: np.ndarray, c_gain: np.ndarray, phi: float
) -> np.ndarray:
    """Unsaturated wheel torques ``[τ_L, τ_R]`` (n, 2) in N·m from eqs. 38–39.

    ``U = ż_cmd + c ⊙ sgn(z_cmd − z)``; ``τ_L = U_a/(2â) − U_b/(2b̂)``,
    ``τ_R = U_a/(2â) + U_b/(2b̂)``. This pairs with ``τ_b = τ_R − τ_L`` (design §5's
    sign fix; with the paper's ``τ_b = τ_L − τ_R`` eq. 39 would push ``ω`` away from ``ω_cmd``).
    """
    u = dcmd + c_gain * sat_sign(cmd - vel, phi)
    half_a = u[:, 0] / (2.0 * c_hat[:, 0])
    half_b = u[:, 1] / (2.0 * c_hat[:, 1])
    tau = np.empty_like(cmd)
    tau[:, 0] = half_a - half_b
    tau[:, 1] = half_a + half_b
    return tau


def saturate(tau: np.ndarray, lim: np.ndarray, steer_priority: bool) -> np.ndarray:
    """Clip wheel torques ``[τ_L, τ_R]`` (n, 2) to ``±lim`` (n, 1) N·m.

    ``steer_priority=False`` clips each wheel on its own, which also clips the
    differential torque: a large common-mode command (the ``c_a sgn`` term at a
    poor ``â``) then leaves no torque to turn with. ``steer_priority=True`` keeps
    ``τ_b = τ_R − τ_L`` (clipped to ``±2 lim``) and gives ``τ_a`` what remains,
    ``|τ_a| ≤ 2 lim − |τ_b|``; both results lie within the wheel limits.
    """
    if not steer_priority:
        return np.clip(tau, -lim, lim)
    lim1 = lim[:, 0]
    tb = np.clip(tau[:, 1] - tau[:, 0], -2.0 * lim1, 2.0 * lim1)
    room = 2.0 * lim1 - np.abs(tb)
    ta = np.clip(tau[:, 0] + tau[:, 1], -room, room)
    out = np.empty_like(tau)
    out[:, 0] = 0.5 * (ta - tb)
    out[:, 1] = 0.5 * (ta + tb)
    return out


def wheel_to_body(tau: np.ndarray) -> np.ndarray:
    """``[τ_L, τ_R]`` → ``[τ_a, τ_b] = [τ_L + τ_R, τ_R − τ_L]`` (n, 2), design §5."""
    out = np.empty_like(tau)
    out[:, 0] = tau[:, 0] + tau[:, 1]
    out[:, 1] = tau[:, 1] - tau[:, 0]
    return out


class OracleStack:
    """The whole control step in numpy (the pre-refactor ``ControlStack``), same order as the kernel."""

    def __init__(self, graph: Graph, p) -> None:
        n = graph.n
        self.n = n
        self.p = p
        self.estimator = Estimator(graph, p.kp, p.ka, p.kb, p.est_phi)
        self.learner = Learner(n, p.k4, p.k5, p.c_min, p.c_max, p.kd)
        mode = getattr(p, "derivative", "filter")
        if mode == "analytic":
            raise NotImplementedError("the oracle has no analytic command derivative (tests compare it otherwise)")
        self.dfilter = DerivativeFilter(n, p.deriv_wn, p.dt) if mode == "filter" else BackwardDifference(n, p.dt)
        self.vs = np.zeros(n)
        self.tau = np.zeros((n, 2))
        self._lim = np.asarray(p.tau_max, dtype=float)[:, None].copy()
        self.tau_body = np.zeros((n, 2))
        self._first = True

    @property
    def c_hat(self):
        return self.learner.c_hat

    def reset(self, est_pose0, vel0) -> None:
        self.estimator.reset(est_pose0)
        self.learner.reset(vel0, self.p.c_hat0)
        self.vs[:] = 0.0
        self.tau[:] = 0.0
        self.tau_body[:] = 0.0
        self._first = True

    def step(self, leader_pose, leader_vel, pose, vel, comm=None):
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


def ideal_rk4_step(x, tau, c, dist, t, dt, n_sub):
    """The ideal plant's RK4 over one control period, numpy (the pre-refactor ``IdealPlant.step``)."""
    acc = wheel_to_body(tau) * c
    h = dt / n_sub

    def f(x, t):
        d = np.array([dist[k, 0] + dist[k, 1] * np.cos(dist[k, 2] * t + dist[k, 3]) for k in range(2)])
        dx = np.empty_like(x)
        dx[:, 0] = x[:, 3] * np.cos(x[:, 2])
        dx[:, 1] = x[:, 3] * np.sin(x[:, 2])
        dx[:, 2] = x[:, 4]
        dx[:, 3:] = acc + d
        return dx

    for k in range(n_sub):
        tk = t + k * h
        k1 = f(x, tk)
        k2 = f(x + 0.5 * h * k1, tk + 0.5 * h)
        k3 = f(x + 0.5 * h * k2, tk + 0.5 * h)
        k4 = f(x + h * k3, tk + h)
        x = x + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
    x[:, 2] = wrap(x[:, 2])
    return x

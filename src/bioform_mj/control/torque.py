"""Sliding-mode torque law (eqs. 38–39, SPEC §6) and the command-derivative filter."""
from __future__ import annotations

import math

import numpy as np

from .common import sat_sign


class DerivativeFilter:
    """Critically damped second-order filter giving a smooth derivative of ``[υ_cmd, ω_cmd]``.

    ``ÿ_f = ω_n² (u − y_f) − 2 ω_n ẏ_f``; the derivative estimate is ``ẏ_f``. It is
    discretised exactly (zero-order hold on ``u``), so it is stable for every step.
    The paper does not say how ``υ̇_cmd, ω̇_cmd`` are obtained (SPEC §6); a raw
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
        self.phi = np.array(
            [[a * (1 + wn * dt), a * dt], [-(wn**2) * dt * a, a * (1 - wn * dt)]]
        )
        self.gam = np.array([1.0 - a * (1 + wn * dt), wn * wn * dt * a])
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
        self.y = y
        return self.dy


def sliding_mode_torques(
    cmd: np.ndarray, dcmd: np.ndarray, vel: np.ndarray, c_hat: np.ndarray, c_gain: np.ndarray, phi: float
) -> np.ndarray:
    """Unsaturated wheel torques ``[τ_L, τ_R]`` (n, 2) in N·m from eqs. 38–39.

    ``U = ż_cmd + c ⊙ sgn(z_cmd − z)``; ``τ_L = U_a/(2â) − U_b/(2b̂)``,
    ``τ_R = U_a/(2â) + U_b/(2b̂)``. This pairs with ``τ_b = τ_R − τ_L`` (SPEC §5's
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
    """``[τ_L, τ_R]`` → ``[τ_a, τ_b] = [τ_L + τ_R, τ_R − τ_L]`` (n, 2), SPEC §5."""
    out = np.empty_like(tau)
    out[:, 0] = tau[:, 0] + tau[:, 1]
    out[:, 1] = tau[:, 1] - tau[:, 0]
    return out

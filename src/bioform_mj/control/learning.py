"""Online learner of ``c = [a, b]`` (eq. 37, SPEC §5), integrated implicitly.

Per follower and channel (``υ`` with ``τ_a``, ``ω`` with ``τ_b``), with scalars
``k4, k5`` and the measured velocity ``z``::

    e  = ẑ − z,   E = ∫ e dt,   S = k4 E + e
    ẑ' = τ ĉ − k4 e − k5 S,     E' = e,     ĉ' = −τ k4 S

For a frozen ``τ`` this is linear in ``(ẑ, E, ĉ)``; explicit Euler diverges once
``|τ|`` exceeds about ``sqrt(k5/(k4 dt))`` (SPEC §8), so each step is one
backward-Euler solve, done in closed form (A-stable for any ``τ`` and ``dt``).
``ĉ`` is then projected onto ``[c_min, c_max]`` because it divides in eqs. 38–39.

Extension (not in the paper, off by default): with ``kd > 0`` the learner also
estimates the disturbance, ``ẑ' = τ ĉ + d̂ − k4 e − k5 S``, ``d̂' = −kd S``; the
Lyapunov function ``S²/2 + c̃²/(2 k4) + d̃²/(2 kd)`` still decreases as ``−k5 S²``
for a constant ``d``. Without it a constant ``d`` and a slowly varying ``τ`` leave
``ĉ`` biased by about ``E[τ d]/E[τ²]`` (SPEC §8).
"""
from __future__ import annotations

import numpy as np


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

"""Online learner of ``c = [a, b]`` (eq. 37, SPEC §5), integrated implicitly.

Per follower and channel (``υ`` with ``τ_a``, ``ω`` with ``τ_b``), with scalars
``k4, k5`` and the measured velocity ``z``::

    e  = ẑ − z,   E = ∫ e dt,   S = k4 E + e
    ẑ' = τ ĉ − k4 e − k5 S,     E' = e,     ĉ' = −τ k4 S

For a frozen ``τ`` this is linear in ``(ẑ, E, ĉ)``; explicit Euler diverges once
``|τ|`` exceeds about ``sqrt(k5/(k4 dt))`` (SPEC §8), so each step is one
backward-Euler solve, done in closed form (A-stable for any ``τ`` and ``dt``).
``ĉ`` is then projected onto ``[c_min, c_max]`` because it divides in eqs. 38–39.
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

    def __init__(self, n: int, k4, k5, c_min: np.ndarray, c_max: np.ndarray) -> None:
        self.k4 = np.asarray(k4, dtype=float)
        self.k5 = np.asarray(k5, dtype=float)
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

    def step(self, tau: np.ndarray, z: np.ndarray, dt: float) -> None:
        """One backward-Euler step of eq. 37 over ``dt`` (s).

        ``tau`` (n, 2) are ``[τ_a, τ_b]`` (N·m) actually applied during the step,
        ``z`` (n, 2) the velocities measured at its end (so the implicit step uses
        them consistently).
        """
        h, k4, k5 = dt, self.k4, self.k5
        z_hat0, e0, c0 = self.z_hat, self.e_int, self.c_hat
        # Eliminate E = R + h ẑ and ĉ = P − Q ẑ, then solve for ẑ.
        R = e0 - h * z
        hk4t = h * k4 * tau
        P = c0 + hk4t * (z - k4 * e0 + h * k4 * z)
        Q = hk4t * (1.0 + h * k4)
        den = 1.0 + h * (k4 + k5) + h * h * k4 * k5 + h * tau * Q
        z_new = (z_hat0 + h * (k4 + k5) * z - h * k4 * k5 * R + h * tau * P) / den
        self.z_hat = z_new
        self.e_int = R + h * z_new
        self.c_hat = np.clip(P - Q * z_new, self.c_min, self.c_max)  # projection onto the bounds

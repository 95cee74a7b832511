"""The paper's idealised plant: unicycle kinematics with ``ż = diag(τ_a, τ_b) c + d`` (eq. 34)."""
from __future__ import annotations

import numpy as np

from ..control.common import wrap
from ..control.torque import wheel_to_body
from .base import DisturbanceFn


class IdealPlant:
    """``n`` unicycles with first-order velocity dynamics, integrated by RK4.

    Parameters
    ----------
    c : (n, 2) true ``[a, b]`` (1/(kg·m), 1/(kg·m²)·m); the paper uses (0.4, 10).
    initial_poses : (n, 3) ``[x, y, θ]`` (m, m, rad).
    control_dt : control period (s); physics_dt : RK4 step (s), dividing it.
    disturbance : ``d(t)`` → (n, 2) accelerations.
    mass, inertia : (n,) only used by :meth:`add_payload`, to rescale ``c``.
    """

    def __init__(
        self,
        c: np.ndarray,
        initial_poses: np.ndarray,
        control_dt: float,
        physics_dt: float,
        disturbance: DisturbanceFn,
        mass: np.ndarray | None = None,
        inertia: np.ndarray | None = None,
    ) -> None:
        self.n = len(initial_poses)
        self.control_dt = control_dt
        self.n_substeps = max(1, round(control_dt / physics_dt))
        self.h = control_dt / self.n_substeps
        self._c = np.array(np.broadcast_to(c, (self.n, 2)), dtype=float)
        self.initial_poses = np.array(initial_poses, dtype=float)
        self.disturbance = disturbance
        self.mass = None if mass is None else np.array(np.broadcast_to(mass, (self.n,)), dtype=float)
        self.inertia = None if inertia is None else np.array(np.broadcast_to(inertia, (self.n,)), dtype=float)
        self.x = np.zeros((self.n, 5))  # [x, y, θ, υ, ω]
        self.reset()

    def reset(self) -> None:
        self.x[:, :3] = self.initial_poses
        self.x[:, 2] = wrap(self.x[:, 2])
        self.x[:, 3:] = 0.0

    def observe(self) -> tuple[np.ndarray, np.ndarray]:
        return self.x[:, :3].copy(), self.x[:, 3:].copy()

    def c_true(self) -> np.ndarray:
        return self._c.copy()

    def _f(self, x: np.ndarray, acc: np.ndarray, t: float) -> np.ndarray:
        dx = np.empty_like(x)
        dx[:, 0] = x[:, 3] * np.cos(x[:, 2])
        dx[:, 1] = x[:, 3] * np.sin(x[:, 2])
        dx[:, 2] = x[:, 4]
        dx[:, 3:] = acc + self.disturbance(t)
        return dx

    def step(self, tau: np.ndarray, t: float) -> None:
        acc = wheel_to_body(tau) * self._c  # diag(τ_a, τ_b) c
        h = self.h
        x = self.x
        for k in range(self.n_substeps):
            tk = t + k * h
            k1 = self._f(x, acc, tk)
            k2 = self._f(x + 0.5 * h * k1, acc, tk + 0.5 * h)
            k3 = self._f(x + 0.5 * h * k2, acc, tk + 0.5 * h)
            k4 = self._f(x + h * k3, acc, tk + h)
            x = x + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
        x[:, 2] = wrap(x[:, 2])
        self.x = x

    def set_leader(self, pose: np.ndarray, slots: np.ndarray | None) -> None:
        """Nothing to show on the ideal plant."""

    def add_payload(self, i: int, mass_kg: float, inertia_kgm2: float) -> None:
        """Scale ``c_i`` as ``a ∝ 1/m``, ``b ∝ 1/I`` (needs ``mass`` and ``inertia``)."""
        if self.mass is None or self.inertia is None:
            raise ValueError("the ideal plant needs robot mass and inertia to add a payload")
        m0, i0 = self.mass[i], self.inertia[i]
        self.mass[i] += mass_kg
        self.inertia[i] += inertia_kgm2
        self._c[i, 0] *= m0 / self.mass[i]
        self._c[i, 1] *= i0 / self.inertia[i]

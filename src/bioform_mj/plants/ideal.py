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
        self._push_until: np.ndarray | None = None  # pushes (faults): see push()

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
        if self._push_until is not None:  # faults: an external push (push())
            acc = acc + self._push_acc(t)
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

    # ------------------------------------------------------------------ faults
    def push(self, i: int, force_xy, torque_z: float, until_t: float) -> None:
        """Push follower ``i`` (0-based) with a world-frame force ``force_xy`` (N) and yaw torque
        ``torque_z`` (N·m) in every control step that starts before ``until_t`` (s).

        A unicycle cannot move sideways: only the force along the heading acts, as the
        acceleration ``F·h/m``, with ``ω̇ += τ_z/I`` (needs ``mass`` and ``inertia``). A new push on
        the same follower replaces the old one; ``reset()`` removes all.
        """
        if self.mass is None or self.inertia is None:
            raise ValueError("the ideal plant needs robot mass and inertia to be pushed")
        if not 0 <= i < self.n:
            raise IndexError(f"follower index {i} out of range 0..{self.n - 1}")
        if self._push_until is None:
            self._push_until = np.full(self.n, -np.inf)
            self._push_wrench = np.zeros((self.n, 3))
        self._push_wrench[i] = (force_xy[0], force_xy[1], torque_z)
        self._push_until[i] = until_t

    def _push_acc(self, t: float) -> np.ndarray:
        """(n, 2) accelerations of the active pushes, heading held over the control period."""
        active = self._push_until > t + 1e-12
        if not active.any():
            self._push_until = None
            return np.zeros((self.n, 2))
        w = self._push_wrench * active[:, None]
        th = self.x[:, 2]
        acc = np.empty((self.n, 2))
        acc[:, 0] = (w[:, 0] * np.cos(th) + w[:, 1] * np.sin(th)) / self.mass
        acc[:, 1] = w[:, 2] / self.inertia
        return acc

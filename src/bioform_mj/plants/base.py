"""The small interface every plant implements (design §8, STYLE: plants behind one interface)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

#: ``d(t)`` → (n, 2) disturbance accelerations ``[d1 m/s², d2 rad/s²]`` (eq. 34).
DisturbanceFn = Callable[[float], np.ndarray]


class Plant(Protocol):
    """A team of ``n`` differential-drive robots driven by wheel torques."""

    n: int
    control_dt: float  # s, one control period

    def reset(self) -> None:
        """Robots at their initial poses, at rest; time 0."""

    def observe(self) -> tuple[np.ndarray, np.ndarray]:
        """Pose (n,3) ``[x m, y m, θ rad ∈ (−π, π]]`` of the axle midpoint and body-frame
        velocity (n,2) ``[υ m/s, ω rad/s]``."""

    def step(self, tau: np.ndarray, t: float) -> None:
        """Apply wheel torques (n,2) ``[τ_L, τ_R]`` N·m for one control period from time ``t`` (s)."""

    def c_true(self) -> np.ndarray:
        """Ground truth ``[a, b]`` (n, 2) of ``υ̇ = a τ_a + d1``, ``ω̇ = b τ_b + d2``."""

    def set_leader(self, pose: np.ndarray, slots: np.ndarray | None) -> None:
        """Show the virtual leader's pose (3,) and the formation slots (n,2); may ignore."""

    def add_payload(self, i: int, mass_kg: float, inertia_kgm2: float) -> None:
        """Follower ``i`` (0-based) picks up a payload at its axle midpoint."""

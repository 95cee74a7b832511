"""Virtual-leader trajectories with analytic velocities (design §2).

A trajectory is a planar curve ``p(t) = (x(t), y(t))`` given with its first three
time derivatives. From them, exactly (no finite differences):

* ``υ_r = |ṗ|``                                     (m/s)
* ``θ_r = atan2(ẏ, ẋ)``                             (rad)
* ``ω_r = (ÿ ẋ − ẍ ẏ) / |ṗ|²``                      (rad/s)
* ``υ̇_r = (ẋ ẍ + ẏ ÿ) / |ṗ|``,  ``ω̇_r`` likewise  (Assumption 2 bounds γ1, γ2)

Every shipped trajectory is a :class:`Harmonic` curve, a drift plus a sum of
cosines in each coordinate; the paper's sinusoid, a line, a circle and a
figure-eight are special cases, and users supply their own terms in TOML or
subclass :class:`Trajectory` in Python.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Trajectory", "Harmonic", "paper", "line", "circle", "figure_eight"]


class Trajectory:
    """Base class: subclasses implement :meth:`derivatives`."""

    def derivatives(self, t: float | np.ndarray) -> np.ndarray:
        """Position and its first three derivatives, shape (4, 2, *t.shape).

        Row k is ``d^k p / dt^k`` in m/s^k.
        """
        raise NotImplementedError

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Leader pose ``[x, y, θ]`` (m, m, rad) and velocity ``[υ, ω]`` at time ``t`` (s)."""
        d = self.derivatives(t)
        (x, y), (dx, dy), (ddx, ddy) = d[0], d[1], d[2]
        v2 = dx * dx + dy * dy
        pose = np.array([x, y, math.atan2(dy, dx)])
        vel = np.array([math.sqrt(v2), (ddy * dx - ddx * dy) / v2])
        return pose, vel

    def states(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Vectorised over times: pose (T, 3), velocity (T, 2) and accel ``[υ̇, ω̇]`` (T, 2)."""
        t = np.asarray(t, dtype=float)
        d = self.derivatives(t)
        (x, y), (dx, dy), (ddx, ddy), (dddx, dddy) = d[0], d[1], d[2], d[3]
        v2 = dx * dx + dy * dy
        v = np.sqrt(v2)
        cross = ddy * dx - ddx * dy
        w = cross / v2
        dot = dx * ddx + dy * ddy
        dv = dot / v
        dcross = dddy * dx - dddx * dy
        dw = dcross / v2 - 2.0 * cross * dot / (v2 * v2)
        pose = np.stack([x, y, np.arctan2(dy, dx)], axis=-1)
        return pose, np.stack([v, w], axis=-1), np.stack([dv, dw], axis=-1)

    def bounds(self, duration: float, samples_per_s: int = 200) -> tuple[float, float]:
        """``(γ1, γ2)`` ≥ ``(max|υ̇_r|, max|ω̇_r|)`` over ``[0, duration]`` (Assumption 2).

        Evaluated on a dense grid; a 1 % margin covers the grid spacing for smooth curves.
        """
        t = np.linspace(0.0, duration, max(2, int(duration * samples_per_s) + 1))
        _, _, acc = self.states(t)
        return float(1.01 * np.max(np.abs(acc[:, 0]))), float(1.01 * np.max(np.abs(acc[:, 1])))

    def min_speed(self, duration: float, samples_per_s: int = 200) -> float:
        """Smallest ``υ_r`` over ``[0, duration]`` (m/s); heading is undefined where it is 0."""
        return self.speed_range(duration, samples_per_s)[0]

    def speed_range(self, duration: float, samples_per_s: int = 200) -> tuple[float, float]:
        """Smallest and largest ``υ_r`` over ``[0, duration]`` (m/s), on a grid of ``samples_per_s`` per s."""
        return self.motion_range(duration, samples_per_s)[:2]

    def motion_range(self, duration: float, samples_per_s: int = 200) -> tuple[float, float, float]:
        """Smallest and largest ``υ_r`` (m/s) and largest ``|ω_r|`` (rad/s) over ``[0, duration]``, on a grid of
        ``samples_per_s`` per s (``|ω_r|`` NaN where the leader stops)."""
        t = np.linspace(0.0, duration, max(2, int(duration * samples_per_s) + 1))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # a stopping leader gives 0/0 in ω
            _, vel, _ = self.states(t)
        return float(np.min(vel[:, 0])), float(np.max(vel[:, 0])), float(np.max(np.abs(vel[:, 1])))


@dataclass(frozen=True)
class Harmonic(Trajectory):
    """``x(t) = x0 + vx t + Σ A cos(w t + φ)`` and the same for ``y``.

    ``x_terms``/``y_terms`` are sequences of ``(A [m], w [rad/s], φ [rad])``.
    """

    x0: float = 0.0
    y0: float = 0.0
    vx: float = 0.0
    vy: float = 0.0
    x_terms: tuple[tuple[float, float, float], ...] = ()
    y_terms: tuple[tuple[float, float, float], ...] = ()

    @staticmethod
    def _series(p0: float, vp: float, terms: Sequence[Sequence[float]], t: np.ndarray) -> np.ndarray:
        out = np.zeros((4,) + np.shape(t))
        out[0] = p0 + vp * t
        out[1] = vp
        for amp, w, phi in terms:
            arg = w * t + phi
            c, s = np.cos(arg), np.sin(arg)
            out[0] += amp * c
            out[1] += -amp * w * s
            out[2] += -amp * w * w * c
            out[3] += amp * w * w * w * s
        return out

    def derivatives(self, t: float | np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        return np.stack(
            [self._series(self.x0, self.vx, self.x_terms, t), self._series(self.y0, self.vy, self.y_terms, t)],
            axis=1,
        )


def paper(
    x0: float = 0.0, y0: float = 3.0, speed: float = 1.0, amplitude: float = 0.4, frequency: float = 1.0
) -> Harmonic:
    """The paper's leader: ``x_r = t``, ``y_r = 3 + 0.4 cos(t − π/2)`` (Sec. IV), generalised."""
    return Harmonic(x0, y0, speed, 0.0, (), ((amplitude, frequency, -math.pi / 2),))


def line(x0: float = 0.0, y0: float = 0.0, speed: float = 1.0, heading: float = 0.0) -> Harmonic:
    """Straight line from ``(x0, y0)`` at ``speed`` (m/s) along ``heading`` (rad)."""
    return Harmonic(x0, y0, speed * math.cos(heading), speed * math.sin(heading))


def circle(cx: float = 0.0, cy: float = 0.0, radius: float = 5.0, speed: float = 1.0) -> Harmonic:
    """Counter-clockwise circle; starts at ``(cx, cy − R)`` heading +x."""
    w = speed / radius
    return Harmonic(cx, cy, 0.0, 0.0, ((radius, w, -math.pi / 2),), ((radius, w, math.pi),))


def figure_eight(cx: float = 0.0, cy: float = 0.0, radius: float = 5.0, frequency: float = 0.2) -> Harmonic:
    """Lemniscate of Gerono ``x = R sin(Ωt)``, ``y = (R/2) sin(2Ωt)``; ``υ_r > 0`` everywhere."""
    return Harmonic(
        cx,
        cy,
        0.0,
        0.0,
        ((radius, frequency, -math.pi / 2),),
        ((radius / 2, 2 * frequency, -math.pi / 2),),
    )

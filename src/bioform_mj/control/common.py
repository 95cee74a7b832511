"""Small elementwise helpers used by every control block."""
from __future__ import annotations

import numpy as np

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

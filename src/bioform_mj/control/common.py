"""Array helpers for outputs and fault injection (the control law itself is in ``equations.py``)."""

from __future__ import annotations

import numpy as np

TWO_PI = 2.0 * np.pi


def wrap(angle: np.ndarray | float) -> np.ndarray:
    """Wrap angles (rad) to (−π, π]. design §3: every heading difference is wrapped."""
    return np.pi - np.mod(np.pi - np.asarray(angle, dtype=float), TWO_PI)

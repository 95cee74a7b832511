"""Array helpers for outputs and fault injection (the control law itself is in ``core/equations.py``)."""

from __future__ import annotations

import numpy as np

from bioform_mj.core.equations import EQUATIONS

#: the one angle wrap, :func:`bioform_mj.core.equations.wrap`, as its plain source (design §0, §3)
_WRAP = EQUATIONS["wrap"]


def wrap_angles(angle: np.ndarray | float) -> np.ndarray:
    """Wrap angles (rad) to (−π, π]: :func:`bioform_mj.core.equations.wrap`'s own source run by numpy on an
    array (design §3: every heading difference is wrapped; one definition, design §0)."""
    return _WRAP(np.asarray(angle, dtype=float))

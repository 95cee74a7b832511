"""Disturbance accelerations ``d(t) = [d1, d2]`` of eq. 34."""

from __future__ import annotations

import numpy as np

from bioform_mj.core.equations import harmonic


class Harmonic:
    """``d_k(t) = bias_k + amp_k cos(freq_k t + phase_k)`` for ``k ∈ {υ (m/s²), ω (rad/s²)}``.

    Same for all ``n`` followers; the paper has ``d1 = 0.1``, ``d2 = 0.1 cos t``.
    """

    def __init__(self, n: int, bias=(0.1, 0.0), amp=(0.0, 0.1), freq=(0.0, 1.0), phase=(0.0, 0.0)) -> None:
        self.n = n
        self.terms = [tuple(float(v[k]) for v in (bias, amp, freq, phase)) for k in range(2)]
        self._out = np.zeros((n, 2))

    def __call__(self, t: float) -> np.ndarray:
        """(n, 2) accelerations at time ``t`` (s). The returned array is reused: copy to keep it."""
        for k, (b, a, f, p) in enumerate(self.terms):
            self._out[:, k] = harmonic(b, a, f, p, t)  # the compiled equation (design §2)
        return self._out


def harmonic_rows(d: object) -> np.ndarray | None:
    """The (2, 4) rows ``bias, amp, freq, phase`` that the compiled loops take for the disturbance
    ``d``: zeros for None, the terms of a :class:`Harmonic`, None for anything else (a plant then
    evaluates ``d(t)`` in Python, step by step)."""
    if d is None:
        return np.zeros((2, 4))
    if isinstance(d, Harmonic):
        return np.array(d.terms, dtype=float).reshape(2, 4)
    return None

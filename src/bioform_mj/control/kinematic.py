"""Bioinspired-neural-dynamics backstepping kinematic control (eqs. 27–33, SPEC §4)."""
from __future__ import annotations

import numpy as np

from .common import wrap


def tracking_error(est_pose: np.ndarray, pose: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Body-frame tracking error ``[x̃, ỹ, θ̃]`` (n, 3) of eqs. 27–28 (m, m, rad).

    ``e_x = x_ir − x_i − Δx_i``, ``e_y = y_ir − y_i − Δy_i`` (world-frame offsets),
    ``e_θ = θ_ir − θ_i`` wrapped to (−π, π].
    """
    ex = est_pose[:, 0] - pose[:, 0] - offsets[:, 0]
    ey = est_pose[:, 1] - pose[:, 1] - offsets[:, 1]
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    out = np.empty_like(pose)
    out[:, 0] = c * ex + s * ey
    out[:, 1] = -s * ex + c * ey
    out[:, 2] = wrap(est_pose[:, 2] - pose[:, 2])
    return out


def shunting_step(vs: np.ndarray, x: np.ndarray, A: float, B: float, D: float, dt: float) -> np.ndarray:
    """Advance the shunting neuron (eq. 32) by ``dt`` (s) for a frozen input ``x``.

    ``V̇ = −A V + (B − V) f(x) − (D + V) g(x)``, ``f = max(x, 0)``, ``g = max(−x, 0)``
    (the paper's ``V_s1`` is a typo for ``V_si``). For frozen ``x`` the equation is
    linear in ``V`` and is integrated exactly, so ``V`` stays in ``(−D, B)`` for any
    step size and input.
    """
    f = np.maximum(x, 0.0)
    g = np.maximum(-x, 0.0)
    lam = A + f + g
    v_inf = (B * f - D * g) / lam
    return v_inf + (vs - v_inf) * np.exp(-lam * dt)


def velocity_command(
    err: np.ndarray, est_vel: np.ndarray, u: np.ndarray, k1: float, k2: float, k3: float
) -> np.ndarray:
    """``[υ_cmd, ω_cmd]`` (n, 2) of eq. 31.

    ``υ_cmd = υ_ir cos θ̃ + k1 u``, ``ω_cmd = ω_ir + k2 υ_ir ỹ + k3 υ_ir sin θ̃``, with
    ``u = V_s`` (bioinspired) or ``u = x̃`` (conventional backstepping).
    """
    v_ir = est_vel[:, 0]
    out = np.empty((err.shape[0], 2))
    out[:, 0] = v_ir * np.cos(err[:, 2]) + k1 * u
    out[:, 1] = est_vel[:, 1] + k2 * v_ir * err[:, 1] + k3 * v_ir * np.sin(err[:, 2])
    return out

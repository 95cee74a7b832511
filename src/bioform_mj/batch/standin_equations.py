"""Stand-in for ``bioform_mj.control.equations`` until that module lands.

It follows the contract the CPU engine's equations will follow: every equation is a
small *scalar* Python function (floats in, a float or a tuple of floats out), using only
module-level names for ``math`` functions and constants (``cos``, ``sin``, ``exp``,
``atan2``, ``sqrt``, ``floor``, ``PI``, ``TWO_PI``), ``min``/``max``/``abs``, ``if``
statements, and calls to other equations of the module. No array indexing, no loops.

The bodies are copied from ``control/fused.py`` (same formulas, same order), so the
Warp translation of this module exercises exactly what the real one will need:
tuple returns, early returns, nested calls, a bool among float outputs, and Python's
floored ``%`` (which Warp does not have: see :mod:`bioform_mj.batch.samesource`).
"""
from __future__ import annotations

import math
from math import atan2, cos, exp, sin, sqrt

PI = math.pi
TWO_PI = 2.0 * math.pi


def wrap(a):
    """Angle to (−π, π] (Python's floored ``%``)."""
    return PI - (PI - a) % TWO_PI


def sat(x, phi):
    """``sgn(x)`` for ``phi == 0`` (the paper), else ``clip(x/phi, −1, 1)``."""
    if phi == 0.0:
        if x > 0.0:
            return 1.0
        if x < 0.0:
            return -1.0
        return 0.0
    return min(max(x / phi, -1.0), 1.0)


def clip(x, lo, hi):
    return min(max(x, lo), hi)


def tracking_error(ex, ey, eth, x, y, th):
    """Eqs. 27–28: the world-frame error ``(ex, ey)`` (estimate − pose − offset) and
    heading error in the follower's frame."""
    co = cos(th)
    si = sin(th)
    return co * ex + si * ey, -si * ex + co * ey, wrap(eth - th)


def velocity_command(e0, e1, e2, u, v_ir, w_ir, k1, k2, k3):
    """Eq. 31 (``u`` = neuron state or ``e0``)."""
    return v_ir * cos(e2) + k1 * u, w_ir + k2 * v_ir * e1 + k3 * v_ir * sin(e2)


def neuron_step(vs, x, A, B, D, dt):
    """Eq. 32 integrated exactly for the frozen input ``x`` over ``dt``."""
    f = max(x, 0.0)
    g = max(-x, 0.0)
    lam = A + f + g
    v_inf = (B * f - D * g) / lam
    return v_inf + (vs - v_inf) * exp(-lam * dt)


def wheel_torques(ua, ub, ca, cb, L, steer):
    """Eqs. 38–39 split into wheels, then saturation (steer-priority or per wheel).
    Returns ``(τ_L, τ_R, saturated)``."""
    half_a = ua / (2.0 * ca)
    half_b = ub / (2.0 * cb)
    r0 = half_a - half_b
    r1 = half_a + half_b
    saturated = abs(r0) > L or abs(r1) > L
    if steer:
        tb = clip(r1 - r0, -2.0 * L, 2.0 * L)
        room = 2.0 * L - abs(tb)
        ta = clip(r0 + r1, -room, room)
        return 0.5 * (ta - tb), 0.5 * (ta + tb), saturated
    return clip(r0, -L, L), clip(r1, -L, L), saturated


def learner_channel(z_hat, e_int, c_hat, d_hat, tau, z, k4, k5, kd, h, c_min, c_max):
    """Eq. 37 for one channel, backward Euler in closed form; returns the new
    ``(ẑ, ∫e, ĉ, d̂)``."""
    R = e_int - h * z
    S0 = k4 * R - z
    S1 = 1.0 + h * k4
    hk4t = h * k4 * tau
    P = c_hat - hk4t * S0
    Q = hk4t * S1
    Pd = d_hat - h * kd * S0
    Qd = h * kd * S1
    den = 1.0 + h * k4 + h * k5 * S1 + h * tau * Q + h * Qd
    zn = (z_hat + h * (tau * P + Pd + k4 * z - k5 * S0)) / den
    return zn, R + h * zn, clip(P - Q * zn, c_min, c_max), Pd - Qd * zn


def body_state(qw, qx, qy, qz, vx, vy, wx, wy, wz):
    """Heading ``θ`` and body-frame ``(υ, ω)`` of a free body, as ``MujocoPlant.observe``:
    ``(hx, hy) = (R00, R10)`` of the quaternion's rotation, ``θ = atan2(hy, hx)``,
    ``υ = (vx, vy)·h/|h|`` (world linear velocity), ``ω = R[2,:]·ω_body``."""
    hx = qw * qw + qx * qx - qy * qy - qz * qz
    hy = 2.0 * (qw * qz + qx * qy)
    r20 = 2.0 * (qx * qz - qw * qy)
    r21 = 2.0 * (qy * qz + qw * qx)
    r22 = qw * qw - qx * qx - qy * qy + qz * qz
    th = atan2(hy + 0.0, hx)
    v = (vx * hx + vy * hy) / sqrt(hx * hx + hy * hy)
    return th, v, r20 * wx + r21 * wy + r22 * wz

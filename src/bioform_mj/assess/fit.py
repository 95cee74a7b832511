"""The fit of :func:`bioform_mj.assess.identify.identify`'s constant-torque tests (design §14).

Split from :mod:`bioform_mj.assess.identify`.
"""

from __future__ import annotations

import numpy as np


def fit_levels(
    runs: list[dict],
    taus: list[float],
    key: str,
    col: int | None,
    drag: bool,
    k0: int,
    *,
    dt: float,
    implicit_damping: bool,
    explicit: bool,
    rate_form: bool,
    residual: bool = False,
) -> tuple[float, ...]:
    """(slope a, intercept c₀, drag β) of ``υ̇ = a τ + c₀ + β υ`` over all levels from ``t₀``, fitted
    on the speed integrated twice (a position-like sum), each level with its own ``υ(t₀)``: a
    rocking chassis adds a bounded wobble to that sum, where it adds its full swing to υ̇. Discrete
    and exact for the integrator: with ``υ*`` the speed the drag acts on (implicit damping: the
    new one, explicit Euler: the old one, RK4: the midpoint; damping 30 on the menagerie Stretch 3
    has k dt ≈ 0.5 at its own step), ``υ_k − υ_0 = α k dt + β S_k``, ``S_k = dt Σ_{j<k} υ*_j``, so
    ``dt Σ_{k<K} υ_k = K dt υ_0 + α dt² K(K−1)/2 + β dt Σ_{k<K} S_k``. Where the model's drag settles
    υ within the test (``k · duration > STRONG_DRAG``: menagerie Stretch 3, k = 232 1/s) the steady
    state carries no information on ``a`` and the fit is on the rates ``(υ_{k+1} − υ_k)/dt = α + β υ*_k``
    instead, every step weighted alike.

    ``runs``: the tests (dicts of series, ``key`` the series, ``col`` its column or None), ``taus`` their
    torques (N·m), ``drag`` whether β is fitted, ``k0`` the first fitted step; ``dt`` the step (s), the
    integrator's scheme (``implicit_damping``, ``explicit``) and ``rate_form`` as above. ``residual``: a fourth
    value, the fit's RMS residual over the RMS of its torque term ``a τ`` (design §14.3: how much of what
    the torque explains is left unexplained; a fit that holds leaves a few per cent at most)."""
    n = len(runs)
    rows, rhs = [], []
    for i_, (run_, tau) in enumerate(zip(runs, taus)):
        y = run_[key] if col is None else run_[key][:, col]
        y = y[k0:]
        mids = y[1:] if implicit_damping else y[:-1] if explicit else 0.5 * (y[1:] + y[:-1])
        S = np.concatenate([[0.0], np.cumsum(mids) * dt])  # S_k, k = 0..K
        P = np.concatenate([[0.0], np.cumsum(y[:-1]) * dt])  # dt Σ_{k<K} υ_k
        SS = np.concatenate([[0.0], np.cumsum(S[:-1]) * dt])
        if rate_form:  # a drag that settles υ within a few steps: the transient is the information
            rows.append(np.column_stack([np.full(len(mids), tau), np.ones(len(mids)), mids * drag, 0 * mids]))
            rhs.append(np.diff(y) / dt)
            continue
        K = np.arange(len(y))
        quad = dt * dt * K * (K - 1) / 2
        v0 = np.zeros((len(y), n))
        v0[:, i_] = K * dt
        rows.append(np.column_stack([tau * quad, quad, SS if drag else 0 * SS, v0]))
        rhs.append(P)
    A, b = np.vstack(rows), np.concatenate(rhs)
    scale = np.abs(A).max(axis=0)
    scale[scale == 0] = 1.0
    sol, *_ = np.linalg.lstsq(A / scale, b, rcond=None)
    x = sol / scale
    a_, c0, beta = x[:3]
    if not residual:
        return float(a_), float(c0), float(beta)
    torque_part = float(np.sqrt(np.mean((A[:, 0] * a_) ** 2)))
    left = float(np.sqrt(np.mean((A @ x - b) ** 2)))
    return float(a_), float(c0), float(beta), left / torque_part if torque_part > 0 else float("inf")

"""Honest confidence intervals for ``bioform robot fit`` (issue 29; design §8): residuals correlated in time
within a chunk (:func:`autocorrelation_inflation`) and the chunks as the independent units
(:func:`cluster_halfwidths`, a cluster-robust covariance: by default the leave-one-chunk-out jackknife)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["autocorrelation_inflation", "cluster_halfwidths", "halfwidths", "jacobian_at", "remaining_step"]


def autocorrelation_inflation(r: np.ndarray, n_chunks: int, n_signals: int) -> float:
    """How much wider than the independent-residual interval an interval must be for residuals that are
    correlated in time: ``sqrt((1 + ρ)/(1 − ρ))`` (the effective sample size of an AR(1) series is
    ``n (1 − ρ)/(1 + ρ)``) with ``ρ`` the lag-1 autocorrelation of the residuals within each chunk and
    signal, averaged (``r``: chunk after chunk, each ``(samples, n_signals)`` row-major). 1 for white noise;
    a smooth model error (ρ near 1) widens the interval by up to 45× (ρ capped at 0.999)."""
    G = int(n_chunks)
    if G < 1 or n_signals < 1 or r.size % (G * n_signals):
        return 1.0
    R = r.reshape(G, -1, n_signals)
    if R.shape[1] < 3:
        return 1.0
    R = R - R.mean(axis=1, keepdims=True)
    num = (R[:, 1:] * R[:, :-1]).sum(axis=1)
    den = (R**2).sum(axis=1)
    ok = den > 0
    if not ok.any():
        return 1.0
    rho = float(np.clip(np.mean(num[ok] / den[ok]), 0.0, 0.999))
    return math.sqrt((1 + rho) / (1 - rho))


def cluster_halfwidths(
    r: np.ndarray, J: np.ndarray, n_chunks: int, alpha: float = 0.05, kind: str = "CR3"
) -> np.ndarray:
    """Half-widths of the ``1 − alpha`` confidence intervals of the parameters (scaled units, as ``J``'s
    columns) from a cluster-robust covariance with the chunks as clusters and Student's t. ``r`` (the residuals,
    chunk after chunk, equal lengths) and ``J`` (its Jacobian) at the optimum; ``H = JᵀJ``, ``A_c = J_cᵀJ_c``,
    ``s_c = J_cᵀ r_c`` (chunk ``c``'s score), ``G`` chunks, ``p`` parameters.

    ``kind="CR3"`` (the default): the leave-one-chunk-out jackknife of the Gauss–Newton step, from ``J`` and
    ``r`` with no refits: without chunk ``c`` the optimum moves by ``Δ_c = (H − A_c)⁻¹ s_c``; the covariance is
    ``(G−1)/G · Σ_c Δ_c Δ_cᵀ``, with ``G − p`` degrees of freedom (the scores it is made of lost ``p`` to the fit;
    t = 2.45 for 12 chunks and 6 parameters, against 2.20 for ``G − 1``). ``kind="CR1"`` (the fit's interval
    before): the sandwich ``G/(G−1) · H⁻¹ (Σ_c s_c s_cᵀ) H⁻¹`` with ``G − 1`` degrees of freedom, which
    under-covers with few chunks: each chunk pulls the optimum towards itself, so its residual understates its
    own error by its leverage (``A_c H⁻¹``, on average ``p/G``: half, with 6 parameters and 12 chunks). Design
    §8.4 gives the coverage measured of both. ``inf`` where ``H`` or some ``H − A_c`` is singular (one chunk
    alone carries a parameter: without it nothing says where it is).

    Within a chunk the residuals are far from independent (a 2 s open-loop rollout compared at 50 Hz: one
    error in the initial state or a torque runs through all of it), so the textbook interval from ``JᵀJ``
    and the residual variance (``mujoco.sysid.calculate_intervals``) counts ~100 samples where there is one
    piece of evidence: on the tb3 test recording ±0.006 kg against a 0.011 kg error. The chunks start from
    their own recorded states, so they are the independent units. Zeros (no say) with fewer than ``p + 2``
    chunks, where the sum of ``G`` scores that cancel at the optimum cannot span the ``p`` parameters."""
    import scipy.special

    G = int(n_chunks)
    p = J.shape[1]
    if G < p + 2 or r.size % G:  # the meat has rank G - 1 at the optimum: fewer chunks than that say nothing
        return np.zeros(p)
    H = J.T @ J
    try:
        Hinv = np.linalg.inv(H)
    except np.linalg.LinAlgError:
        return np.full(p, np.inf)
    if not np.all(np.isfinite(Hinv)):
        return np.full(p, np.inf)
    L = r.size // G
    Jc = [J[c * L : (c + 1) * L] for c in range(G)]
    scores = np.stack([Jc[c].T @ r[c * L : (c + 1) * L] for c in range(G)])  # (G, p)
    if kind == "CR1":
        cov = G / (G - 1) * Hinv @ (scores.T @ scores) @ Hinv
        dof = G - 1
    elif kind == "CR3":
        steps = np.empty_like(scores)
        for c in range(G):
            Hc = H - Jc[c].T @ Jc[c]
            lam = np.linalg.eigvalsh(Hc)
            if lam[0] <= 1e-12 * max(lam[-1], 1e-300):  # without this chunk a parameter is not determined
                return np.full(p, np.inf)
            steps[c] = np.linalg.solve(Hc, scores[c])
        cov = (G - 1) / G * steps.T @ steps
        dof = G - p
    else:
        raise ValueError(f"kind must be 'CR1' or 'CR3', got {kind!r}")
    return np.sqrt(np.maximum(np.diag(cov), 0.0)) * scipy.special.stdtrit(dof, 1 - alpha / 2)


def jacobian_at(residual, x: np.ndarray, r: np.ndarray, eps: float, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Jacobian of ``residual`` (scaled variables; ``residual(X)`` takes one point per column of ``X`` and
    returns one residual column per point, all rolled out in parallel) at ``x``, where it is ``r``, by forward
    differences of step ``eps · max(1, |x|)`` (backward where that passes the upper bound ``hi``); and per
    parameter its ``roughness``: the relative change of its column at a 10× step. Where that is large the residual
    is not smooth at this scale (open-loop rollouts that are chaotic: a dragging caster's stick-slip) and no
    interval from ``J`` means anything (design §8.4). Returns ``(J, roughness)``."""
    cols = []
    for k in (1.0, 10.0):
        h = k * eps * np.maximum(1.0, np.abs(x))
        h = np.where(x + h > hi, -h, h)
        cols.append((residual(x[:, None] + np.diag(h)) - r[:, None]) / h[None, :])
    J, J2 = cols
    big = np.maximum(np.linalg.norm(J, axis=0), np.linalg.norm(J2, axis=0))
    return J, np.linalg.norm(J - J2, axis=0) / np.maximum(big, 1e-300)


def remaining_step(
    r: np.ndarray,
    J: np.ndarray,
    x: np.ndarray | None = None,
    lo: np.ndarray | None = None,
    hi: np.ndarray | None = None,
) -> np.ndarray:
    """The Gauss–Newton step ``δ = −(JᵀJ)⁻¹ Jᵀ r`` still to go from the reported point (scaled units): about 0
    where the optimiser converged, the distance to the optimum where it stopped short (its time budget, its
    iteration limit). A parameter at a bound of its search range (``x``, ``lo``, ``hi``) that the step would push
    out of it is held there (the step is taken over the others)."""
    free = np.ones(J.shape[1], bool)
    step = np.zeros(J.shape[1])
    for _ in range(2):
        if not free.any():
            break
        step[:] = 0.0
        step[free] = np.linalg.lstsq(J[:, free], -r, rcond=None)[0]
        if x is None or lo is None or hi is None:
            break
        span = np.maximum(hi - lo, 1e-300)
        out = ((x - lo <= 1e-6 * span) & (step < 0)) | ((hi - x <= 1e-6 * span) & (step > 0))
        if not (out & free).any():
            break
        free &= ~out
    return step


def halfwidths(
    r: np.ndarray,
    J: np.ndarray,
    n_chunks: int,
    n_signals: int,
    step: np.ndarray | None = None,
    kind: str = "CR3",
) -> tuple[np.ndarray, np.ndarray]:
    """The fit's 95 % half-widths (scaled units) and the parameters' correlation matrix, at the reported point:
    the wider of the independent-residual interval (``mujoco.sysid.calculate_intervals``) widened by the
    residual's autocorrelation (:func:`autocorrelation_inflation`) and the leave-one-chunk-out jackknife
    (:func:`cluster_halfwidths`), plus ``|step|`` (:func:`remaining_step`: where the optimiser stopped short of
    the optimum, the interval about the reported point must reach the interval about the optimum); the
    correlations from ``(JᵀJ)⁻¹``. ``kind``: :func:`cluster_halfwidths`' (``CR1`` only for
    ``scripts/fit_coverage.py``'s comparison)."""
    from mujoco import sysid

    sigma, half_iid = sysid.calculate_intervals([r], J)
    inflate = autocorrelation_inflation(r, n_chunks, n_signals)
    half = np.maximum(half_iid * inflate, cluster_halfwidths(r, J, n_chunks, kind=kind))
    if step is not None:
        half = half + np.abs(step)
    sd = np.sqrt(np.maximum(np.diag(sigma), 0))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = sigma / np.outer(sd, sd)
    return half, np.where(np.isfinite(corr), corr, 0.0)

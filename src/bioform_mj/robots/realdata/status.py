"""What ``bioform robot fit`` may call found (issue 29; design §8.4): the chunk length a recording's intervals
need (:func:`choose_chunk`), and each parameter's row of ``fit.json`` with its status (:func:`parameter_rows`,
:func:`settle_zero`).

A parameter's ``status`` is one of

- ``identified``: its 95 % interval holds (the model follows the recording, the residual is smooth in it, the
  recording gives enough chunks for the jackknife) and is narrower than 30 % of its value (so it does not include
  0; the clause "or than 5 % of its search range, for one found near zero" is gone: it called the PMB-2's dry
  friction 0.047 ± 0.085 N·m identified, design §8.4);
- ``negligible``: its interval includes 0 (the recording cannot tell it from 0), or is too wide to identify it,
  and its upper end is physically small: its torque at the wheel, at the recording's own RMS wheel speed (damping) or
  acceleration (armature), or the dry friction itself, is below :data:`NEGLIGIBLE_TORQUE` of the RMS recorded effort
  of that wheel. The fitted value is written into the calibrated robot; what the report says is "below X, negligible
  here";
- ``not identified``: anything else, with ``why`` (a wide interval, an interval that includes 0 and is not
  negligible — "the recording says only that it is below X" —, correlated partners, a search bound, a residual
  that is not smooth in it, a diverged finite-difference trial, a model that misses the recording, a recording
  too short for an interval that holds).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bioform_mj.robots.realdata.recording import Recording, chunk_starts

__all__ = [
    "CHUNK_S",
    "CHUNK_FLOOR_S",
    "CHUNK_MARGIN",
    "NEGLIGIBLE_TORQUE",
    "choose_chunk",
    "too_short_why",
    "torque_effects",
    "parameter_rows",
    "settle_zero",
    "suspension_rule",
]

#: the default chunk length (s): where the recording gives at least ``p + CHUNK_MARGIN`` of them
CHUNK_S = 2.0
#: chunks wanted beyond the parameter count ``p``: the jackknife needs ``p + 2`` (design §8.4); with ``p + 4`` its
#: t has 4 degrees of freedom (2.78): 10 chunks of 2 s (20 s recorded) held 92 of 96 intervals (design §8.4)
CHUNK_MARGIN = 4
#: the shortest chunk the fit chooses by itself (s). Measured (design §8.4; Kobuki and lab robot, 8 torque
#: programs each, 96 intervals): 12 chunks of 0.5 s held 95.8 % (12 s recorded), 99.0 % (8 s) and 96.9 % (6 s) of
#: their intervals; 12 of 0.25 s (6 s) 91.7 %, and 8 of the 12 that missed were called identified. A 0.25 s chunk
#: holds half a torque pulse at most (the test programs' last 0.3-0.8 s) and its recorded start state's error
#: counts for more of it
CHUNK_FLOOR_S = 0.5
#: a parameter whose interval includes 0 is ``negligible`` where its upper end's torque is below this share of the
#: RMS recorded effort of its wheel (else ``not identified``)
NEGLIGIBLE_TORQUE = 0.05


def _count(rec: Recording, length: float) -> int:
    return int(chunk_starts(rec, length, 1 << 30).size)


def choose_chunk(rec: Recording, n_params: int, chunk_s: float | None, max_chunks: int) -> tuple[float, list[str]]:
    """The chunk length (s) for a fit of ``n_params`` parameters, and the notes saying why. ``chunk_s`` given
    (``--chunk``): it, honoured. Otherwise :data:`CHUNK_S` where the recording gives at least ``n_params +
    CHUNK_MARGIN`` chunks of it (without pauses, and ``max_chunks`` at most); else shorter: the longest length (a
    multiple of 0.1 s, down to :data:`CHUNK_FLOOR_S`) that gives ``max_chunks`` chunks, or as many as the floor
    gives (on 12 s recordings 12 chunks of 1 s held their intervals with narrower ones than 10 of 1.2 s; on 8 s
    ones 12 of 0.5 s than 8 of 1 s: design §8.4)."""
    if chunk_s is not None:
        return float(chunk_s), []
    n_default = _count(rec, CHUNK_S)
    if n_default >= min(n_params + CHUNK_MARGIN, max_chunks):
        return CHUNK_S, []
    lengths = np.round(np.arange(CHUNK_S - 0.1, CHUNK_FLOOR_S - 1e-9, -0.1), 1)
    counts = [_count(rec, float(s)) for s in lengths]
    target = min(max_chunks, max(counts))
    if target <= n_default:
        return CHUNK_S, []
    k = next(i for i, n in enumerate(counts) if n >= target)
    length, n = float(lengths[k]), min(counts[k], max_chunks)
    return length, [
        f"chunks of {length:g} s, not {CHUNK_S:g} s: the recording gives {n_default} chunks of {CHUNK_S:g} s, fewer "
        f"than the {n_params} parameters + {CHUNK_MARGIN} an interval that holds needs (design §8.4); {n} of "
        f"{length:g} s (--chunk sets the length)"
    ]


def too_short_why(n_chunks: int, n_params: int, chunk_s: float, max_chunks: int) -> str:
    """Why no parameter can be called identified with ``n_chunks`` chunks of ``chunk_s`` s (``""`` where they are
    enough): fewer than ``n_params + 2`` chunks give no jackknife interval, and the independent-residual one
    under-covers (3 of 6 intervals missed the truth on a 12 s recording, design §8.4)."""
    need = n_params + 2
    if n_chunks >= need:
        return ""
    if max_chunks < need:
        return (
            f"{n_chunks} chunks for {n_params} parameters, too few for an interval that holds (needs {need}): "
            f"give --max-chunks {need + CHUNK_MARGIN - 2} or more"
        )
    floor = min(chunk_s, CHUNK_FLOOR_S)
    return (
        f"recording too short for an interval that holds ({n_chunks} chunks of {chunk_s:g} s for {n_params} "
        f"parameters; needs {need}): record ≥ {math.ceil((n_params + CHUNK_MARGIN) * floor)} s"
        + (f" (or give a shorter --chunk, down to {CHUNK_FLOOR_S:g} s)" if chunk_s > CHUNK_FLOOR_S else "")
    )


def torque_effects(rec: Recording) -> dict[str, tuple[float, float]]:
    """Per wheel parameter (``damping_L`` …) the torque one unit of it makes at the recording's own motion and
    the RMS recorded effort of its wheel (N·m): damping × RMS wheel speed (rad/s), dry friction itself (N·m per
    N·m), armature × RMS wheel acceleration (rad/s², a 0.1 s Savitzky–Golay derivative). Only where the robot
    moved: a parameter of a wheel that never turned gets no effect bound (absent)."""
    from scipy.signal import savgol_filter

    out: dict[str, tuple[float, float]] = {}
    if len(rec.t) < 7:
        return out
    dt = float(np.median(np.diff(rec.t)))
    win = min(len(rec.t) - (1 - len(rec.t) % 2), max(5, int(round(0.1 / dt)) | 1))
    acc = savgol_filter(rec.velocity, win, 2, deriv=1, delta=dt, axis=0)
    for i, side in enumerate(("L", "R")):
        w = rec.velocity[:, i]
        rms_tau = float(np.sqrt(np.mean(rec.effort[:, i] ** 2)))
        if not (rms_tau > 0 and np.abs(w).max() > 0):
            continue
        out[f"damping_{side}"] = (float(np.sqrt(np.mean(w**2))), rms_tau)
        out[f"frictionloss_{side}"] = (1.0, rms_tau)
        out[f"armature_{side}"] = (float(np.sqrt(np.mean(acc[:, i] ** 2))), rms_tau)
    return out


def settle_zero(row: dict[str, Any], effects: dict[str, tuple[float, float]]) -> None:
    """A row whose interval includes 0 (``ci95[0] <= 0``; every fitted quantity is physically positive or 0) is
    never ``identified``: ``negligible`` where its upper end's torque (:func:`torque_effects`) is below
    :data:`NEGLIGIBLE_TORQUE` of the RMS effort, else ``not identified`` ("the recording says only that it is
    below X"). A row not identified only for its width is ``negligible`` too where its upper end is so. A row not
    identified for another reason (a rough residual, a diverged trial, a misfit, too short a recording, an
    unbounded interval) stays so: its interval does not hold, so its bound says nothing."""
    ci = row.get("ci95")
    if ci is None:
        return
    crosses = ci[0] <= 0.0
    why = [w for w in row["why"].split("; ") if w]
    wide_only = row["status"] == "identified" or all(
        w.startswith(("interval ±", "interval [", "correlated with", "at the bound")) for w in why
    )
    if not wide_only or (row["status"] == "identified" and not crosses):
        return
    hi, unit = float(ci[1]), row["unit"]
    bound = f"interval [{ci[0]:.3g}, {hi:.3g}] {unit}".rstrip() + (" includes 0" if crosses else "")
    rest = [w for w in why if not w.startswith(("interval ±", "interval ["))]
    eff = effects.get(row["name"])
    if eff is not None and math.isfinite(hi) and hi * eff[0] < NEGLIGIBLE_TORQUE * eff[1]:
        row["status"] = "negligible"
        row["why"] = "; ".join(
            [
                f"{bound}: below {hi:.3g} {unit}".rstrip() + f", whose torque at the recording's motion "
                f"({hi * eff[0]:.2g} N·m) is under {NEGLIGIBLE_TORQUE:.0%} of the wheel's RMS effort "
                f"({eff[1]:.2g} N·m)",
                *rest,
            ]
        )
        return
    if not crosses:  # wide, and not negligible: its why stands
        return
    row["status"] = "not identified"
    more = "" if eff is None else f" (its torque there, {hi * eff[0]:.2g} N·m, is not negligible: {eff[1]:.2g} RMS)"
    said = f"{bound}: the recording says only that it is below {hi:.3g} {unit}".rstrip() + more
    row["why"] = "; ".join([said, *rest])


def parameter_rows(
    info: list,
    x: np.ndarray,
    half: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray],
    corr: np.ndarray,
    rough: np.ndarray,
    blew: np.ndarray,
    misfit: float | None,
    short: str,
    rough_max: float,
) -> list[dict[str, Any]]:
    """``fit.json``'s ``parameters`` from the optimum ``x``, the half-widths ``half`` and the search ``bounds``
    (scaled: value = x · ``info[i].scale``), the correlations, the Jacobian's ``rough``-ness (not identified above
    ``rough_max``), the columns whose finite-difference trial diverged (``blew``), ``misfit`` (the weighted
    residual RMS where the model misses the recording, else None) and ``short`` (:func:`too_short_why`). The
    zero rule (:func:`settle_zero`) is the caller's, after any profile intervals."""
    lo, hi = bounds
    names = [p.name for p in info]
    rows = []
    for i, p in enumerate(info):
        v, hw = float(x[i]) * p.scale, float(half[i]) * p.scale
        lo_i, hi_i = float(lo[i]) * p.scale, float(hi[i]) * p.scale
        rng = hi_i - lo_i
        narrow = math.isfinite(hw) and hw <= 0.3 * abs(v)  # excludes 0; near 0: settle_zero's negligible
        ident = narrow and misfit is None and not short and rough[i] <= rough_max and not blew[i]
        partners = [
            {"name": names[k], "rho": round(float(corr[i, k]), 3)}
            for k in np.argsort(-np.abs(corr[i]))
            if k != i and abs(corr[i, k]) > 0.9
        ]
        at_bound = v <= lo_i + 1e-6 * rng or v >= hi_i - 1e-6 * rng
        why = [f"the model misses the recording (weighted residual RMS {misfit:.2g})"] if misfit is not None else []
        if short:
            why.append(short)
        if blew[i]:
            why.append("a finite-difference step of it made the rollouts diverge: its Jacobian column is no slope")
        if rough[i] > rough_max:
            why.append(
                f"the residual is not smooth in it (its Jacobian column at a 10x step differs by {rough[i]:.0%}): "
                "the open-loop rollouts are chaotic, so no interval holds"
            )
        if not narrow and misfit is None:
            why.append(
                f"interval ±{hw:.3g} {p.unit}".rstrip() + (" (unbounded)" if not math.isfinite(hw) else "") + " is wide"
            )
        if partners and not ident:
            why.append("correlated with " + ", ".join(f"{q['name']} (ρ = {q['rho']:+.2f})" for q in partners))
        if at_bound:
            why.append(f"at the bound of its search range [{lo_i:.4g}, {hi_i:.4g}]")
        rows.append(
            {
                "name": p.name,
                "what": p.what,
                "unit": p.unit,
                "published": p.published,
                "fitted": v,
                "ci95": [v - hw, v + hw] if math.isfinite(hw) else None,
                "ci95_halfwidth": hw if math.isfinite(hw) else None,
                "search_range": [lo_i, hi_i],
                "status": "identified" if ident else "not identified",
                "roughness": round(float(rough[i]), 4),  # Jacobian column change from 1x to 10x step (relative)
                "correlated_with": partners,
                "why": "; ".join(why),
            }
        )
    return rows


def suspension_rule(rows: list[dict[str, Any]], layout: Any) -> list[str]:
    """A wheel that hangs below a joint the scene freezes (``layout.suspended_wheels``: a suspension, design §13)
    is simulated rigidly mounted while the robot rode it, so its own terms (``damping``, ``frictionloss``,
    ``armature`` of that side) absorb the difference and are never reported ``identified`` or ``negligible``
    (measured on a PMB-2 whose ±5 mm wheel sliders the recording rode: damping R 0.148 ± 0.041 N·m·s/rad
    "identified" against a truth of 0.05; with ``--free-joints`` it held). Returns fit.json's note (empty: none)."""
    hung = dict(layout.suspended_wheels)
    if not hung:
        return []
    side_of = dict(zip(("L", "R"), layout.wheel_joints))
    hit = []
    for row in rows:
        kind, _, side = row["name"].rpartition("_")
        joint = side_of.get(side) if kind in ("damping", "frictionloss", "armature") else None
        if joint not in hung:
            continue
        if row["status"] != "not identified":
            hit.append(f"{row['name']} {row['status']}")
        row["status"] = "not identified"
        row["why"] = "; ".join(
            [
                f"its wheel hangs below '{hung[joint]}', which the model freezes (a suspension) while the robot rode "
                "it: its terms absorb that; --free-joints (mapping free_joints = true) simulates it",
                *(w for w in row["why"].split("; ") if w),
            ]
        )
    joints = ", ".join(f"'{w}' below '{j}'" for w, j in hung.items())
    return [
        f"driven wheel(s) {joints}: a suspension the model freezes (design §13); those wheels' damping, dry friction "
        "and armature are not reported identified"
        + (f" (otherwise: {', '.join(hit)})" if hit else "")
        + "; give --free-joints to simulate the suspension"
    ]

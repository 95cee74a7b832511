"""The casters of a robot for ``bioform robot fit`` (issue 29; design §0, §8): which geoms they are, the wheel
torque a sliding caster takes (the linear start's regressor), and what the report says of them.

A caster's sliding friction brakes the wheels. Driving straight it brakes both alike, ``μ N r/2`` each (``N``
the caster's load, ``r`` the wheel radius); turning on the spot, ``μ N r |x_c|/(2 l)`` each (``x_c`` its
distance behind the axle, ``l`` the half track): where ``|x_c| ≈ l`` (tb3: 81 mm, 80 mm) both motions look
exactly like a dry friction of each wheel's own (``frictionloss``). Pivots about one wheel and arcs tell them
apart: the caster's drag then follows the direction it slides in, set by the two wheels' speeds together.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import mujoco
import numpy as np

from bioform_mj.core.errors import InputError
from bioform_mj.robots.layout import CONTACT_PRIORITY
from bioform_mj.robots.realdata.recording import Recording
from bioform_mj.robots.realdata.simmodel import SimRobot

__all__ = [
    "caster_geoms",
    "robot_casters",
    "caster_regressor",
    "caster_notes",
    "frictionless_casters",
    "caster_start_notes",
    "caster_start",
    "cost_profile",
    "profile_row",
    "window_means",
    "CASTER_WINDOW_S",
    "CASTER_FD_STEP",
    "CASTER_GRID",
]

#: where caster friction is fitted, the fit compares the means of the signals over windows of this length (s),
#: not samples. A sliding caster chatters: on the tb3 test recording (caster friction 0.3, 24 s at 0.08 N·m) its
#: contact opens 20-45 % of the time at ~50 Hz, the normal force peaks at 4x the static load and the wheel speeds
#: jitter by ±3 rad/s; the phase of that chatter is chaotic (a change of 1e-4 in the friction shifts it within
#: 0.1-0.7 s), so samples of it cannot be fitted. Weighted cost at the true parameters (12 chunks of 2 s):
#: 120.8 sampled at 50 Hz, 2.2 as 0.1 s means (sum of squares)
CASTER_WINDOW_S = 0.1
#: the optimiser's finite-difference step (scaled variables, as ``fit.FD_STEP``) where caster friction is fitted:
#: a secant over the chatter. On that recording from the same start, 1e-3 stalled (cost 24.6 -> 22.3, caster
#: 0.2996, mass 1.12 against 1.243 kg); 3e-2 reached 2.42 (caster 0.318, mass 1.272; at the truth 2.20)
CASTER_FD_STEP = 3e-2
#: the caster frictions of the staged start's 1-D search (each with the wheels and inertias regressed around it)
CASTER_GRID = (0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.6, 0.8, 1.0)
#: smoothing (s) of the wheel speeds for that regression: the chatter's ±3 rad/s at 50 Hz, differentiated over
#: 0.1 s, biased the regressed mass to 0.33 kg (truth 1.243); over 0.5 s 1.13 kg
CASTER_SMOOTH_S = 0.5
#: the steps (±) of a parameter's profile at the optimum where caster friction is fitted, outwards until the
#: cost crosses its threshold (:func:`cost_profile`): in caster friction; others in proportion to their scale
PROFILE_STEPS = (0.01, 0.02, 0.05, 0.1, 0.2)


def caster_geoms(spec: mujoco.MjSpec, model: mujoco.MjModel, names: tuple[str, ...]) -> list[str]:
    out = []
    for n in names:
        g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n)
        if g >= 0:
            out.append(n)
            continue
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, n)
        if b < 0:
            raise InputError(f"--caster {n}: no geom or body of that name")
        for g in range(model.ngeom):
            if model.geom_bodyid[g] == b and (model.geom_contype[g] or model.geom_conaffinity[g]):
                gname = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)
                if not gname:  # named in the spec, by its place among its body's geoms (spec.geoms[g] was
                    # another geom: the Create 3's front caster, and an internal error 'Invalid name')
                    gname = f"bioform_caster_{g}"
                    own = list(spec.body(model.body(b).name).geoms)
                    own[g - int(model.body_geomadr[b])].name = gname
                out.append(gname)
    return out


def robot_casters(robot: SimRobot, spec: mujoco.MjSpec | None = None, model: mujoco.MjModel | None = None) -> list[str]:
    """The caster geoms of ``robot``: the mapping's (``--caster``, :func:`caster_geoms`), else those
    ``robot check`` calls casters (:func:`bioform_mj.robots.contacts.floor_contacts` on the robot settled at
    rest: a non-wheel geom on the floor carrying more than ``CASTER_LOAD`` of the weight)."""
    from bioform_mj.robots.contacts import floor_contacts

    spec = robot.spec if spec is None else spec
    model = spec.compile() if model is None else model
    if robot.ref.casters:
        return caster_geoms(spec, model, robot.ref.casters)
    data = mujoco.MjData(model)
    data.qpos[:] = robot.rest_qpos
    mujoco.mj_forward(model, data)
    found = [c for c in floor_contacts(model, data, robot.layout) if c["role"] == "caster"]
    names = []
    for c in found:
        named = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, c["geom"]) >= 0
        names += [c["geom"]] if named else caster_geoms(spec, model, (c["body"],))
    return list(dict.fromkeys(names))


def caster_regressor(robot: SimRobot, u: np.ndarray, r: float, l: float) -> np.ndarray | None:
    """Per sample and wheel, the wheel torque a sliding caster of friction 1 takes (N·m): the casters'
    loads ``N`` (N) at rest and contact points ``p`` (m, base frame, from the axle midpoint); the drag
    ``F = −N ĉ`` against the caster's velocity ``v x̂ + ω ẑ × p`` maps to the wheels as
    ``Q = (r/2) F_x ∓ (r/2l) (p × F)_z`` (left −, right +)."""
    model = robot.spec.compile()
    try:
        geoms = robot_casters(robot, robot.spec, model)
    except InputError:
        return None
    ids = {model.geom(g).id for g in geoms}
    data = mujoco.MjData(model)
    data.qpos[:] = robot.rest_qpos
    mujoco.mj_forward(model, data)
    base = model.body(robot.layout.base).id
    R = data.xmat[base].reshape(3, 3)
    axle = data.xpos[base] + R @ robot.axle_base
    pts = []
    f6 = np.zeros(6)
    for c in range(data.ncon):
        con = data.contact[c]
        if con.geom1 in ids or con.geom2 in ids:
            mujoco.mj_contactForce(model, data, c, f6)
            pts.append((abs(f6[0]), R.T @ (con.pos - axle)))
    if not pts:
        return None
    v = r * (u[:, 0] + u[:, 1]) / 2
    w = r * (u[:, 1] - u[:, 0]) / (2 * l)
    out = np.zeros_like(u)
    for n, p in pts:
        vc = np.stack([v - w * p[1], w * p[0]], axis=1)
        speed = np.linalg.norm(vc, axis=1)
        ok = speed > 1e-3
        F = np.zeros_like(vc)
        F[ok] = -n * vc[ok] / speed[ok, None]
        torque_z = p[0] * F[:, 1] - p[1] * F[:, 0]
        out[:, 0] += r / 2 * F[:, 0] - r / (2 * l) * torque_z
        out[:, 1] += r / 2 * F[:, 0] + r / (2 * l) * torque_z
    return -out  # τ = ... + μ (−Q/μ): the torque the drive spends against the caster


def caster_notes(robot: SimRobot, which, names: list[str], corr: np.ndarray, find_casters: bool) -> list[str]:
    """What the report says of casters: found and not fitted, or fitted and not separable from the wheels'
    dry friction (|ρ| > 0.8 with a ``frictionloss``)."""
    out = []
    if "caster_friction" in names:
        i = names.index("caster_friction")
        tied = [
            (n, float(corr[i, k]))
            for k, n in enumerate(names)
            if n.startswith("frictionloss") and abs(corr[i, k]) > 0.8
        ]
        if tied:
            out.append(
                "caster friction is not separable from the wheels' dry friction on this recording ("
                + ", ".join(f"ρ with {n} {r:+.2f}" for n, r in tied)
                + "): both brake the robot alike when it drives straight; turns in place set them apart"
            )
    elif "caster_friction" in which and not robot.ref.casters and not find_casters:
        try:
            found = robot_casters(robot)
        except InputError:
            found = []
        if found:
            out.append(
                f"the robot has caster(s) {', '.join(found)} (found as robot check finds them); their friction is "
                "not fitted unless asked: --fit ...,caster_friction (or --caster NAME). Fitted by default on the "
                "tb3 test recordings it led the optimiser to a worse optimum (cost 44.8 against 24.3 without it)"
            )
    return out


def frictionless_casters(model: mujoco.MjModel, geoms: list[str]) -> list[str]:
    """The ``geoms`` the robot file makes frictionless (``condim 1``, or a sliding friction of 0): their
    friction is 0 as published and the fit gives them ``condim 3`` so that a sliding friction acts."""
    return [g for g in geoms if model.geom(g).condim[0] < 3 or model.geom(g).friction[0] <= 0.0]


def caster_start(
    robot: SimRobot,
    rec: Recording,
    info: list,
    x0: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray],
    regress: Callable[..., np.ndarray],
    cost: Callable[[np.ndarray], float],
    reset: Callable[[], None],
) -> tuple[np.ndarray, float, list[str]]:
    """The staged start where caster friction is fitted: a 1-D search over :data:`CASTER_GRID`, at each friction
    the wheels' damping and dry friction regressed around it (``regress(caster_mu=, smooth_s=)``, the linear
    estimate), the inertias regressed or as published; the best by ``cost`` (the simulated, windowed residual).
    ``reset()`` puts the published values back into the robot's spec before each regression (the caster's load
    is read from it). Returns the start (scaled vector), its cost and a note of the search (the cost profile)."""
    lo, hi = bounds
    span = hi - lo
    names = [p.name for p in info]
    k = names.index("caster_friction")
    inertias = [i for i, n in enumerate(names) if n in ("mass", "yaw_inertia")]
    best, best_cost, profile = None, math.inf, []
    for mu in CASTER_GRID:
        reset()
        g = regress(caster_mu=mu, smooth_s=CASTER_SMOOTH_S)
        g_pub = g.copy()  # the published inertias: the regressed ones are biased where the caster chatters
        g_pub[inertias] = np.clip(x0[inertias], (lo + 1e-3 * span)[inertias], (hi - 1e-3 * span)[inertias])
        here = math.inf
        for cand in (g, g_pub):
            c = cost(cand)
            here = min(here, c)
            if c < best_cost:
                best, best_cost = cand, c
        profile.append((mu, here))
    reset()
    note = (
        f"caster friction searched first on a grid (the wheels and inertias regressed around each value; "
        f"weighted cost of {CASTER_WINDOW_S:g} s means: "
        + ", ".join(f"{mu:g}: {c:.3g}" for mu, c in profile)
        + f"), the fit started from {best[k] * info[k].scale:.3g}, then all parameters together with a "
        f"finite-difference step of {CASTER_FD_STEP:g} (scaled) over the caster's chatter; the costs in "
        "fit.json's residual are of these means"
    )
    return best, best_cost, [note]


def cost_profile(
    cost: Callable[[np.ndarray], float],
    x: np.ndarray,
    k: int,
    scale: float,
    n_units: int,
    corr: np.ndarray,
    bounds: tuple[float, float] = (0.0, 1.0),
) -> dict:
    """A parameter's 95 % interval from the cost's profile at the optimum ``x`` (scaled; ``k`` its index, ``scale``
    its scale, ``bounds`` its search range in its own unit), used where caster friction is fitted instead of the
    Jacobian's (the chatter makes the residual rough at a finite-difference step; at a hundredth of the search
    range it is not). The parameter is stepped outwards by :data:`PROFILE_STEPS` × ``scale`` / 0.1 on each side
    (caster friction, scale 0.1: 0.01 ... 0.2), the others held, until the cost exceeds
    ``c* (1 + 3.84 / (n_units - n_params))`` (a likelihood-ratio bound with the ``n_units`` chunks as the
    independent units, as the cluster-robust interval); the crossing (linear between steps) is the bound, and
    the half-widths are widened by ``sqrt((C⁻¹)_kk)`` (``C``: the correlation matrix; the others held make the
    profile narrower by that factor). A side that stays under the threshold is unbounded (the cost is flat
    there), except at a bound of 0 (no friction or damping at all).
    Returns ``{"ci95": [lo, hi] or None, "halfwidth", "points": [[value, cost], ...], "threshold", "flat"}``."""
    c0 = cost(x)
    n_par = len(x)
    thr = c0 * (1.0 + 3.84 / max(1, n_units - n_par))
    v0 = float(x[k]) * scale
    lo_b, hi_b = bounds
    try:
        widen = float(np.sqrt(max(1.0, np.linalg.pinv(corr)[k, k])))
    except np.linalg.LinAlgError:  # pragma: no cover
        widen = math.inf
    points, edges = [[v0, c0]], []
    for sign in (-1.0, 1.0):
        prev_v, prev_c, edge = v0, c0, None
        for d in PROFILE_STEPS:
            v = min(hi_b, max(lo_b, v0 + sign * d * scale / 0.1))
            if v == prev_v:
                break
            z = x.copy()
            z[k] = v / scale
            c = cost(z)
            points.append([v, c])
            if c > thr:
                edge = prev_v + (v - prev_v) * (thr - prev_c) / (c - prev_c)
                break
            prev_v, prev_c = v, c
        if edge is None and sign < 0 and prev_v == lo_b == 0.0:
            edge = 0.0  # flat down to none at all: bounded by the range
        edges.append(edge)
    flat = any(e is None for e in edges)
    points.sort()
    if flat or not math.isfinite(widen):
        return {"ci95": None, "halfwidth": math.inf, "points": points, "threshold": thr, "flat": True}
    ci = [max(lo_b, v0 - widen * (v0 - edges[0])), min(hi_b, v0 + widen * (edges[1] - v0))]
    return {"ci95": ci, "halfwidth": max(v0 - ci[0], ci[1] - v0), "points": points, "threshold": thr, "flat": False}


def profile_row(row: dict, prof: dict, misfit: bool) -> None:
    """Write the profile's interval (:func:`cost_profile`) into a parameter's fit.json row: ``ci95``, ``status``
    (identified: bounded on both sides, narrower than 30 % of the value or, reaching the search range's lower
    bound, than 5 % of the range, and the model does not miss the recording; the Jacobian's ``roughness`` is
    reported, not used) and ``why``."""
    v, hw = row["fitted"], prof["halfwidth"]
    lo_b, hi_b = row.get("search_range", (0.0, 1.0))
    # the 5 %-of-range rule only for one found near its lower bound (its interval reaching it): a dry friction
    # of 0.0027 ± 0.0028 N·m is not identified, whatever the range
    near_lo = prof["ci95"] is not None and prof["ci95"][0] <= lo_b
    narrow = math.isfinite(hw) and (hw <= 0.3 * abs(v) or (near_lo and hw <= 0.05 * (hi_b - lo_b)))
    why = [w for w in row["why"].split("; ") if w and "not smooth" not in w and "interval" not in w]
    if prof["flat"]:
        why.insert(0, "the cost is flat in it (its profile stays within the threshold on a side)")
    elif not narrow:
        why.insert(0, f"interval [{prof['ci95'][0]:.3g}, {prof['ci95'][1]:.3g}] from its profile is wide")
    row["ci95"] = prof["ci95"]
    row["ci95_halfwidth"] = hw if math.isfinite(hw) else None
    row["ci95_method"] = "profile of the windowed cost (the others held, widened by sqrt((C^-1)_kk))"
    row["profile"] = {"points": [[round(m, 7), round(c, 4)] for m, c in prof["points"]], "threshold": prof["threshold"]}
    row["status"] = "identified" if narrow and not misfit and not prof["flat"] else "not identified"
    row["why"] = "; ".join(why) if row["status"] != "identified" else ""


def window_means(t: np.ndarray, y: np.ndarray, ends: np.ndarray, window: float) -> np.ndarray:
    """Means of the rows of ``y`` (sampled at times ``t``, s) over the windows ``(end - window, end]``; a window
    holding no sample takes the value interpolated at its middle."""
    k = np.ceil((t - ends[0]) / window - 1e-9).astype(int)  # the window each sample falls in
    ok = (k >= 0) & (k < len(ends)) & (t > ends[0] - window + 1e-12)
    n = np.bincount(k[ok], minlength=len(ends)).astype(float)
    out = np.stack([np.bincount(k[ok], y[ok, c], minlength=len(ends)) for c in range(y.shape[1])], 1).astype(float)
    empty = n == 0
    out[~empty] /= n[~empty, None]
    if empty.any():
        out[empty] = np.stack([np.interp(ends[empty] - 0.5 * window, t, y[:, c]) for c in range(y.shape[1])], 1)
    return out


def caster_start_notes(robot: SimRobot, info: list, model: mujoco.MjModel) -> list[str]:
    """What the report says where caster friction is fitted: casters the file makes frictionless (the fit gives
    them ``condim 3``)."""
    out = []
    k = [p.name for p in info].index("caster_friction")
    geoms = frictionless_casters(model, robot_casters(robot, robot.spec, model))
    if geoms:
        out.append(
            f"caster(s) {', '.join(geoms)} are frictionless in the robot file (condim 1 or friction 0): the fit "
            f"gives them condim 3 (sliding friction, priority {CONTACT_PRIORITY}) so that their friction acts; "
            f"published value taken as {info[k].published:g}"
        )
    return out

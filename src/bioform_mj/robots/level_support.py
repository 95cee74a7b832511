"""Wheels level with other supports: a statically indeterminate stance, not wheels off the floor (design §14).

A base whose casters sit exactly level with its wheels stands on four (or more) points in one plane:
rigid-body statics cannot say how its weight is shared, and MuJoCo's soft contacts resolve it by the
order of its solver (a paper robot with its casters lowered by 0.5 mm and μ = 0.01 carries all 240 N
on the casters at rest, 0 N on the wheels, then drives at a = 0.39 against the formula's 0.40, the
wheels taking 112 N each as soon as they push). The wheel load MuJoCo reports at rest is then no
evidence that "the wheels do not stand on the floor". :func:`level_support` tells the two apart by
geometry (the wheels' contacts as deep in the floor as the loaded supports, within
:data:`LEVEL_GAP_M`) and gives the load the statics of the stance implies (:func:`statics_loads`:
every support point equally stiff under a rigid chassis, the minimum-norm solution of the force and
moment balance); whether the robot then drives as the formula says is the identification's drive
test's to decide (design §14.2).
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from bioform_mj.robots.layout import subtree

__all__ = ["LEVEL_GAP_M", "level_support", "statics_loads"]

#: a wheel whose floor contact is within this of the deepest loaded support's (m) stands level with it
LEVEL_GAP_M = 5e-4


def statics_loads(points: np.ndarray, com_xy: np.ndarray, weight: float) -> np.ndarray:
    """Normal loads (N) on support ``points`` (k, 2) world x, y (m) of a rigid body of ``weight`` (N)
    whose centre of mass is over ``com_xy`` (m), every support equally stiff (a rigid plane pressed
    into equal springs): the minimum-norm ``f`` with ``Σ f = W``, ``Σ f x = W x_c``, ``Σ f y = W y_c``,
    supports that would pull (``f < 0``) dropped and the rest solved again. Zeros where no stance
    carries it (the centre of mass outside every support)."""
    pts = np.asarray(points, dtype=float)
    f = np.zeros(len(pts))
    active = np.ones(len(pts), bool)
    b = weight * np.array([1.0, com_xy[0], com_xy[1]])
    for _ in range(len(pts)):
        if not active.any():
            break
        a = np.vstack([np.ones(active.sum()), pts[active, 0], pts[active, 1]])
        sol = np.linalg.pinv(a) @ b
        if not np.allclose(a @ sol, b, rtol=1e-6, atol=1e-9 * weight):
            break  # these supports cannot balance it (the centre of mass off their hull): no stance
        if (sol >= -1e-9 * weight).all():
            f[:] = 0.0
            f[active] = np.maximum(sol, 0.0)
            return f
        idx = np.flatnonzero(active)
        active[idx[np.argmin(sol)]] = False
    return np.zeros(len(pts))


def level_support(model: Any, data: Any, lay: Any, weight: float, min_share: float) -> dict[str, Any] | None:
    """Where robot ``lay``'s wheels carry less than ``min_share`` of ``weight`` (N) at rest (``data``
    settled) yet touch the floor as deep as the supports that carry it (within :data:`LEVEL_GAP_M`):
    ``{"measured_n": [L, R], "statics_n": [L, R], "gap_m", "supports": [geom names], "detail"}``, the
    wheel loads MuJoCo resolved and those the statics of the stance gives (N, :func:`statics_loads`),
    the wheels' height above the deepest loaded support (m). None where the wheels carry their share
    or stand clear of the floor (then they do not stand on it: design §14, ``structural``)."""
    wheel_geoms = [model.geom(g).id for g in lay.wheel_geoms]
    if len(wheel_geoms) != 2:
        return None
    inside = set(subtree(model, model.body(lay.base).id).tolist())
    f6 = np.zeros(6)
    per: dict[int, dict[str, Any]] = {}
    # the contacts between the floor (world body) and this robot, found at once (a Python test per contact of the
    # whole scene was n² in a team); the test below is unchanged
    n = int(data.ncon)
    b1s = model.geom_bodyid[np.asarray(data.contact.geom1[:n], dtype=int)]
    b2s = model.geom_bodyid[np.asarray(data.contact.geom2[:n], dtype=int)]
    mine = np.fromiter(inside, dtype=int, count=len(inside))
    near = ((b1s == 0) & np.isin(b2s, mine)) | ((b2s == 0) & np.isin(b1s, mine))
    for c in np.flatnonzero(near).tolist():
        con = data.contact[c]
        g1, g2 = int(con.geom1), int(con.geom2)
        b1, b2 = int(model.geom_bodyid[g1]), int(model.geom_bodyid[g2])
        if b1 == 0 and b2 in inside:
            g = g2
        elif b2 == 0 and b1 in inside:
            g = g1
        else:
            continue
        mujoco.mj_contactForce(model, data, c, f6)
        row = per.setdefault(g, {"load": 0.0, "dist": np.inf, "pos": []})
        row["load"] += float(f6[0])
        row["dist"] = min(row["dist"], float(con.dist))
        row["pos"].append(np.array(con.pos[:2]))
    measured = [per.get(g, {"load": 0.0})["load"] for g in wheel_geoms]
    if min(measured) >= min_share * weight or any(g not in per for g in wheel_geoms):
        return None
    loaded = [r["dist"] for g, r in per.items() if g not in wheel_geoms and r["load"] > 0]
    if not loaded:
        return None
    deepest = min(loaded)
    gap = max(per[g]["dist"] for g in wheel_geoms) - deepest
    if gap > LEVEL_GAP_M:
        return None
    # the stance: every geom touching within LEVEL_GAP_M of the deepest, at the mean of its contact points
    stance = [g for g, r in per.items() if r["dist"] - deepest <= LEVEL_GAP_M]
    pts = np.array([np.mean(per[g]["pos"], axis=0) for g in stance])
    com = data.subtree_com[model.body(lay.base).id][:2]
    f = statics_loads(pts, com, weight)
    statics = [float(f[stance.index(g)]) for g in wheel_geoms]
    if min(statics) < min_share * weight:
        return None  # the statics too leave a wheel unloaded: it does not stand on the floor
    names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"#{g}" for g in stance]
    prefix = lay.base[: lay.base.index("/") + 1] if "/" in lay.base else ""
    names = [n[len(prefix) :] if prefix and n.startswith(prefix) else n for n in names]
    others = [n for g, n in zip(stance, names) if g not in wheel_geoms]
    return {
        "measured_n": measured,
        "statics_n": statics,
        "gap_m": float(gap),
        "supports": names,
        "detail": (
            f"the wheels stand level with {', '.join(repr(n) for n in others)} (within {1e3 * gap:.2g} mm): a "
            f"statically indeterminate stance that MuJoCo resolved with {measured[0]:.3g} N / {measured[1]:.3g} N "
            f"on the wheels at rest; its statics (every support equally stiff) give {statics[0]:.3g} N / "
            f"{statics[1]:.3g} N of {weight:.3g} N, used for the traction limit; the drive test decides "
            "whether it drives as the formula says"
        ),
    }

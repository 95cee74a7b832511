"""The casters of a robot for ``bioform robot fit`` (issue 29; design §0, §8): which geoms they are, the wheel
torque a sliding caster takes (the linear start's regressor), and what the report says of them.

A caster's sliding friction brakes the wheels. Driving straight it brakes both alike, ``μ N r/2`` each (``N``
the caster's load, ``r`` the wheel radius); turning on the spot, ``μ N r |x_c|/(2 l)`` each (``x_c`` its
distance behind the axle, ``l`` the half track): where ``|x_c| ≈ l`` (tb3: 81 mm, 80 mm) both motions look
exactly like a dry friction of each wheel's own (``frictionloss``). Pivots about one wheel and arcs tell them
apart: the caster's drag then follows the direction it slides in, set by the two wheels' speeds together.
"""

from __future__ import annotations

import mujoco
import numpy as np

from bioform_mj.core.errors import InputError
from bioform_mj.robots.realdata.simmodel import SimRobot

__all__ = ["caster_geoms", "robot_casters", "caster_regressor", "caster_notes", "frictionless_casters"]


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
                if not gname:
                    gname = f"bioform_caster_{g}"
                    spec.geoms[g].name = gname
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

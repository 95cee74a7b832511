"""Which joints of a URDF robot are its driven wheels (design §12), from the geometry at ``qpos0``:
the revolute/continuous joints along the base's y axis, right below the base, on links that touch the
floor, one on each side; and which side a Gazebo diff-drive plugin's wheels are on. Used by
:mod:`bioform_mj.robots.urdf`; errors are :class:`~bioform_mj.core.errors.InputError` (exit 2)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from bioform_mj.core.errors import InputError


def collision_zmin(model: Any, data: Any, g: int) -> float:
    """Lowest world z of geom ``g``'s bounding box, m."""
    rot = data.geom_xmat[g].reshape(3, 3)
    c, h = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
    return float((data.geom_xpos[g] + rot @ c)[2] - np.abs(rot[2]) @ h)


#: most candidate joints a message lists
CANDIDATES_SHOWN = 12


def hinge_candidates(model: Any) -> str:
    """The model's hinge joints (a URDF's continuous and revolute ones) with their body and its parent, for an
    error that asks for a mapping: ``'j' (link 'b' on 'p'), …`` (``"none"`` when there is none)."""
    import mujoco

    hinge = int(mujoco.mjtJoint.mjJNT_HINGE)

    def name(obj: Any, i: int) -> str:
        return mujoco.mj_id2name(model, obj, i) or f"#{i}"

    out = []
    for j in range(model.njnt):
        if int(model.jnt_type[j]) != hinge:
            continue
        b = int(model.jnt_bodyid[j])
        out.append(
            f"'{name(mujoco.mjtObj.mjOBJ_JOINT, j)}' (on '{name(mujoco.mjtObj.mjOBJ_BODY, b)}', child of "
            f"'{name(mujoco.mjtObj.mjOBJ_BODY, int(model.body_parentid[b]))}')"
        )
    more = f" and {len(out) - CANDIDATES_SHOWN} more" if len(out) > CANDIDATES_SHOWN else ""
    return ", ".join(out[:CANDIDATES_SHOWN]) + more if out else "none"


def find_wheels(model: Any, base: int, path: Path) -> tuple[str, str, str]:
    """``(left, right, note)``: the two joints that can be the driven wheels (see the module docstring)."""
    import mujoco

    from bioform_mj.robots.layout import SUPPORT_CLEARANCE, welded_to  # MuJoCo only when a URDF is read

    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    rot = data.xmat[base].reshape(3, 3)
    left = rot[:, 1]
    hinge = int(mujoco.mjtJoint.mjJNT_HINGE)

    def collides(g: int) -> bool:
        return bool(model.geom_contype[g] or model.geom_conaffinity[g])

    robot = [g for g in range(model.ngeom) if collides(g) and model.body_rootid[model.geom_bodyid[g]] != 0]
    if not robot:
        raise InputError(f"{path}: the robot has no collision geometry: nothing can touch the floor")
    floor = min(collision_zmin(model, data, g) for g in robot)
    sides: dict[int, list[tuple[str, float]]] = {1: [], -1: []}
    on_base = set(welded_to(model, base).tolist())
    for j in range(model.njnt):
        if model.jnt_type[j] != hinge or abs(float(data.xaxis[j] @ left)) < 0.99:
            continue
        b = int(model.jnt_bodyid[j])
        if model.body_jntnum[b] != 1 or int(model.body_parentid[b]) not in on_base:
            continue
        on_wheel = set(welded_to(model, b).tolist())
        mine = [g for g in robot if int(model.geom_bodyid[g]) in on_wheel]
        if not mine:
            continue
        low = min(collision_zmin(model, data, g) for g in mine)
        radius = float(data.xanchor[j][2]) - low
        if radius <= 0 or low - floor > max(SUPPORT_CLEARANCE, 0.25 * radius):
            continue
        side = 1 if float((data.xanchor[j] - data.xpos[base]) @ left) > 0 else -1
        sides[side].append((mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) or f"#{j}", radius))
    if len(sides[1]) == 1 and len(sides[-1]) == 1:
        lw, rw = sides[1][0][0], sides[-1][0][0]
        return (
            lw,
            rw,
            f"wheels found: left '{lw}', right '{rw}' (the joints along the base's y axis whose links touch the "
            "floor; map left_wheel/right_wheel to choose others)",
        )
    cand = [n for n, _ in sides[1]] + [n for n, _ in sides[-1]]
    if not cand:
        raise InputError(
            f"{path}: no continuous or revolute joint can be a driven wheel (an axis along the base's y axis, "
            "right below the base, on a link that touches the floor); map left_wheel and right_wheel "
            f"(continuous/revolute joints found: {hinge_candidates(model)})"
        )
    raise InputError(
        f"{path}: cannot tell the driven wheels (left: {', '.join(repr(n) for n, _ in sides[1]) or 'none'}; "
        f"right: {', '.join(repr(n) for n, _ in sides[-1]) or 'none'}); map left_wheel and right_wheel "
        f"(continuous/revolute joints found: {hinge_candidates(model)})"
    )


def left_of(model: Any, base: int, a: str, b: str) -> bool:
    """True when joint ``a``'s anchor lies left of joint ``b``'s (the base's +y side) at ``qpos0``."""
    import mujoco

    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    left = data.xmat[base].reshape(3, 3)[:, 1]
    return float((data.xanchor[model.joint(a).id] - data.xanchor[model.joint(b).id]) @ left) > 0

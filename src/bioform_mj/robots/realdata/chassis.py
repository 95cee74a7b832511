"""The chassis body whose mass and yaw inertia ``bioform robot fit`` fits (issue 29; design §8).

The mapping's base body is where the robot's pose is read (ROS ``base_link`` or ``base_footprint``), not
always where its mass is: a ROS URDF's root ``base_footprint`` is massless and its chassis mass sits on
``base_link`` (the Kobuki's 2.4 kg, the PMB2's 28 kg), welded to it by a fixed joint, which the import keeps
as a body; the Husky's 46 kg sit on ``inertial_link``. A payload fitted on a massless base had bounds of
0–0 kg (the fit failed on an internal error). :func:`chassis_body` therefore takes the heaviest body of the
base's welded group (the base and the bodies attached to it through no joint; the base where it is the
heaviest): a payload there moves the chassis' mass as one added at its centre of mass. :func:`explicit_base`
and :func:`set_yaw_inertia` make that body's inertial explicit and set its yaw inertia.
"""

from __future__ import annotations

import mujoco
import numpy as np

__all__ = ["chassis_body", "explicit_base", "set_yaw_inertia"]


def chassis_body(model: mujoco.MjModel, base: str) -> str:
    """The name of the heaviest body welded to ``base`` (``base`` itself where none is heavier, kg): the
    bodies reachable from ``base`` through children that have no joint."""
    root = model.body(base).id
    group = [root]
    for b in range(root + 1, model.nbody):  # MuJoCo orders bodies depth-first: a child after its parent
        if model.body_parentid[b] in group and model.body_jntnum[b] == 0:
            group.append(b)
    heaviest = max(group, key=lambda b: (float(model.body_mass[b]), b == root))
    return model.body(heaviest).name


def explicit_base(spec: mujoco.MjSpec, base: str) -> tuple[int, float]:
    """Make the body ``base``'s inertial explicit (as compiled) and return its principal axis nearest the
    vertical and its inertia about it (kg·m²)."""
    model = spec.compile()
    b = model.body(base)
    body = spec.body(base)
    body.explicitinertial = True
    body.fullinertia = np.full(6, np.nan)
    body.mass = float(b.mass[0])
    body.inertia = np.array(b.inertia, float)
    body.ipos = np.array(b.ipos, float)
    body.iquat = np.array(b.iquat, float)
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, np.array(b.iquat, float))
    k = int(np.argmax(np.abs(R.reshape(3, 3)[2, :])))  # the principal axis (column) most along the body's z
    return k, float(b.inertia[k])


def set_yaw_inertia(body: mujoco.MjsBody, axis: int, value: float) -> None:
    """Set the principal inertia ``axis`` of ``body`` to ``value`` (kg·m²); where that breaks the triangle
    inequality (a yaw inertia above the sum of roll and pitch ones), the other two grow evenly to meet it
    (a payload spread in the plane adds to both; a planar robot's roll and pitch barely matter). Where a
    smaller yaw inertia breaks it the other way (roll or pitch above the sum of the other two: the Husky's
    inertial_link, 0.615 / 1.759 / 2.0 kg·m², at the search range's lower quarter), the smaller of roll and
    pitch grows to meet it (MuJoCo refused to compile: the fit ended on 'no usable trajectory')."""
    inertia = np.array(body.inertia, float)
    inertia[axis] = value
    others = [k for k in range(3) if k != axis]
    short = value - inertia[others].sum()
    if short > 0:
        inertia[others] += 0.5 * short * 1.001 + 1e-12
    small, big = sorted(others, key=lambda k: inertia[k])
    if inertia[big] > inertia[small] + value:
        inertia[small] = (inertia[big] - value) * 1.001 + 1e-12
    body.inertia = inertia

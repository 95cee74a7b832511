"""Friction of the scene's own surfaces against a robot's priority geoms (design §13.3).

MuJoCo gives a contact the friction of the geom with the higher ``priority`` (or, at equal
priority, the larger of the two). A robot's frictionless geoms, mapped casters and URDF links with a
Gazebo ``mu1`` below the floor's get priority :data:`~bioform_mj.robots.layout.CONTACT_PRIORITY` so
that their own friction wins against the floor (design §13). Against a surface that the scene makes
*more* slippery than such a geom (a ``[faults] friction_patch``, a ``floor_friction``) that priority
would keep the geom's larger friction: a wheel of Gazebo μ 0.5 would keep 0.5 on an icy patch of
μ 0.05. :func:`add_min_friction_pairs` gives each such (surface, robot geom) pair an explicit MuJoCo
``<pair>`` with the element-wise smaller friction (ODE/Gazebo's rule), everything else as MuJoCo's
priority rule would have given it; an explicit pair replaces the dynamic contact of the same geoms.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

__all__ = ["add_min_friction_pairs", "min_friction_candidates"]


def _collides(a: mujoco.MjsGeom, b: mujoco.MjsGeom) -> bool:
    """MuJoCo's contype/conaffinity filter of a dynamic geom pair."""
    return bool((a.contype & b.conaffinity) or (b.contype & a.conaffinity))


def min_friction_candidates(spec: mujoco.MjSpec, surface: str) -> list[mujoco.MjsGeom]:
    """The geoms of moving bodies in ``spec`` whose contact with the world geom ``surface`` MuJoCo
    would give a friction larger than the smaller of the two: priority above the surface's and a
    friction component (sliding, torsional, rolling) above the surface's, colliding with it."""
    s = spec.geom(surface)
    sf = np.asarray(s.friction, float)
    out = []
    for g in spec.geoms:
        if g.parent.name == "world" or g.priority <= s.priority or not _collides(g, s):
            continue
        if np.any(np.asarray(g.friction, float) > sf):
            out.append(g)
    return out


def add_min_friction_pairs(spec: mujoco.MjSpec, surfaces: Sequence[str]) -> int:
    """Add an explicit contact pair between each world geom named in ``surfaces`` and each of its
    :func:`min_friction_candidates` (design §13.3); returns the number of pairs added.

    The pair's friction (5 numbers: sliding ×2, torsional, rolling ×2) is the element-wise minimum of
    the two geoms'; condim, solref, solimp and adhesion are the robot geom's (it has the higher priority,
    so MuJoCo would take them), margin and gap the larger of the two (MuJoCo's rule). An unnamed robot
    geom is named ``<its body>/bioform_pair_geom<k>`` so that the pair can refer to it. No candidates,
    nothing added: a scene without such pairs is unchanged.
    """
    added = 0
    for name in surfaces:
        s = spec.geom(name)
        sf = np.asarray(s.friction, float)
        for g in min_friction_candidates(spec, name):
            if not g.name:
                g.name = f"{g.parent.name}/bioform_pair_geom{added}"
            f = np.minimum(np.asarray(g.friction, float), sf)
            spec.add_pair(
                name=f"bioform_min_{name}_{g.name}",
                geomname1=name,
                geomname2=g.name,
                condim=g.condim,
                friction=[f[0], f[0], f[1], f[2], f[2]],
                solref=list(g.solref),
                solimp=list(g.solimp),
                margin=max(s.margin, g.margin),
                gap=max(s.gap, g.gap),
                adhesion=g.adhesion,
            )
            added += 1
    return added

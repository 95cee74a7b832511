"""Pairs of a robot's own bodies whose published collision geoms overlap or touch at rest (design §13.1).

The scene replaces a wheel's collision shape by a single-contact proxy (``robot_prepare._wheel_proxy``)
and holds, freezes or locks the other joints (design §13), so its contact list hides overlaps that
the robot's maker published: a wheel cylinder inside the chassis. Here the robot's model is read
as its file gives it — the MJCF compiled as it stands, a URDF imported with MuJoCo's collision
rules (:func:`bioform_mj.robots.urdf.import_urdf` with ``self_collide``) — at ``qpos0`` (the joints as
published), and every pair of geoms that MuJoCo's collision filter would collide (:func:`pair_margin`:
``contype``/``conaffinity``, the weld-level parent–child filter, ``<exclude>``, explicit ``<pair>``)
and whose world boxes meet (a vectorised prefilter on ``geom_aabb``) is measured with
``mujoco.mj_geomDistance`` (cut off at the pair's margin + :data:`TOUCH_M`). Each body pair then says
whether the simulated scene collides it (:func:`bodies_collide` on the scene model).

Imports nothing of the project at module level but :mod:`bioform_mj.robots.contacts`' name helpers.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from bioform_mj.robots.contacts import _bname, _gname

__all__ = ["TOUCH_M", "pair_margin", "bodies_collide", "geom_overlaps", "published_model", "self_contacts_at_rest"]

#: two geoms closer than their margin plus this (m) touch (GJK's accuracy is ~1e-6 m on meshes)
TOUCH_M = 1e-5
_SKIP = (int(mujoco.mjtGeom.mjGEOM_PLANE), int(mujoco.mjtGeom.mjGEOM_HFIELD))


def _weld_filtered(model: mujoco.MjModel, b1: int, b2: int) -> bool:
    """MuJoCo's body filter: the same weld body, or (``filterparent`` on) a weld body and its weld parent."""
    w1, w2 = int(model.body_weldid[b1]), int(model.body_weldid[b2])
    if w1 == w2:
        return True
    if model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_FILTERPARENT or w1 == 0 or w2 == 0:
        return False
    p1 = int(model.body_weldid[model.body_parentid[w1]])
    p2 = int(model.body_weldid[model.body_parentid[w2]])
    return w1 == p2 or w2 == p1


def pair_margin(model: mujoco.MjModel, g1: int, g2: int) -> float | None:
    """The margin (m) with which MuJoCo collides geoms ``g1``, ``g2``, or None where it does not:
    an explicit ``<pair>`` always (its margin); otherwise both collide at all, ``contype``/``conaffinity``
    match either way, the bodies are not welded together nor weld parent and child (unless
    ``filterparent`` is disabled) and not ``<exclude>``d; then the larger geom margin."""
    if model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT:
        return None
    for k in range(model.npair):
        if {int(model.pair_geom1[k]), int(model.pair_geom2[k])} == {g1, g2}:
            return float(model.pair_margin[k])
    ct1, ca1 = int(model.geom_contype[g1]), int(model.geom_conaffinity[g1])
    ct2, ca2 = int(model.geom_contype[g2]), int(model.geom_conaffinity[g2])
    if not (ct1 & ca2 or ct2 & ca1):
        return None
    b1, b2 = int(model.geom_bodyid[g1]), int(model.geom_bodyid[g2])
    if _weld_filtered(model, b1, b2):
        return None
    if model.nexclude:
        sig = set(model.exclude_signature.tolist())
        if (b1 << 16) + b2 in sig or (b2 << 16) + b1 in sig:
            return None
    return max(float(model.geom_margin[g1]), float(model.geom_margin[g2]))


def bodies_collide(model: mujoco.MjModel, b1: int, b2: int) -> bool:
    """True when MuJoCo collides some geom of body ``b1`` with some geom of body ``b2`` (:func:`pair_margin`)."""
    g1s = range(model.body_geomadr[b1], model.body_geomadr[b1] + model.body_geomnum[b1])
    g2s = range(model.body_geomadr[b2], model.body_geomadr[b2] + model.body_geomnum[b2])
    return any(pair_margin(model, g1, g2) is not None for g1 in g1s for g2 in g2s)


def _world_boxes(model: mujoco.MjModel, data: mujoco.MjData, geoms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned world boxes ``(centre (k, 3), half size (k, 3))`` of ``geoms`` from their local ``geom_aabb``."""
    rot = data.geom_xmat[geoms].reshape(-1, 3, 3)
    box = model.geom_aabb[geoms]
    centre = data.geom_xpos[geoms] + np.einsum("kij,kj->ki", rot, box[:, :3])
    half = np.einsum("kij,kj->ki", np.abs(rot), box[:, 3:])
    return centre, half


def geom_overlaps(model: mujoco.MjModel, data: mujoco.MjData, root: int) -> dict[tuple[int, int], dict[str, Any]]:
    """Body pairs of the tree under top-level body ``root`` whose geoms MuJoCo collides and that overlap or
    touch now (``data`` holds ``mj_kinematics``): ``{(b1, b2): {"geoms": [(g1, g2), …], "depth_m": deepest
    penetration ≥ 0 (m)}}``, ``b1 < b2``. Cost: one vectorised box test over all geom pairs, then
    ``mj_geomDistance`` on the pairs whose boxes meet (within the largest margin + :data:`TOUCH_M`)."""
    ids = np.arange(model.ngeom)
    explicit = np.isin(ids, np.concatenate([model.pair_geom1, model.pair_geom2]))
    mine = ids[
        (model.body_rootid[model.geom_bodyid] == root)
        & ((model.geom_contype != 0) | (model.geom_conaffinity != 0) | explicit)
        & ~np.isin(model.geom_type, _SKIP)
    ]
    out: dict[tuple[int, int], dict[str, Any]] = {}
    if len(mine) < 2:
        return out
    centre, half = _world_boxes(model, data, mine)
    reach = max(float(model.geom_margin[mine].max()), float(model.pair_margin.max()) if model.npair else 0.0)
    i, j = np.triu_indices(len(mine), k=1)
    near = np.all(np.abs(centre[i] - centre[j]) <= half[i] + half[j] + reach + TOUCH_M, axis=1)
    near &= model.geom_bodyid[mine[i]] != model.geom_bodyid[mine[j]]
    for a, b in zip(mine[i[near]], mine[j[near]]):
        g1, g2 = int(a), int(b)
        margin = pair_margin(model, g1, g2)
        if margin is None:
            continue
        cut = margin + 2 * TOUCH_M
        dist = float(mujoco.mj_geomDistance(model, data, g1, g2, cut, None))
        if dist > margin + TOUCH_M:
            continue
        b1, b2 = int(model.geom_bodyid[g1]), int(model.geom_bodyid[g2])
        if b1 > b2:
            b1, b2, g1, g2 = b2, b1, g2, g1
        row = out.setdefault((b1, b2), {"geoms": [], "depth_m": 0.0})
        row["geoms"].append((g1, g2))
        row["depth_m"] = max(row["depth_m"], -dist)
    return out


def published_model(entry: Any) -> mujoco.MjModel:
    """The robot's model as its file gives it, before the scene changes anything: an MJCF compiled as it
    stands; a URDF imported (design §12) with MuJoCo's own collision rules (``self_collide``: every pair
    but parent–child), so that its overlaps are found whatever the scene's convention."""
    from bioform_mj.robots.entries import resolve_robot
    from bioform_mj.robots.formats import format_of

    ref = resolve_robot(entry)
    fmt = format_of(Path(ref.model))
    if fmt.published is not None:  # design §12: the format's reading
        return fmt.published(ref)
    return fmt.load(ref, Path(ref.model))[1]  # a format without one: its own (confined) loader's model


def _why_not(scene: mujoco.MjModel, b1: int, b2: int, urdf: bool) -> str:
    if b1 < 0 or b2 < 0:
        return "the scene has no such body (fused)"
    if urdf:
        return "self-collision off (the URDF/Gazebo convention, design §12; map self_collide = true to collide them)"
    if _weld_filtered(scene, b1, b2):
        return "the scene welds them together or as parent and child (a joint between them frozen, design §13)"
    return "the scene's collision filter drops the pair (contype/conaffinity or <exclude>)"


def self_contacts_at_rest(
    entry: Any, base: str, scene: mujoco.MjModel, prefix: str, in_scene: list[dict]
) -> tuple[list[dict], list[str]]:
    """Every pair of the robot's own bodies in contact at rest, and a note per pair the scene does not collide.

    ``in_scene``: :func:`bioform_mj.robots.contacts.self_contacts` of the settled scene (names without ``prefix``);
    ``base``: the base body's name without ``prefix``; ``scene``: the compiled scene. Each pair found in the
    published geoms at the file's configuration (:func:`geom_overlaps` on :func:`published_model`) is merged
    with the scene's: ``body1``, ``body2``, ``geoms`` (name pairs), ``depth_m`` (the deeper of the published
    overlap and the scene's contact, m), ``force_n``/``points`` (the scene's, 0 where it has none) and
    ``simulated`` (the scene's filter collides the pair: MJCF as the file says, less what frozen joints weld;
    URDF off by convention). Returns ``(pairs, notes)``."""
    from bioform_mj.robots.entries import resolve_robot
    from bioform_mj.robots.formats import format_of

    ref = resolve_robot(entry)
    urdf = not format_of(Path(ref.model)).self_collision and not ref.self_collide  # the URDF/Gazebo convention
    from bioform_mj.robots.analysis import layout_of

    pub = published_model(entry)
    data = mujoco.MjData(pub)
    lay = layout_of(scene, prefix)
    for jn, q in lay.keyframe_qpos:  # the configuration that runs: the keyframe's (design §13.2)
        data.qpos[pub.jnt_qposadr[pub.joint(jn).id]] = q
    config = f"keyframe '{lay.keyframe}'" if lay.keyframe else "file's"
    mujoco.mj_kinematics(pub, data)
    root = int(pub.body_rootid[pub.body(base).id])
    rows = {frozenset((c["body1"], c["body2"])): dict(c, simulated=True) for c in in_scene}
    notes = []
    for (b1, b2), hit in geom_overlaps(pub, data, root).items():
        n1, n2 = _bname(pub, b1), _bname(pub, b2)
        geoms = [[_gname(pub, g1), _gname(pub, g2)] for g1, g2 in hit["geoms"]]
        key = frozenset((n1, n2))
        if key in rows:
            row = rows[key]
            row["depth_m"] = max(row["depth_m"], hit["depth_m"])
            row["geoms"] += [p for p in geoms if p not in row["geoms"] and p[::-1] not in row["geoms"]]
            continue
        s1 = mujoco.mj_name2id(scene, mujoco.mjtObj.mjOBJ_BODY, prefix + n1)
        s2 = mujoco.mj_name2id(scene, mujoco.mjtObj.mjOBJ_BODY, prefix + n2)
        sim = s1 >= 0 and s2 >= 0 and bodies_collide(scene, s1, s2)
        rows[key] = {
            "body1": n1,
            "body2": n2,
            "geoms": geoms,
            "depth_m": hit["depth_m"],
            "force_n": 0.0,
            "points": 0,
            "simulated": sim,
        }
        where = f"'{n1}' and '{n2}': published collision geoms overlap {1e3 * hit['depth_m']:.3g} mm at the {config} "
        if sim:
            notes.append(
                where + "configuration; the scene collides the pair but its geoms do not touch at rest (a wheel's "
                "contact proxy, design §8)"
            )
        else:
            notes.append(where + "configuration; not collided in the scene: " + _why_not(scene, s1, s2, urdf))
    return sorted(rows.values(), key=lambda r: (r["body1"], r["body2"])), notes

"""A published MJCF with heavy meshes made small for the test data (mujoco + numpy + trimesh).

What changes, and why it changes nothing the checks measure:
- every body gets the explicit ``<inertial>`` MuJoCo compiled from the published file (mass, centre,
  principal inertia and axes), so the masses and inertias stay the published ones whatever the geoms;
- visual geoms (``contype = conaffinity = 0``) go, with the textures and materials (looks only);
- each collision mesh is replaced by its convex hull (what MuJoCo collides with anyway), vertices
  snapped to a ``--grid`` (m, default 1 mm) to keep it small;
- the compiler's ``assetdir``/``meshdir`` point at the folder of the new meshes.

    python tests/zoo_candidates/_tools/strip_mjcf.py PUBLISHED.xml OUT_DIR [--grid 0.001]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import mujoco
import numpy as np
import trimesh

sys.path.insert(0, str(Path(__file__).resolve().parent))
from hull_stl import hull  # noqa: E402


def strip(src: Path, out: Path, grid: float) -> Path:
    spec = mujoco.MjSpec.from_file(str(src))
    model = spec.compile()
    for b in spec.bodies:  # explicit inertials, as compiled from the published geoms
        if b.name == "world":
            continue
        i = model.body(b.name).id
        b.explicitinertial = True
        b.mass = float(model.body_mass[i])
        b.ipos = [float(x) for x in model.body_ipos[i]]
        b.iquat = [float(x) for x in model.body_iquat[i]]
        b.inertia = [float(x) for x in model.body_inertia[i]]
    meshdir = Path(spec.modelfiledir or src.parent) / (spec.compiler.meshdir or "")
    used: dict[str, str] = {}
    for g in list(spec.geoms):
        if not (g.contype or g.conaffinity):
            spec.delete(g)
            continue
        g.material = ""
        if g.type == mujoco.mjtGeom.mjGEOM_MESH:
            used[g.meshname] = ""
    (out / "assets").mkdir(parents=True, exist_ok=True)
    flat: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # mesh -> (centre, half extents) of a flat one
    for m in list(spec.meshes):
        if m.name not in used:
            spec.delete(m)
            continue
        scale = np.asarray(m.scale, float)
        v = np.asarray(trimesh.load(str(meshdir / m.file), force="mesh").vertices) * scale
        lo, hi = v.min(axis=0), v.max(axis=0)
        if np.min(hi - lo) < 1e-3:  # a sticker: no hull; a thin box of its extent
            flat[m.name] = (0.5 * (lo + hi), np.maximum(0.5 * (hi - lo), 2.5e-4))
            spec.delete(m)
            continue
        name = Path(m.file).stem + "_hull.stl"
        hull(str(meshdir / m.file), str(out / "assets" / name), 1.0, grid)
        m.file = name  # a per-axis scale stays on the asset
    for g in spec.geoms:
        if g.type == mujoco.mjtGeom.mjGEOM_MESH and g.meshname in flat:
            c, h = flat[g.meshname]
            rot = np.zeros(9)
            mujoco.mju_quat2Mat(rot, np.asarray(g.quat, float))
            g.type, g.meshname = mujoco.mjtGeom.mjGEOM_BOX, ""
            g.pos = [float(x) for x in np.asarray(g.pos, float) + rot.reshape(3, 3) @ c]
            g.size = [float(x) for x in h]
    for t in list(spec.textures):
        spec.delete(t)
    for mat in list(spec.materials):
        spec.delete(mat)
    spec.compiler.meshdir = "assets"
    spec.compiler.texturedir = ""
    spec.modelfiledir = str(out)  # to_xml compiles: the hulls are found where the new file lies
    dst = out / src.name
    dst.write_text(spec.to_xml())
    return dst


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("src", type=Path)
    p.add_argument("out", type=Path)
    p.add_argument("--grid", type=float, default=0.001)
    a = p.parse_args()
    dst = strip(a.src, a.out, a.grid)
    m0, m1 = mujoco.MjModel.from_xml_path(str(a.src)), mujoco.MjModel.from_xml_path(str(dst))
    print(f"{dst}: mass {m0.body_mass.sum():.6g} -> {m1.body_mass.sum():.6g} kg, {m0.ngeom} -> {m1.ngeom} geoms")

"""Replace a published collision mesh by its convex hull, written as a binary STL (test-data tool).

MuJoCo collides a mesh geom through its convex hull, so for contacts the hull is the published
mesh; it is a few kB where the published file is hundreds. (The inertia MuJoCo would compute from a
mesh changes with the hull: use it where the description gives the inertia, as URDF ``<inertial>``
or the MJCF bodies' ``<inertial>`` that ``strip_mjcf.py`` writes.)

    python tests/zoo_candidates/_tools/hull_stl.py IN.stl|IN.dae|IN.obj OUT.stl [--scale S] [--grid G]
"""

from __future__ import annotations

import argparse

import numpy as np
import trimesh


def hull(src: str, dst: str, scale: float = 1.0, grid: float = 0.0) -> tuple[int, np.ndarray]:
    """Write the convex hull of ``src`` (× ``scale``) to ``dst``; returns its vertex count and bounds (2, 3).
    ``grid`` > 0 (m): the vertices are first snapped to that grid (the hull moves by at most grid/2)."""
    mesh = trimesh.load(src, force="mesh")
    v = np.asarray(mesh.vertices) * scale
    if grid > 0:
        v = np.unique(np.round(v / grid) * grid, axis=0)
    h = trimesh.convex.convex_hull(v)
    h.export(dst, file_type="stl")
    return len(h.vertices), h.bounds


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("src")
    p.add_argument("dst")
    p.add_argument("--scale", type=float, default=1.0)
    p.add_argument("--grid", type=float, default=0.0, help="snap the vertices to this grid first (m)")
    a = p.parse_args()
    n, b = hull(a.src, a.dst, a.scale, a.grid)
    print(f"{a.dst}: {n} vertices, bounds {np.round(b, 4).tolist()}")

"""Meshes MuJoCo cannot read, converted with trimesh for the URDF import (design §12): COLLADA (its
``<unit meter>`` applied, as Gazebo and RViz do) and whatever else trimesh reads; the reader is bounded by the
same mesh resolver as every robot file (:func:`bioform_mj.robots.sanity.mesh_resolver`)."""

from __future__ import annotations

import functools
import xml.etree.ElementTree as ET

import numpy as np

__all__ = ["INSTALL_HINT", "collada_unit", "have_trimesh", "one_line", "trimesh_read"]

#: how to get the converter (the ``urdf`` extra)
INSTALL_HINT = "pip install 'bioform-mj[urdf]' (trimesh + pycollada)"


def one_line(msg: object) -> str:
    """``msg`` as one line (an exception's text in an ``error:`` line)."""
    return " ".join(str(msg).split())


def have_trimesh() -> bool:
    """Whether trimesh (the ``urdf`` extra) is installed."""
    try:
        import trimesh  # noqa: F401
    except ImportError:
        return False
    return True


def collada_unit(file: str) -> float:
    """``<asset><unit meter=…>`` of a COLLADA file (1 without one): Gazebo and RViz apply it."""
    try:
        for _ev, el in ET.iterparse(file, events=("start",)):
            if el.tag.endswith("}unit") or el.tag == "unit":
                return float(el.get("meter", "1"))
            if el.tag.endswith("library_geometries"):
                break
    except (OSError, ET.ParseError, ValueError):
        pass
    return 1.0


@functools.lru_cache(maxsize=64)
def trimesh_read(file: str, mtime_ns: int, size: int) -> tuple[np.ndarray, np.ndarray, float] | str:
    """``(vertices (V, 3) m, faces (F, 3), COLLADA unit)`` of a mesh trimesh reads (all its parts,
    placed), or why not; cached by file and its ``(mtime, size)``: a scene builds a robot several
    times (a published COLLADA visual takes ~0.2 s)."""
    import trimesh

    from bioform_mj.robots.sanity import mesh_resolver

    try:
        mesh = trimesh.load(file, force="mesh", resolver=mesh_resolver(file))
        v = np.asarray(mesh.vertices, float)
        f = np.asarray(mesh.faces, int)
    except Exception as exc:  # a broken file, a missing pycollada
        return one_line(exc) or type(exc).__name__
    if len(v) < 4 or len(f) < 1:
        return "it has no triangles"
    unit = collada_unit(file) if file.lower().endswith(".dae") else 1.0
    v = v * unit
    v.flags.writeable = False
    f.flags.writeable = False
    return v, f, unit

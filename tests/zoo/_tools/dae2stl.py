"""Convert the triangles of a COLLADA (.dae) file to a binary STL (used once to build the zoo, see SOURCE.md).

Only what the zoo's one COLLADA collision mesh needs: ``<triangles>`` with a VERTEX input, node
``<matrix>`` transforms (one level) and ``<unit meter>``. Usage: ``python dae2stl.py IN.dae OUT.stl``.
"""

from __future__ import annotations

import struct
import sys
import xml.etree.ElementTree as ET

import numpy as np

NS = "{http://www.collada.org/2005/11/COLLADASchema}"


def convert(src: str, dst: str) -> int:
    """Write the triangles of ``src`` (in metres, node transforms applied) to ``dst``; returns their count."""
    root = ET.parse(src).getroot()
    unit = root.find(f"{NS}asset/{NS}unit")
    scale = float(unit.get("meter", "1")) if unit is not None else 1.0
    geoms = {}
    for g in root.iter(f"{NS}geometry"):
        mesh = g.find(f"{NS}mesh")
        arrays = {
            s.get("id"): np.array(s.find(f"{NS}float_array").text.split(), float) for s in mesh.iter(f"{NS}source")
        }
        verts = mesh.find(f"{NS}vertices")
        pos_src = verts.find(f"{NS}input[@semantic='POSITION']").get("source")[1:]
        pos = arrays[pos_src].reshape(-1, 3)
        tris = []
        for t in mesh.iter(f"{NS}triangles"):
            inputs = t.findall(f"{NS}input")
            stride = max(int(i.get("offset")) for i in inputs) + 1
            off = next(int(i.get("offset")) for i in inputs if i.get("semantic") == "VERTEX")
            idx = np.array(t.find(f"{NS}p").text.split(), int).reshape(-1, stride)[:, off]
            tris.append(pos[idx].reshape(-1, 3, 3))
        geoms["#" + g.get("id")] = np.concatenate(tris)
    out = []
    for node in root.iter(f"{NS}node"):
        inst = node.find(f"{NS}instance_geometry")
        if inst is None:
            continue
        m = node.find(f"{NS}matrix")
        mat = np.array(m.text.split(), float).reshape(4, 4) if m is not None else np.eye(4)
        tri = geoms[inst.get("url")]
        out.append((tri @ mat[:3, :3].T + mat[:3, 3]) * scale)
    tri = np.concatenate(out)
    with open(dst, "wb") as f:
        f.write(b"dae2stl".ljust(80, b" "))
        f.write(struct.pack("<I", len(tri)))
        for t in tri:
            n = np.cross(t[1] - t[0], t[2] - t[0])
            n = n / (np.linalg.norm(n) or 1.0)
            f.write(struct.pack("<12fH", *n, *t.ravel(), 0))
    return len(tri)


if __name__ == "__main__":
    print(convert(sys.argv[1], sys.argv[2]), "triangles")

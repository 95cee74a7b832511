"""A run's ``scene.xml`` that loads on its own (design §12): the asset files copied beside it.

The composed scene names every robot's mesh, skin, height-field and texture file by its absolute
path (:func:`bioform_mj.robots.mjcf.absolute_asset_files`; URDF meshes likewise). :func:`write_scene`
copies each such file into ``assets/`` of the run folder and points the saved XML at the copy, so
the folder can be moved, shared or opened in a viewer (``python -m mujoco.viewer
--mjcf=run/scene.xml``) from any working directory, and the XML holds no path of the machine
that wrote it. Meshes converted on import (COLLADA) are inline vertex data and need no file.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

from bioform_mj.outputs.files import atomic_path, write_text
from bioform_mj.robots.spec_files import CUBE_FACES

__all__ = ["ASSETS_DIR", "ASSET_SUFFIXES", "write_scene", "portable_xml"]

#: folder of a run that holds the copied asset files
ASSETS_DIR = "assets"
#: file suffixes an ``assets/`` folder of a run may hold (the run-folder survey trusts only these)
ASSET_SUFFIXES = (".stl", ".obj", ".msh", ".skn", ".png", ".ktx", ".bin", ".hf", ".jpg", ".jpeg")
#: asset elements and their file attributes (a cube texture has six)
_FILE_ATTRS = {
    "mesh": ("file",),
    "skin": ("file",),
    "hfield": ("file",),
    "texture": ("file", *CUBE_FACES),
}


def portable_xml(xml: str) -> tuple[str, dict[str, str]]:
    """``(xml, {absolute source: name in assets/})``: ``xml`` with every asset file renamed to
    ``assets/NAME`` (one copy per source file; two sources with one name, in any case, get ``-2``, ``-3`` …) and
    the compiler's ``meshdir``/``texturedir``/``assetdir`` removed, and each robot's layout text
    naming its model file by file name only. A relative file name (one no robot resolved) is left
    as it is."""
    root = ET.fromstring(xml)
    copies: dict[str, str] = {}
    taken: set[str] = set()
    for comp in root.iter("compiler"):
        for k in ("meshdir", "texturedir", "assetdir"):
            comp.attrib.pop(k, None)
    for asset in root.iter("asset"):
        for el in asset:
            for attr in _FILE_ATTRS.get(el.tag, ()):
                src = el.get(attr)
                if not src or not Path(src).is_absolute():
                    continue
                if src not in copies:
                    p = Path(src)
                    stem, sfx = p.stem, p.suffix.lower()
                    name, k = stem + sfx, 1
                    while name.lower() in taken:  # one name per file, on case-blind file systems too
                        k += 1
                        name = f"{stem}-{k}{sfx}"
                    taken.add(name.lower())
                    copies[src] = name
                el.set(attr, f"{ASSETS_DIR}/{copies[src]}")
    for text in root.iter("text"):  # the robots' layouts name their files: by file name only
        if (text.get("name") or "").endswith("bioform_layout"):
            raw = text.get("data") if text.get("data") is not None else text.text  # MuJoCo writes a CDATA node
            try:
                lay = json.loads(raw or "")
            except ValueError:
                continue
            if isinstance(lay, dict) and isinstance(lay.get("file"), str):
                lay["file"] = Path(lay["file"]).name
                text.text = None  # MuJoCo reads a text's data from the attribute (or a CDATA node)
                text.set("data", json.dumps(lay))
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n", copies


def write_scene(out: str | Path, xml: str) -> list[str]:
    """Write ``out/scene.xml`` and copy its asset files into ``out/assets/`` (each file atomically);
    returns the names copied. The XML is written last, so a ``scene.xml`` never names a missing copy."""
    out = Path(out)
    text, copies = portable_xml(xml)
    if copies:
        (out / ASSETS_DIR).mkdir(exist_ok=True)
        for src, name in copies.items():
            with atomic_path(out / ASSETS_DIR / name) as tmp:
                tmp.write_bytes(Path(src).read_bytes())
    write_text(out / "scene.xml", text)
    return sorted(copies.values())

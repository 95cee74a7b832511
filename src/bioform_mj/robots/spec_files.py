"""The files a parsed MuJoCo ``MjSpec`` makes its compiler read (design §12; issue 28): one list for every
check and rewrite of them.

:func:`spec_files` yields each mesh's, skin's and height field's ``file`` and each texture's ``file`` and six
cube faces (:data:`CUBE_FACES`). Its users: the escape check (:func:`bioform_mj.robots.mjcf_assets.spec_escape`),
the special-file check (:func:`bioform_mj.robots.sanity.spec_file_problem`), the absolute names of a composed
scene (:func:`bioform_mj.robots.mjcf.absolute_asset_files`) and the check cache's key
(:func:`bioform_mj.assess.prerun.robot_key`); three of them kept lists of their own, and two missed the cube
faces (a FIFO as a face hung the compiler). Imports nothing of the package and nothing of MuJoCo.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["CUBE_FACES", "SpecFile", "spec_files"]

#: a cube or skybox texture's six face files, in the order of ``MjsTexture.cubefiles`` (MuJoCo's XML reader)
CUBE_FACES = ("fileright", "fileleft", "fileup", "filedown", "filefront", "fileback")


@dataclass(frozen=True)
class SpecFile:
    """One file a parsed ``MjSpec``'s compiler will read: ``kind`` (``mesh``, ``skin``, ``hfield``,
    ``texture``), ``attr`` (``file``, or a cube face of :data:`CUBE_FACES`), the ``name`` as written, the
    compiler ``folder`` it is relative to (``meshdir`` or ``texturedir``) and the spec ``element``."""

    kind: str
    attr: str
    name: str
    folder: str
    element: Any

    def path(self, top: str | Path) -> str:
        """The file as MuJoCo's compiler opens it, ``top`` being the model file's folder (an absolute
        name as it is; not made real: a symlink stays a symlink)."""
        return os.path.join(os.path.abspath(top), self.folder or "", self.name)

    def rename(self, name: str) -> None:
        """Point the spec's element at ``name`` instead (a cube face: only that face)."""
        if self.attr == "file":
            self.element.file = name
        else:
            faces = list(self.element.cubefiles)
            faces[CUBE_FACES.index(self.attr)] = name
            self.element.cubefiles = faces


def spec_files(spec: Any) -> Iterator[SpecFile]:
    """Every file a parsed ``MjSpec``'s compiler reads (issue 28: one list for the escape check, the
    special-file check, the absolute names and the check cache's key; the cube faces were missing from
    two): each mesh's, skin's and height field's ``file``, each texture's ``file`` and six cube faces.
    Empty names and names of the spec's own asset dictionary (not files) are left out."""
    own = set(spec.assets) if spec.assets else set()
    groups = [
        ("mesh", spec.meshdir, spec.meshes),
        ("skin", spec.meshdir, spec.skins),
        ("hfield", spec.meshdir, spec.hfields),
        ("texture", spec.texturedir, spec.textures),
    ]
    for kind, folder, elements in groups:
        for el in list(elements):
            names = [("file", el.file)]
            if kind == "texture":
                names += list(zip(CUBE_FACES, el.cubefiles, strict=False))
            for attr, name in names:
                if name and name not in own:
                    yield SpecFile(kind, attr, name, folder or "", el)

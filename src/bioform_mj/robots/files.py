"""Every file a URDF robot loads, for provenance (design §16; issue 28 item 3).

:func:`urdf_files` reads the robot as the import does (:func:`bioform_mj.robots.urdf._parse`: the package
search path of its mapping and the scenario, xacro when asked) and returns the SHA-256 of the file,
of every mesh it names (``package://``, ``model://``, ``file://`` and relative names resolved to the
files the import reads; a mesh that cannot be found is ``"missing"``) and, for a xacro file, of
every file its expansion included or loaded. A resumed sweep whose robot's ``package://`` mesh
changed is then redone (it was recorded as missing and never compared).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["urdf_files"]


def urdf_files(ref: Any, file_hash: Callable[[str | Path], str]) -> dict[str, str]:
    """``{absolute file: file_hash(file)}`` of URDF robot ``ref`` (a resolved :class:`~bioform_mj.robots.refs.RobotRef`;
    ``file_hash``: :func:`bioform_mj.jobs.provenance.file_hash`).

    Raises :class:`~bioform_mj.core.errors.InputError` when the import itself would refuse the robot."""
    from bioform_mj.robots.urdf import _parse, _read_text

    path = Path(ref.model).resolve()
    out = {str(path): file_hash(path)}
    text = _read_text(Path(ref.model), ref.package_path, ref.xacro, ref.xacro_args)
    for f in getattr(text, "includes", ()):
        out[str(Path(f))] = file_hash(f)
    parsed = _parse(Path(ref.model), ref.package_path, ref.xacro, ref.xacro_args, ref.asset_roots)
    for m in re.finditer(r'<mesh\b[^>]*\bfilename="([^"]+)"', parsed.text):
        f = Path(m.group(1))
        if f.is_absolute():
            out[str(f)] = file_hash(f)
    return out

"""Where a URDF's mesh names may point (design §12; issue 28): inside the robot's packages.

:func:`symlink_escape` refuses a mesh that resolves outside its package, through a symlink or ``..``
(a link to ``~/.ssh/id_rsa`` was copied into a run's ``assets/`` under the target's name). No MuJoCo here.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

from bioform_mj.robots.packages import find_package

__all__ = ["symlink_escape", "absolute_escape"]


def symlink_escape(uri: str, packages: Any, urdf: Path, meshdir: Path) -> str:
    """Why the mesh ``uri`` of the URDF ``urdf`` is refused as a symlink out of its package (``""``: it is not).

    A ``package://NAME/…`` mesh must stay inside the package's folder, a relative one inside the URDF's
    package (the nearest folder above it with a ``package.xml``, else the folder above the URDF's) once
    symlinks are followed: a link to ``~/.ssh/id_rsa`` was copied into a run's ``assets/`` under the
    target's name (issue 28). Absolute and ``file://`` names are :func:`absolute_escape`'s."""
    m = re.match(r"^([A-Za-z][A-Za-z0-9+.-]*)://(.*)$", uri)
    if m is None:
        if Path(uri).expanduser().is_absolute():
            return ""
        lexical = os.path.normpath(meshdir / uri)
        root = next((d for d in Path(urdf).absolute().parents if (d / "package.xml").is_file()), None)
        root = str(root) if root is not None else os.path.dirname(os.path.dirname(os.path.abspath(urdf)))
    elif m.group(1).lower() in ("package", "model"):
        name, _, sub = m.group(2).partition("/")
        found, _ = find_package(name, packages, Path(urdf))
        if found is None:
            return ""
        lexical, root = os.path.normpath(Path(found) / sub), str(found)
    else:
        return ""
    real = os.path.realpath(lexical)
    if not _inside(lexical, os.path.abspath(root)):  # package://NAME/../../x, ../../../x
        return f"'{lexical}' is outside its package '{root}': not read"
    if real == lexical or _inside(real, os.path.realpath(root)):
        return ""
    return f"a symlink to '{real}', outside its package '{root}': not read"


def absolute_escape(uri: str, file: Path, packages: Any, urdf: Path, extra: tuple[str, ...] = ()) -> str:
    """Why the absolute (or ``file://``) mesh ``uri``, resolved to ``file``, is refused (``""``: it is not):
    outside, once symlinks are followed, the URDF's package, its ``package_path`` folders, ``extra`` and the
    ``--asset-root`` folders (issue 28: a robot file from a stranger names ``/etc/…`` as a mesh). Relative and
    ``package://`` names are :func:`symlink_escape`'s."""
    from bioform_mj.robots.mjcf_assets import granted_roots

    if not (Path(uri).expanduser().is_absolute() or uri.lower().startswith("file://")):
        return ""
    root = next((d for d in Path(urdf).absolute().parents if (d / "package.xml").is_file()), None)
    own = str(root) if root is not None else os.path.dirname(os.path.dirname(os.path.abspath(urdf)))
    roots = [os.path.realpath(r) for r in (own, *(d for _, d in packages or ()), *extra, *granted_roots())]
    real = os.path.realpath(file)
    if any(_inside(real, r) for r in roots):
        return ""
    via = f" (a symlink to '{real}')" if real != os.path.normpath(str(file)) else ""
    return (
        f"'{file}'{via} is outside the robot's package '{own}' and its package_path folders: not read "
        '(assets kept elsewhere: --asset-root DIR, or asset_roots = ["DIR"] in the robot\'s table; design §12)'
    )


def _inside(path: str, root: str) -> bool:
    return path == root or path.startswith(root.rstrip(os.sep) + os.sep)

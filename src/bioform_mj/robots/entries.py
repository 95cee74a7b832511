"""How a ``plant.robots`` entry resolves to a file (design §10, §12): a shipped name, or a path.

A name with a registered robot format's suffix (:func:`bioform_mj.robots.formats.robot_suffixes`: ``.xml``,
``.urdf``, ``.xacro`` and whatever a registered format adds) or a path separator is a path. Relative paths inside a
TOML file (models, package directories, asset roots) resolve against the directory of that file
(:func:`rebase_entries`, called when the file is read); on the command line against the working directory.
The entry's mapping (:class:`~bioform_mj.robots.refs.RobotRef`) is :mod:`bioform_mj.robots.refs`'. This module
imports nothing of MuJoCo.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

from bioform_mj.core.errors import InputError
from bioform_mj.robots.formats import looks_like_path
from bioform_mj.robots.refs import (
    RobotRef,
    as_ref,
    asset_root_problem,
    is_shipped,
    models_dir,
    rebase_package_path,
    robot_names,
)

__all__ = ["rebase_entries", "resolve_robot"]


def resolve_robot(entry: Any) -> RobotRef:
    """A ``plant.robots`` entry → a :class:`RobotRef` whose ``model`` is an existing file.

    Shipped names (``paper``, ``paper_robot``, ``paper_robot.xml``) map to the package's
    ``models/``; anything else must be a path to a file (``.xml`` MJCF, ``.urdf``/``.xacro`` URDF;
    relative: to the working directory).
    Raises :class:`InputError` naming an unknown robot, a missing file or a missing ``asset_roots`` folder.
    """
    ref = as_ref(entry)
    for folder in ref.asset_roots:
        if why := asset_root_problem(folder):
            raise InputError(f"asset_roots: {why}")
    name = ref.model
    if is_shipped(name) and not Path(name).is_file():
        stem = name[: -len(".xml")] if name.endswith(".xml") else name
        stem = stem[: -len("_robot")] if stem.endswith("_robot") else stem
        return replace(ref, model=str(models_dir() / f"{stem}_robot.xml"))
    path = Path(name)
    if looks_like_path(name):
        from bioform_mj.robots.sanity import not_regular, unstatable  # a FIFO or a device: said, never opened

        if unstatable(path):  # a name too long, a symlink loop: one line, not an OSError (issue 28)
            raise InputError(f"model file {unstatable(path)}")
        if not path.is_file():
            raise InputError(
                f"model file {not_regular(path)}" if not_regular(path) else f"model file '{path}' does not exist"
            )
        return replace(ref, model=str(path))
    raise InputError(f"unknown robot '{name}' (expected one of: {', '.join(robot_names())}, or an MJCF or URDF path)")


def rebase_entries(entries: Any, base_dir: Path) -> Any:
    """``plant.robots`` as read from a TOML file in ``base_dir``: relative MJCF/URDF paths (and a
    table's ``package_path`` directories) made relative to that directory (design §10: paths
    inside a TOML file are relative to the file; a bare ``robot.urdf`` is a path, §12).

    Shipped names and absolute paths are kept; anything that is not a list is returned as is
    (validation reports it).
    """
    if not isinstance(entries, list):
        return entries

    def fix(model: Any) -> Any:
        if not isinstance(model, str) or is_shipped(model) or Path(model).is_absolute():
            return model
        if looks_like_path(model):
            return str((base_dir / model).resolve())
        return model

    out = []
    for e in entries:
        if isinstance(e, str):
            out.append(fix(e))
        elif isinstance(e, Mapping) and "model" in e:
            t = {**e, "model": fix(e["model"])}
            if "package_path" in t:
                t["package_path"] = rebase_package_path(t["package_path"], base_dir)
            if isinstance(t.get("asset_roots"), list):  # design §12: relative to the file, as the model
                t["asset_roots"] = [
                    str((base_dir / v).resolve()) if isinstance(v, str) and v and not Path(v).is_absolute() else v
                    for v in t["asset_roots"]
                ]
            out.append(t)
        else:
            out.append(e)
    return out

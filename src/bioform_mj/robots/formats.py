"""The robot formats (design §12): a registry of the file formats a robot may be written in.

A format is one module that reads it (a loader to a compiled ``MjSpec``) and one line here, :func:`register_format`:
its name, the file suffixes that make a robot entry a path of it, a detector, the loader, what the loader confines,
and whether xacro applies; optionally its checks before any work, its files, its published model, the top wheel
speed its file states and the spec a calibrated copy is written from. :func:`format_of` picks the format of a file
(the first registered whose detector accepts it; MJCF, the fallback, last), and
:func:`bioform_mj.robots.prepare.prepare_robot` loads every robot through it; :func:`robot_suffixes` (every
registered format's suffixes) decides whether a scenario's robot entry is a path (:func:`looks_like_path`,
:mod:`bioform_mj.robots.entries`). Importing it imports no MuJoCo.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from bioform_mj.robots.files import urdf_files
from bioform_mj.robots.mjcf import editable_mjcf, load_mjcf, published_mjcf
from bioform_mj.robots.mjcf_assets import confine_mjcf
from bioform_mj.robots.urdf import URDF_SUFFIXES, check_file, import_urdf, is_urdf, load_urdf, wheel_velocity_limit

__all__ = ["RobotFormat", "format_of", "looks_like_path", "register_format", "robot_formats", "robot_suffixes"]


@dataclass(frozen=True)
class RobotFormat:
    """One robot file format.

    Parameters
    ----------
    name : str
        The format's name (``"mjcf"``, ``"urdf"``).
    suffixes : tuple of str
        Lower-case file suffixes that make a robot entry a path of this format (:func:`robot_suffixes` holds
        them all).
    detect : callable
        ``detect(path) -> bool``: whether the file is of this format.
    load : callable
        ``load(ref, path) -> (spec, model, ref, import notes, keyframe, keyframe qpos, keyframe notes)``: the
        compiled robot; raises ``ModelError`` (exit 2) naming the file.
    confines : str
        What its loader confines, and how (said in the documentation; design §12).
    xacro : bool
        Whether a xacro file of it may be expanded (``--xacro``, design §12).
    precheck : callable or None
        ``precheck(ref)``: the format's checks that need no MuJoCo, run when a scenario is validated (before any
        work); raises ``InputError`` (exit 2). None: none.
    files : callable or None
        ``files(ref, file_hash) -> {path: hash}``: every file the robot reads (a run's provenance, issue 28). None:
        the MJCF include walk (:func:`bioform_mj.jobs.provenance.model_files`).
    published : callable or None
        ``published(ref) -> MjModel``: the robot as its file gives it, with MuJoCo's own collision rules (every pair
        but parent–child), for the overlaps at rest (design §13.1). None: the file compiled as it stands.
    self_collision : bool
        Whether the scene collides the robot's own bodies by default (MJCF: as the file says; URDF: off, the
        Gazebo convention, unless the mapping says ``self_collide``; design §12).
    wheel_speed : callable or None
        ``wheel_speed(ref, path, wheel_joints) -> float or None``: the least top speed (rad/s) the file states for
        the named wheel joints (a robot's limits, design §21), None when a wheel has none; raises when the file
        cannot be read again. None: the format states none.
    wheel_speed_what : str
        What ``wheel_speed`` reads, as the top speed's note names it (``"the URDF's wheel <limit velocity>"``).
    editable : callable or None
        ``editable(ref) -> MjSpec``: the robot as published, uncompiled, asset file names absolute: the spec
        ``bioform robot fit`` writes its calibrated copy (an MJCF file) from. None: a calibrated copy of it
        cannot be written.
    """

    name: str
    suffixes: tuple[str, ...]
    detect: Callable[[Path], bool]
    load: Callable[[Any, Path], tuple[Any, ...]]
    confines: str
    xacro: bool
    precheck: Callable[[Any], None] | None = None
    files: Callable[[Any, Callable[[Any], str]], dict[str, str]] | None = None
    published: Callable[[Any], Any] | None = None
    self_collision: bool = True
    wheel_speed: Callable[[Any, Path, list[str]], float | None] | None = None
    wheel_speed_what: str = "the file's wheel speed limit"
    editable: Callable[[Any], Any] | None = None


_FORMATS: dict[str, RobotFormat] = {}
_FALLBACK: list[RobotFormat] = []


def register_format(fmt: RobotFormat, *, fallback: bool = False) -> None:
    """Register (or replace) a robot format; ``fallback``: the format of any file no other format detects."""
    if not (isinstance(fmt.name, str) and fmt.name) or not callable(fmt.detect) or not callable(fmt.load):
        raise ValueError(f"a robot format needs a name, a detector and a loader, got {fmt!r}")
    _FORMATS[fmt.name] = fmt
    if fallback:
        _FALLBACK[:] = [fmt]


def robot_formats() -> tuple[RobotFormat, ...]:
    """The registered formats, in the order :func:`format_of` tries them (the fallback last)."""
    return tuple(f for f in _FORMATS.values() if f not in _FALLBACK) + tuple(_FALLBACK)


def format_of(path: str | Path) -> RobotFormat:
    """The format of the robot file ``path``: the first registered format whose detector accepts it, else the
    fallback (MJCF: MuJoCo's compiler says what is wrong with a file that is none)."""
    for fmt in robot_formats():
        if fmt in _FALLBACK or fmt.detect(Path(path)):
            return fmt
    raise ValueError(f"{path}: no robot format reads it (registered: {', '.join(_FORMATS)})")


def robot_suffixes() -> tuple[str, ...]:
    """The file suffixes of every registered format (lower case, each once, in registration order): a robot entry
    ending in one is a path (:func:`looks_like_path`)."""
    return tuple(dict.fromkeys(s.lower() for f in robot_formats() for s in f.suffixes))


def looks_like_path(model: str) -> bool:
    """A robot entry with a registered format's suffix or a path separator is a path, never a shipped name."""
    return model.lower().endswith(robot_suffixes()) or "/" in model or "\\" in model


register_format(
    RobotFormat(
        "urdf",
        URDF_SUFFIXES,
        is_urdf,
        load_urdf,
        "package:// paths to the robot's packages (--package-path, $BIOFORM_PACKAGE_PATH, $ROS_PACKAGE_PATH); a "
        "xacro file expands only with --xacro, in a separate process with no environment, 1024 MiB, 30 s",
        True,
        check_file,
        urdf_files,
        lambda ref: import_urdf(replace(ref, self_collide=True)).model,
        False,
        wheel_velocity_limit,
        "the URDF's wheel <limit velocity>",
        lambda ref: import_urdf(ref).spec,
    )
)
register_format(
    RobotFormat(
        "mjcf",
        (".xml",),
        lambda path: str(path).lower().endswith(".xml"),
        load_mjcf,
        "includes and assets (meshdir/texturedir/assetdir, meshes, skins, height fields, textures, attached models) "
        "inside the model file's own folder or an asset root (asset_roots / --asset-root), by real path, before "
        "MuJoCo reads them; no special file, no mesh over the budget",
        False,
        lambda ref: confine_mjcf(ref.model, ref.asset_roots),
        None,
        published_mjcf,
        editable=editable_mjcf,
    ),
    fallback=True,
)

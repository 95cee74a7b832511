"""Robots: an MJCF or URDF file plus a mapping (design §8, §10, §12), and how entries resolve to files.

An entry of ``plant.robots`` is

- a shipped name (``paper``, ``lab``, ``tb3``, ``jackal``: ``models/<name>_robot.xml``),
- a path to an MJCF file or a URDF file (``.urdf``, ``.xacro``: imported by :mod:`bioform_mj.robots.urdf`), or
- a table ``{model = "path.xml", base = "BODY", left_wheel = "JOINT", right_wheel = "JOINT",
  wheel_radius = r, half_track = l, tau_max = τ, motor = "ideal" | "dc", driver = "current" |
  "voltage", casters = ["GEOM or BODY", ...], caster_friction = μ, free_joints = false,
  self_collide = false, package_path = {NAME = "DIR"}, keyframe = "home", balance_inertia = false}``: every
  key but ``model``
  optional; an empty name (or 0 for a number) means "as in the shipped convention" (body
  ``base``, joints ``left_wheel``/``right_wheel``; a URDF: its root link, and the two wheels it
  finds) resp. "read it from the model".

How an entry resolves to a file (a name with a registered format's suffix or a path separator is a path) is
:mod:`bioform_mj.robots.entries`' job, below the format registry (:mod:`bioform_mj.robots.formats`) that this
module's types sit under. What the project then reads from the model is :mod:`bioform_mj.robots.scene`'s
job (:func:`bioform_mj.robots.prepare.prepare_robot`). This module imports nothing of MuJoCo.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from importlib import resources
from pathlib import Path
from typing import Any

from bioform_mj.core.errors import InputError

__all__ = [
    "RobotRef",
    "PackagePath",
    "models_dir",
    "robot_names",
    "as_ref",
    "as_package_path",
    "asset_root_problem",
    "rebase_package_path",
    "package_path_from_args",
]


class PackagePath(tuple):
    """Where ``package://NAME/…`` URIs of a URDF point (design §12): ``((NAME, DIR), …)``, searched
    in order before the environment (``BIOFORM_PACKAGE_PATH``, ``ROS_PACKAGE_PATH``). Written in a
    scenario or a robot table as ``{NAME = "DIR"}``."""

    def merged(self, other: tuple[tuple[str, str], ...]) -> PackagePath:
        """These entries, then those of ``other`` whose names are not here yet."""
        have = {n for n, _ in self}
        return PackagePath((*self, *((n, d) for n, d in other if n not in have)))


def as_package_path(value: Any, key: str) -> PackagePath:
    """A ``{NAME = "DIR"}`` table (or ``[[NAME, DIR], …]``) as a :class:`PackagePath`; raises
    :class:`InputError` naming ``key`` for a malformed one (the directories are checked where the
    URDF is read)."""
    if isinstance(value, PackagePath):
        return value
    if isinstance(value, Mapping):
        items = list(value.items())
    elif isinstance(value, (list, tuple)) and all(isinstance(p, (list, tuple)) and len(p) == 2 for p in value):
        items = [tuple(p) for p in value]
    else:
        raise InputError(f"scenario key '{key}': expected a table {{NAME = \"DIR\"}}, got {value!r}")
    for name, folder in items:
        if not isinstance(name, str) or not name or "/" in name or "\\" in name:
            raise InputError(f"scenario key '{key}': package name {name!r} must be a non-empty name without '/'")
        if not isinstance(folder, str) or not folder or "\x00" in folder:
            raise InputError(f"scenario key '{key}.{name}': expected a directory path, got {folder!r}")
    return PackagePath((str(n), str(d)) for n, d in items)


@dataclass(frozen=True)
class RobotRef:
    """One robot: its MJCF or URDF file and the mapping of the parts the plant drives and reads.

    ``base``: the chassis body (it must carry the model's free joint); ``left_wheel`` /
    ``right_wheel``: the two hinge joints of the driven wheels; ``wheel_radius`` (m) and
    ``half_track`` (m) override what the model tells; ``tau_max`` (N·m): wheel torque limit of
    the motors the plant attaches (default: the model's own drive limit, see
    :func:`bioform_mj.robots.prepare.prepare_robot`). Empty string / 0: the convention / from the model.
    ``top_speed`` (m/s at the tyre) and ``control_rate`` (Hz, the rate the maker's controller commands the wheels
    at, e.g. a ROS 2 diff_drive_controller's ``update_rate``): the maker's figures (design §21, §19); 0: not given.

    ``casters``: geoms or bodies (every collision geom of a body) that are casters (design §13);
    ``caster_friction``: their sliding friction against the floor (they then win the contact
    pair's mixing by priority), negative: as published; ``free_joints``: leave the joints other
    than the wheels free (default: held, design §13).
    ``self_collide``: a URDF robot's links collide with each other (default off, the URDF/Gazebo
    convention; an MJCF robot collides as its file says either way). ``package_path``: where its
    ``package://`` URIs point (:class:`PackagePath`; not part of the mapping proper).
    ``keyframe``: the MJCF keyframe the robot starts and is held in (design §13.2; ``""``: ``home``
    where the file has one, else ``qpos0``; ``"none"``: ``qpos0``).
    ``xacro``: the file may be expanded by xacro, a program, in a sandboxed process
    (:mod:`bioform_mj.robots.xacro_sandbox`; default: a file that needs xacro is refused); ``xacro_args``:
    its ``$(arg NAME)`` values, written ``{NAME = "VALUE"}``.
    ``asset_roots``: folders an MJCF robot's includes and asset files may be in beyond the robot file's
    own folder (:mod:`bioform_mj.robots.mjcf_assets`; default: none; not part of the mapping proper).
    """

    model: str
    base: str = ""
    left_wheel: str = ""
    right_wheel: str = ""
    wheel_radius: float = 0.0
    half_track: float = 0.0
    tau_max: float = 0.0
    motor: str = ""  # "" or "ideal": torque sources (the paper); "dc": the model's <dcmotor> drives
    driver: str = ""  # with motor = "dc": "current" (default) or "voltage" (design §8.2)
    casters: tuple[str, ...] = ()  # geom or body names of casters (design §13)
    caster_friction: float = -1.0  # sliding friction of the casters against the floor; < 0: as published
    free_joints: bool = False  # True: joints other than the wheels left free (default: held, design §13)
    self_collide: bool = False  # URDF only (design §12): keep contacts between the robot's own links
    package_path: PackagePath = PackagePath()  # URDF only: package:// search path, before the environment
    keyframe: str = ""  # MJCF keyframe to start in (design §13.2); "": 'home' if the file has one; "none": qpos0
    top_speed: float = 0.0  # m/s at the tyre, the maker's datasheet figure (design §21); 0: not given
    control_rate: float = 0.0  # Hz, the rate the maker's controller commands the wheels at (design §19); 0: not given
    balance_inertia: bool = False  # MuJoCo's compiler option balanceinertia (an inertia breaking A + B >= C)
    xacro: bool = False  # URDF only (design §12): the file may be expanded by xacro (a program), sandboxed
    xacro_args: tuple[tuple[str, str], ...] = ()  # URDF only: xacro's $(arg NAME) values, ((NAME, VALUE), ...)
    asset_roots: tuple[str, ...] = ()  # MJCF only: folders its files may be in beyond its own (design §12)

    @property
    def mapped(self) -> bool:
        """True when any key beyond ``model`` (and ``package_path``, ``asset_roots``: where files may be) differs
        from its default."""
        return any(
            getattr(self, f.name) != f.default
            for f in fields(self)
            if f.name not in ("model", "package_path", "asset_roots")
        )

    def to_table(self) -> dict[str, Any]:
        """The mapping as a TOML table: ``model`` and every key that differs from its default
        (``package_path`` as ``{NAME = DIR}``)."""
        out: dict[str, Any] = {"model": self.model}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in ("package_path", "xacro_args"):
                if v:
                    out[f.name] = dict(v)
            elif f.name != "model" and v != f.default:
                out[f.name] = list(v) if isinstance(v, tuple) else v
        return out

    def to_entry(self) -> str | dict[str, Any]:
        """The entry as a scenario writes it: the model alone, or the table of :meth:`to_table`."""
        if not self.mapped and not self.package_path and not self.asset_roots:
            return self.model
        return self.to_table()

    def __str__(self) -> str:
        return self.model


_KEYS = tuple(f.name for f in fields(RobotRef))


@functools.cache
def models_dir() -> Path:
    """Directory of the MJCF files installed with the package (looked up once per process: every robot of a team
    resolves its entry, 3 × 1024 times at n = 1024, docs/findings/performance.md)."""
    return Path(str(resources.files("bioform_mj.robots") / "models"))


@functools.cache
def _shipped() -> tuple[str, ...]:
    return tuple(sorted(p.name[: -len("_robot.xml")] for p in models_dir().glob("*_robot.xml")))


def robot_names() -> list[str]:
    """Names of the shipped robots: ``paper`` → ``models/paper_robot.xml``, ``lab`` → ``lab_robot.xml`` … (the
    package's folder listed once per process)."""
    return list(_shipped())


def as_ref(entry: Any, key: str = "plant.robots") -> RobotRef:
    """A ``plant.robots`` entry (name, path, table or :class:`RobotRef`) as a :class:`RobotRef`.

    Checks the table's keys and types only (raises :class:`InputError` naming ``key``); the
    file is not looked at.
    """
    if isinstance(entry, RobotRef):
        return entry
    if isinstance(entry, (str, Path)):
        return RobotRef(model=str(entry))
    if not isinstance(entry, Mapping):
        raise InputError(
            f"scenario key '{key}': expected a robot name, an MJCF or URDF path or a table "
            f"{{model = ..., base = ..., left_wheel = ..., right_wheel = ...}}, got {entry!r}"
        )
    unknown = [k for k in entry if k not in _KEYS]
    if unknown:
        raise InputError(f"scenario key '{key}.{unknown[0]}': unknown key (expected one of: {', '.join(_KEYS)})")
    if "model" not in entry:
        raise InputError(f"scenario key '{key}': a robot table needs 'model' (an MJCF or URDF path or shipped name)")
    kw: dict[str, Any] = {}
    for name, value in entry.items():
        if name == "xacro_args":
            kw[name] = _xacro_args(value, f"{key}.{name}")
        elif name in ("self_collide", "balance_inertia", "xacro"):
            if not isinstance(value, bool):
                raise InputError(f"scenario key '{key}.{name}': expected true or false, got {value!r}")
            kw[name] = value
        elif name == "package_path":
            kw[name] = as_package_path(value, f"{key}.{name}")
        elif name in ("model", "base", "left_wheel", "right_wheel", "motor", "driver", "keyframe"):
            if not isinstance(value, str):
                raise InputError(f"scenario key '{key}.{name}': expected a string, got {value!r}")
            allowed = {"motor": ("", "ideal", "dc"), "driver": ("", "current", "voltage")}.get(name)
            if allowed is not None and value not in allowed:
                raise InputError(
                    f"scenario key '{key}.{name}': expected one of "
                    f"{', '.join(repr(a) for a in allowed if a)}, got {value!r}"
                )
            kw[name] = value
        elif name == "asset_roots":
            if not isinstance(value, (list, tuple)) or not all(
                isinstance(v, str) and v and "\x00" not in v for v in value
            ):
                raise InputError(
                    f"scenario key '{key}.asset_roots': expected an array of directory paths, got {value!r}"
                )
            kw[name] = tuple(value)
        elif name == "casters":
            if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) and v for v in value):
                raise InputError(
                    f"scenario key '{key}.casters': expected an array of geom or body names, got {value!r}"
                )
            kw[name] = tuple(value)
        elif name == "free_joints":
            if not isinstance(value, bool):
                raise InputError(f"scenario key '{key}.free_joints': expected true or false, got {value!r}")
            kw[name] = value
        elif name in ("top_speed", "control_rate"):  # design §21, §19: the maker's figures
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (0 < value < math.inf):
                what = "m/s at the tyre" if name == "top_speed" else "Hz, the rate its controller runs at"
                raise InputError(
                    f"scenario key '{key}.{name}': expected a finite number > 0 ({what}, the maker's figure), "
                    f"got {value!r}"
                )
            kw[name] = float(value)
        else:  # finite (design §17: tau_max = inf was taken as "no limit" while robot check refused it)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (0 <= value < math.inf):
                raise InputError(f"scenario key '{key}.{name}': expected a finite number >= 0, got {value!r}")
            kw[name] = float(value)
    if kw.get("driver") and kw.get("motor") != "dc":  # the driver is the DC motor's: refused, never ignored
        raise InputError(
            f"scenario key '{key}.driver': driver = {kw['driver']!r} applies only with motor = \"dc\" "
            f"(this robot's motor is {kw.get('motor') or 'ideal'!r}: torque sources, no driver); "
            f'add motor = "dc" or remove driver'
        )
    return RobotRef(**kw)


def _xacro_args(value: Any, key: str) -> tuple[tuple[str, str], ...]:
    """A ``{NAME = "VALUE"}`` table of xacro ``$(arg)`` values as ``((NAME, VALUE), …)`` (numbers and
    booleans as xacro writes them); raises :class:`InputError` naming ``key``."""
    if isinstance(value, tuple) and all(isinstance(p, tuple) and len(p) == 2 for p in value):
        return value
    if not isinstance(value, Mapping):
        raise InputError(f"scenario key '{key}': expected a table {{NAME = \"VALUE\"}}, got {value!r}")
    out = []
    for name, v in value.items():
        if not isinstance(name, str) or not name or not (name[0].isalpha() or name[0] == "_"):
            raise InputError(f"scenario key '{key}': xacro arg name {name!r} must start with a letter or '_'")
        if isinstance(v, bool):
            v = "true" if v else "false"
        if not isinstance(v, (str, int, float)) or "\n" in str(v) or "\x00" in str(v):
            raise InputError(f"scenario key '{key}.{name}': expected a string or a number, got {v!r}")
        out.append((name, str(v)))
    return tuple(out)


def is_shipped(model: str) -> bool:
    stem = model[: -len(".xml")] if model.endswith(".xml") else model
    stem = stem[: -len("_robot")] if stem.endswith("_robot") else stem
    return "/" not in model and "\\" not in model and stem in robot_names()


def asset_root_problem(folder: str) -> str:
    """Why an ``asset_roots`` entry cannot be an MJCF robot's asset folder (``""``: it can): it must be an
    existing, readable directory (``~`` expanded). A typo was taken in silently and surfaced only as an
    "outside the robot's folder" refusal naming the roots (issue 28)."""
    import os

    from bioform_mj.robots.sanity import unstatable

    d = os.path.expanduser(folder)
    if unstatable(d):
        return unstatable(d)
    if not os.path.exists(d):
        return f"'{folder}' does not exist (a typo? relative paths in a scenario file are relative to the file)"
    if not os.path.isdir(d):
        return f"'{folder}' is not a directory"
    if not os.access(d, os.R_OK | os.X_OK):
        return f"'{folder}' cannot be read (permission denied)"
    return ""


def package_path_from_args(values: list[str] | None, flag: str = "--package-path") -> PackagePath:
    """``--package-path NAME=DIR`` flags (repeatable) as a :class:`PackagePath` of absolute
    directories (relative: to the working directory); raises :class:`InputError` naming the flag."""
    out = []
    for v in values or ():
        name, sep, folder = v.partition("=")
        name, folder = name.strip(), folder.strip()
        if not sep or not name or not folder or "/" in name:
            raise InputError(f"{flag} '{v}': expected NAME=DIR, e.g. {flag} turtlebot3_description=~/ws/src/turtlebot3")
        d = Path(folder).expanduser()
        if not d.is_dir():
            raise InputError(f"{flag} {name}={folder}: no such directory")
        out.append((name, str(d.resolve())))
    return PackagePath(out)


def rebase_package_path(table: Any, base_dir: Path) -> Any:
    """A ``{NAME = "DIR"}`` table read from a TOML file in ``base_dir``: relative directories made
    relative to that directory (anything else is returned as is; validation reports it)."""
    if not isinstance(table, Mapping):
        return table
    return {
        k: str((base_dir / v).resolve()) if isinstance(v, str) and v and not Path(v).is_absolute() else v
        for k, v in table.items()
    }

"""Robots: an MJCF file plus a mapping (design §8, §10), and how entries resolve to files.

An entry of ``plant.robots`` is

- a shipped name (``paper``, ``lab``, ``tb3``, ``jackal``: ``models/<name>_robot.xml``),
- a path to an MJCF file, or
- a table ``{model = "path.xml", base = "BODY", left_wheel = "JOINT", right_wheel = "JOINT",
  wheel_radius = r, half_track = l, tau_max = τ, motor = "ideal" | "dc", driver = "current" |
  "voltage", casters = ["GEOM or BODY", ...], caster_friction = μ, free_joints = false}``: every key
  but ``model`` optional; an empty
  name (or 0 for a number) means "as in the shipped convention" (body ``base``, joints
  ``left_wheel``/``right_wheel``) resp. "read it from the model".

Relative paths inside a TOML file resolve against the directory of that file
(:func:`rebase_entries`, called when the file is read); on the command line against the
working directory. What the project then reads from the model is :mod:`bioform_mj.scene`'s
job (:func:`bioform_mj.scene.prepare_robot`). This module imports nothing of MuJoCo.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from importlib import resources
from pathlib import Path
from typing import Any

from .errors import InputError

__all__ = ["RobotRef", "models_dir", "robot_names", "resolve_robot", "as_ref", "rebase_entries"]


@dataclass(frozen=True)
class RobotRef:
    """One robot: its MJCF file and the mapping of the parts the plant drives and reads.

    ``base``: the chassis body (it must carry the model's free joint); ``left_wheel`` /
    ``right_wheel``: the two hinge joints of the driven wheels; ``wheel_radius`` (m) and
    ``half_track`` (m) override what the model tells; ``tau_max`` (N·m): wheel torque limit of
    the motors the plant attaches (default: the model's own drive limit, see
    :func:`bioform_mj.scene.prepare_robot`). Empty string / 0: the convention / from the model.

    ``casters``: geoms or bodies (every collision geom of a body) that are casters (design §13);
    ``caster_friction``: their sliding friction against the floor (they then win the contact
    pair's mixing by priority), negative: as published; ``free_joints``: leave the joints other
    than the wheels free (default: held, design §13).
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

    @property
    def mapped(self) -> bool:
        """True when any key beyond ``model`` is given."""
        return any(getattr(self, f.name) != f.default for f in fields(self) if f.name != "model")

    def to_table(self) -> dict[str, Any]:
        """The mapping as a TOML table: ``model`` and every key that differs from its default."""
        out: dict[str, Any] = {"model": self.model}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name != "model" and v != f.default:
                out[f.name] = list(v) if isinstance(v, tuple) else v
        return out

    def __str__(self) -> str:
        return self.model


_KEYS = tuple(f.name for f in fields(RobotRef))


def models_dir() -> Path:
    """Directory of the MJCF files installed with the package."""
    return Path(str(resources.files("bioform_mj") / "models"))


def robot_names() -> list[str]:
    """Names of the shipped robots: ``paper`` → ``models/paper_robot.xml``, ``lab`` → ``lab_robot.xml`` …"""
    return sorted(p.name[: -len("_robot.xml")] for p in models_dir().glob("*_robot.xml"))


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
            f"scenario key '{key}': expected a robot name, an MJCF path or a table "
            f"{{model = ..., base = ..., left_wheel = ..., right_wheel = ...}}, got {entry!r}"
        )
    unknown = [k for k in entry if k not in _KEYS]
    if unknown:
        raise InputError(f"scenario key '{key}.{unknown[0]}': unknown key (expected one of: {', '.join(_KEYS)})")
    if "model" not in entry:
        raise InputError(f"scenario key '{key}': a robot table needs 'model' (an MJCF path or shipped name)")
    kw: dict[str, Any] = {}
    for name, value in entry.items():
        if name in ("model", "base", "left_wheel", "right_wheel", "motor", "driver"):
            if not isinstance(value, str):
                raise InputError(f"scenario key '{key}.{name}': expected a string, got {value!r}")
            allowed = {"motor": ("", "ideal", "dc"), "driver": ("", "current", "voltage")}.get(name)
            if allowed is not None and value not in allowed:
                raise InputError(
                    f"scenario key '{key}.{name}': expected one of "
                    f"{', '.join(repr(a) for a in allowed if a)}, got {value!r}"
                )
            kw[name] = value
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


def _is_shipped(model: str) -> bool:
    stem = model[: -len(".xml")] if model.endswith(".xml") else model
    stem = stem[: -len("_robot")] if stem.endswith("_robot") else stem
    return "/" not in model and "\\" not in model and stem in robot_names()


def resolve_robot(entry: Any) -> RobotRef:
    """A ``plant.robots`` entry → a :class:`RobotRef` whose ``model`` is an existing file.

    Shipped names (``paper``, ``paper_robot``, ``paper_robot.xml``) map to the package's
    ``models/``; anything else must be a path to a file (relative: to the working directory).
    Raises :class:`InputError` naming an unknown robot or a missing file.
    """
    ref = as_ref(entry)
    name = ref.model
    if _is_shipped(name) and not Path(name).is_file():
        stem = name[: -len(".xml")] if name.endswith(".xml") else name
        stem = stem[: -len("_robot")] if stem.endswith("_robot") else stem
        return replace(ref, model=str(models_dir() / f"{stem}_robot.xml"))
    path = Path(name)
    if path.suffix.lower() == ".xml" or "/" in name or "\\" in name:
        if not path.is_file():
            raise InputError(f"model file '{path}' does not exist")
        return replace(ref, model=str(path))
    raise InputError(f"unknown robot '{name}' (expected one of: {', '.join(robot_names())}, or an MJCF path)")


def rebase_entries(entries: Any, base_dir: Path) -> Any:
    """``plant.robots`` as read from a TOML file in ``base_dir``: relative MJCF paths made
    relative to that directory (design §10: paths inside a TOML file are relative to the file).

    Shipped names and absolute paths are kept; anything that is not a list is returned as is
    (validation reports it).
    """
    if not isinstance(entries, list):
        return entries

    def fix(model: Any) -> Any:
        if not isinstance(model, str) or _is_shipped(model) or Path(model).is_absolute():
            return model
        if model.lower().endswith(".xml") or "/" in model or "\\" in model:
            return str((base_dir / model).resolve())
        return model

    out = []
    for e in entries:
        if isinstance(e, str):
            out.append(fix(e))
        elif isinstance(e, Mapping) and "model" in e:
            out.append({**e, "model": fix(e["model"])})
        else:
            out.append(e)
    return out

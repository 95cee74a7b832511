"""Shipped robot models (``bioform_mj/models/*.xml``) and how names resolve to files."""
from __future__ import annotations

from importlib import resources
from pathlib import Path

from .errors import InputError


def models_dir() -> Path:
    """Directory of the MJCF files installed with the package."""
    return Path(str(resources.files("bioform_mj") / "models"))


def robot_names() -> list[str]:
    """Names of the shipped robots: ``paper`` → ``models/paper_robot.xml``, ``lab`` → ``lab_robot.xml``."""
    return sorted(p.name[: -len("_robot.xml")] for p in models_dir().glob("*_robot.xml"))


def resolve_robot(name_or_path: str) -> Path:
    """A shipped robot name (``paper``, ``lab``) or a path to an MJCF file → an existing file path."""
    if name_or_path in robot_names():
        return models_dir() / f"{name_or_path}_robot.xml"
    path = Path(name_or_path)
    if path.suffix.lower() == ".xml" or "/" in name_or_path:
        if not path.is_file():
            raise InputError(f"model file '{path}' does not exist")
        return path
    raise InputError(f"unknown robot '{name_or_path}' (expected one of: {', '.join(robot_names())}, or an MJCF path)")

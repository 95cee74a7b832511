"""No absolute path of the machine in a run's files (design §10): ``summary.json`` and ``resolved.toml`` name robot
files and package folders relative to the run's own folder.

A run's record must load back (``bioform run runs/X/summary.json``): :func:`bioform_mj.scenario.loader.load` rebases
relative robot paths (and ``package_path`` folders) against the folder of the file it reads, so a path relative
to the output folder is the same file on reloading, wherever the folder was moved together with the robot
files. Every other string of the summary that quotes such a path (a warning naming the robot's file) says it
the same way.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

__all__ = ["relative_paths"]


def _absolute_paths(config: dict[str, Any]) -> list[str]:
    """The absolute robot files and package folders the configuration ``config`` names."""
    plant = config.get("plant") or {}
    found: list[str] = []

    def package(pp: Any) -> None:
        if isinstance(pp, dict):
            for v in pp.values():
                for d in v if isinstance(v, list) else [v]:
                    if isinstance(d, str) and os.path.isabs(d):
                        found.append(d)

    for r in plant.get("robots") or []:
        model = r.get("model") if isinstance(r, dict) else r
        if isinstance(model, str) and os.path.isabs(model):
            found.append(model)
        if isinstance(r, dict):
            package(r.get("package_path"))
    package(plant.get("package_path"))
    return sorted(set(found), key=len, reverse=True)  # the longest first: a file before its folder


def relative_paths(summary: dict[str, Any], out_dir: Path) -> dict[str, Any]:
    """A copy of ``summary`` whose absolute robot files and package folders (as its ``config`` names them) are
    relative to ``out_dir`` (the folder the summary is written to) in every string it holds."""
    base = Path(out_dir).resolve()
    table = [(p, os.path.relpath(p, base)) for p in _absolute_paths(summary.get("config") or {})]
    if not table:
        return summary

    def fix(obj: Any) -> Any:
        if isinstance(obj, str):
            for a, r in table:
                if a in obj:
                    obj = r if obj == a else obj.replace(a, r)
            return obj
        if isinstance(obj, dict):
            return {k: fix(v) for k, v in obj.items()}
        if isinstance(obj, list):
            return [fix(v) for v in obj]
        return obj

    return fix(summary)

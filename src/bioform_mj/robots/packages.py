"""Where ``package://NAME/…`` points: the package search path of URDF robots (design §12).

Order: the robot's/scenario's ``package_path`` (``--package-path NAME=DIR``), then
``BIOFORM_PACKAGE_PATH``, ``ROS_PACKAGE_PATH``, ``AMENT_PREFIX_PATH``, then the URDF file's own
parent folders (:func:`find_package`). Used for mesh URIs (:func:`resolve_uri`) and xacro's
``$(find NAME)``. No MuJoCo here.
"""

from __future__ import annotations

import functools
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

from bioform_mj.core.errors import InputError
from bioform_mj.robots.refs import PackagePath

# at the top, not in _package_name: the xacro child (design §12) imports this module before its audit hook, and a
# later import (reading a .py or .pyc) is refused there
from bioform_mj.robots.sanity import not_regular, parse_xml

__all__ = ["find_package", "package_search_path", "resolve_uri"]

#: how deep a directory of ``ROS_PACKAGE_PATH`` is searched for a package (ROS crawls without end)
_CRAWL_DEPTH = 3
_NO_PACKAGES = PackagePath()


def _package_name(d: Path) -> str | None:
    """The ``<name>`` in ``d/package.xml``, None without one (or when it is no regular file: a FIFO would block;
    or above 1 MB: a manifest is a few kB, and a huge one on ``ROS_PACKAGE_PATH`` would be parsed whole)."""
    if not_regular(d / "package.xml"):
        return None
    try:
        if (d / "package.xml").stat().st_size > 10**6:
            return None
        return (parse_xml(d / "package.xml").findtext("name") or "").strip() or None
    except (OSError, ET.ParseError):
        return None


def _in_dir(d: Path, name: str) -> Path | None:
    """Package ``name`` in the ``ROS_PACKAGE_PATH``-style directory ``d``: ``d`` itself (its name or its
    ``package.xml`` says so), ``d/NAME``, or a package below ``d`` (at most :data:`_CRAWL_DEPTH`
    levels; a package's own subfolders are not searched, as ROS does)."""
    if not d.is_dir():
        return None
    if d.name == name or _package_name(d) == name:
        return d
    if (d / name).is_dir():
        return d / name
    found = _crawl(str(d), d.stat().st_mtime_ns).get(name)
    return Path(found) if found else None


@functools.lru_cache(maxsize=32)
def _crawl(d: str, mtime_ns: int) -> dict[str, str]:
    """``{package name: folder}`` of the packages below ``d`` (by folder name and ``package.xml``
    name, at most :data:`_CRAWL_DEPTH` levels, none inside a package): one walk per folder and
    process, however many meshes name it (``mtime_ns``: a folder changed since is walked again)."""
    del mtime_ns
    out: dict[str, str] = {}
    top = len(Path(d).parts)
    for dirpath, dirnames, filenames in os.walk(d):
        here = Path(dirpath)
        if "package.xml" in filenames and str(here) != d:
            for key in (here.name, _package_name(here)):
                if key:
                    out.setdefault(key, str(here))
            dirnames[:] = []  # ROS: no package inside a package
            continue
        if len(here.parts) - top >= _CRAWL_DEPTH:
            dirnames[:] = []
        dirnames[:] = sorted(n for n in dirnames if not n.startswith("."))
    return out


def package_search_path(packages: PackagePath = _NO_PACKAGES) -> list[str]:
    """The search path as words, in order (for messages and ``docs/robots-urdf.md``)."""
    out = [f"{n}={d}" for n, d in packages]
    for var in ("BIOFORM_PACKAGE_PATH", "ROS_PACKAGE_PATH", "AMENT_PREFIX_PATH"):
        val = os.environ.get(var, "")
        if val:
            out.append(f"${var}={val}")
    out.append("the URDF file's parent folders")
    return out


def find_package(name: str, packages: PackagePath = _NO_PACKAGES, near: Path | None = None) -> tuple[Path | None, str]:
    """``(directory, how it was found)`` of package ``name``, ``(None, "")`` if nothing resolves it.

    Order: ``packages`` (a mapping's/scenario's ``package_path``, ``--package-path``), then
    ``BIOFORM_PACKAGE_PATH`` (``:``-separated ``NAME=DIR`` or ``DIR`` entries, a ``DIR`` read as in
    ``ROS_PACKAGE_PATH``), ``ROS_PACKAGE_PATH`` (``:``-separated directories, each the package
    itself or a folder holding packages), ``AMENT_PREFIX_PATH`` (``PREFIX/share/NAME``, ROS 2), and
    last the parent folders of ``near`` (the URDF file: one whose ``package.xml`` names ``name``, or the file's own
    package folder by its name, ``NAME/urdf/robot.urdf``: :func:`_parent_package`) — a guess, said by the caller.
    An empty name (``package:///etc/passwd``) resolves to nothing: the root folder's name is
    empty, so the parent-folder guess took ``/`` as the package and a robot file read any file (issue 28).
    """
    if not name or name in (".", ".."):
        return None, ""
    for n, d in packages:
        if n == name:
            p = Path(d).expanduser()
            if not p.is_dir():
                raise InputError(f"package_path {name}={d}: no such directory")
            return p.resolve(), f"package_path {name}={d}"
    for entry in filter(None, os.environ.get("BIOFORM_PACKAGE_PATH", "").split(os.pathsep)):
        n, sep, d = entry.partition("=")
        if sep:
            if n == name and Path(d).expanduser().is_dir():
                return Path(d).expanduser().resolve(), f"BIOFORM_PACKAGE_PATH {entry}"
        elif (hit := _in_dir(Path(entry).expanduser(), name)) is not None:
            return hit.resolve(), f"BIOFORM_PACKAGE_PATH {entry}"
    for entry in filter(None, os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep)):
        if (hit := _in_dir(Path(entry).expanduser(), name)) is not None:
            return hit.resolve(), f"ROS_PACKAGE_PATH {entry}"
    for entry in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        hit = Path(entry).expanduser() / "share" / name
        if hit.is_dir():
            return hit.resolve(), f"AMENT_PREFIX_PATH {entry}"
    if near is not None and (d := _parent_package(Path(near).resolve(), name)) is not None:
        return d, "a parent folder of the URDF file"
    return None, ""


def _parent_package(urdf: Path, name: str) -> Path | None:
    """The parent folder of ``urdf`` that is package ``name`` (None: none is): a parent folder whose
    ``package.xml`` names ``name``, or the robot's own package folder named ``name`` — the nearest parent
    holding a ``package.xml``, or without one the ROS layout ``NAME/urdf/robot.urdf`` (the file's folder
    ``urdf``, or the file's folder itself). Any parent folder named ``name`` had matched: a URDF anywhere
    under ``/root`` resolved ``package://root/…`` in ``/root`` (issue 28)."""
    parents = list(urdf.parents)
    own = next((d for d in parents if (d / "package.xml").exists()), None)
    for d in parents:
        if (d / "package.xml").is_file() and _package_name(d) == name:
            return d
    if own is None:  # no package.xml above the file: NAME/urdf/robot.urdf or NAME/robot.urdf
        own = parents[1] if len(parents) > 1 and parents[0].name == "urdf" else parents[0]
    return own if own.name == name else None


_URI = re.compile(r"^(?P<scheme>[A-Za-z][A-Za-z0-9+.-]*)://(?P<rest>.*)$")


def resolve_uri(uri: str, packages: PackagePath, urdf: Path, meshdir: Path) -> tuple[Path | None, str, str]:
    """``(absolute path or None, why not, how found)`` of a mesh ``filename``."""
    m = _URI.match(uri)
    if m is None:
        p = Path(uri).expanduser()
        return (p if p.is_absolute() else (meshdir / p)).resolve(), "", ""
    scheme, rest = m.group("scheme").lower(), m.group("rest")
    if scheme == "file":
        return Path(rest if rest.startswith("/") else "/" + rest).resolve(), "", ""
    if scheme in ("package", "model"):  # model:// (Gazebo) is searched like a package
        name, _, sub = rest.partition("/")
        if not name or name in (".", ".."):
            return None, f"{scheme}://{name}/ names no package ({scheme}://NAME/PATH)", ""
        found, how = find_package(name, packages, urdf)
        if found is None:
            return (
                None,
                f"package '{name}' is on no search path (searched: {'; '.join(package_search_path(packages))}; "
                f'give --package-path {name}=DIR or plant.package_path = {{{name} = "DIR"}})',
                "",
            )
        return (found / sub).resolve(), "", f"package '{name}' from {how}"
    return None, f"URI scheme '{scheme}://' is not supported (package://, file:// or a path)", ""

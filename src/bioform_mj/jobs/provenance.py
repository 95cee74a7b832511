"""What a result depends on beyond its scenario: the code and every file a robot model loads (design §16).

A sweep row or a calibration evaluation records :func:`provenance` of the scenario it ran;
a resume compares the record with the present one (:func:`differences`) and redoes the work
when anything changed, saying what. Three parts:

* ``code``: a SHA-256 over the package's Python sources (every ``*.py`` under
  ``bioform_mj/``, names and contents; computed once per process, ~2 ms), beside the
  package version and, for the MuJoCo plant, the MuJoCo version. numba's cache is keyed by a subset of these
  files (``control/equations._cache_dir``: the kernel modules); a result also depends on
  the scenario loader, the metrics and the sweep itself, so the whole package counts.
* ``files``: for every robot model of a MuJoCo scenario, the SHA-256 of the model file and
  of each file it loads: ``<include file>`` (recursively), mesh / height-field / texture /
  skin files (``file``, ``filename`` and the cube-texture ``file*`` attributes), resolved as
  MuJoCo does (``compiler`` ``meshdir`` / ``texturedir`` / ``assetdir`` relative to the main
  file's folder, then the folder itself). A file that cannot be found is recorded as
  ``"missing"``, so that its later appearance also counts as a change. A URDF robot's files are
  the ones its import reads (:func:`bioform_mj.robots.files.urdf_files`: ``package://`` meshes
  through the package search path, a xacro file's includes).
* the hashes are cached per ``(path, size, mtime)`` in this process: a 1,000-row resume
  hashes each model once.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from bioform_mj._version import __version__
from bioform_mj.core.codehash import code_hash
from bioform_mj.robots.sanity import parse_xml
from bioform_mj.robots.spec_files import CUBE_FACES

#: attributes that name a file MuJoCo loads (MJCF and URDF)
_FILE_ATTRS = ("file", "filename", *CUBE_FACES)
#: element tag → which compiler folder its file is relative to
_DIR_OF = {"mesh": "meshdir", "skin": "meshdir", "hfield": "meshdir", "texture": "texturedir"}

_CODE: dict[str, str] = {}
_FILE_CACHE: dict[tuple[str, int, int], str] = {}
_MODEL_CACHE: dict[tuple, dict[str, str]] = {}


def _mujoco_version() -> str:
    if "mujoco" not in _CODE:
        try:  # the module's own version: importlib.metadata scans site-packages (~80 ms), this is ~1 ms when
            import mujoco  # the plant has loaded it already (a MuJoCo sweep has)

            _CODE["mujoco"] = str(mujoco.__version__)
        except Exception:  # noqa: BLE001 - not installed: the ideal plant does not need it
            _CODE["mujoco"] = "absent"
    return _CODE["mujoco"]


def file_hash(path: str | Path) -> str:
    """SHA-256 (16 hex digits) of a file's bytes, or ``"missing"``; cached per (path, size, mtime)."""
    p = str(path)
    try:
        st = os.stat(p)
    except OSError:
        return "missing"
    key = (p, st.st_size, st.st_mtime_ns)
    h = _FILE_CACHE.get(key)
    if h is None:
        try:
            with open(p, "rb") as fh:
                h = hashlib.file_digest(fh, "sha256").hexdigest()[:16]
        except OSError:
            return "missing"
        _FILE_CACHE[key] = h
    return h


def _resolve(name: str, candidates: list[Path]) -> Path:
    """The first of ``candidate / name`` that exists (absolute ``name`` as is); else the first candidate's."""
    p = Path(name)
    if p.is_absolute():
        return p
    for c in candidates:
        q = c / p
        if q.is_file():
            return q
    return candidates[0] / p


def model_files(path: str | Path) -> dict[str, str]:
    """``{file: hash}`` of a robot model and of every file it includes or loads (see the module doc).

    Paths are absolute strings; an unreadable or malformed XML is hashed as bytes and not walked
    (the run itself reports the problem).
    """
    main = Path(path).resolve()
    try:
        st = main.stat()
        ck: tuple = (str(main), st.st_size, st.st_mtime_ns)
    except OSError:
        return {str(main): "missing"}
    got = _MODEL_CACHE.get(ck)
    if got is not None and all(file_hash(f) == h for f, h in got.items() if f != str(main)):
        return dict(got)
    base = main.parent
    out: dict[str, str] = {}
    dirs: dict[str, Path] = {}
    todo = [main]
    while todo:
        f = todo.pop(0)
        if str(f) in out:
            continue
        out[str(f)] = file_hash(f)
        try:
            root = parse_xml(f)  # fed whole (a huge attribute: quadratic in chunks)
        except (ET.ParseError, OSError):
            continue
        for comp in root.iter("compiler"):  # MuJoCo: the last compiler element wins; assetdir sets both
            for k in ("assetdir", "meshdir", "texturedir"):
                v = comp.get(k)
                if v:
                    d = Path(v) if Path(v).is_absolute() else base / v
                    if k == "assetdir":
                        dirs.setdefault("meshdir", d)
                        dirs.setdefault("texturedir", d)
                    else:
                        dirs[k] = d
        for el in root.iter():
            tag = el.tag if isinstance(el.tag, str) else ""
            for a in _FILE_ATTRS:
                name = el.get(a)
                if not name:
                    continue
                if name.startswith("package://"):  # URDF: relative to the package; try the model's folder
                    name = name.split("/", 3)[-1]
                if tag == "include":
                    todo.append(_resolve(name, [base, f.parent]).resolve())
                elif tag == "model":  # an attached MJCF (asset <model file>): walk it too
                    todo.append(_resolve(name, [base, f.parent]).resolve())
                else:
                    cands = [dirs[_DIR_OF[tag]]] if tag in _DIR_OF and _DIR_OF[tag] in dirs else []
                    q = _resolve(name, [*cands, base, f.parent])
                    with contextlib.suppress(OSError):
                        q = q.resolve()
                    out[str(q)] = file_hash(q)
    _MODEL_CACHE[ck] = dict(out)
    return out


def provenance(sc: Any) -> dict[str, Any]:
    """What a run of scenario ``sc`` depends on beyond ``sc.to_dict()``: versions, code hash, model files."""
    files: dict[str, str] = {}
    mj = None  # the ideal plant does not use MuJoCo
    if sc.plant.kind == "mujoco":
        mj = _mujoco_version()
        from bioform_mj.core.errors import BioformError
        from bioform_mj.robots.entries import resolve_robot

        for r in sc.plant.robots:
            with contextlib.suppress(BioformError, OSError):
                ref = resolve_robot(r)
                try:  # a URDF: its package:// meshes and xacro includes, as the import finds them (issue 28)
                    from bioform_mj.robots.formats import format_of

                    read = format_of(ref.model).files  # design §12: the robot's format says what it reads
                    files.update(read(ref, file_hash) if read is not None else model_files(ref.model))
                except BioformError:
                    files.update(model_files(ref.model))
    return {"version": __version__, "code": code_hash(), "mujoco": mj, "files": files}


def differences(old: Any, new: dict[str, Any]) -> list[str]:
    """Why a result recorded with provenance ``old`` is stale under ``new`` (empty: it is not)."""
    if not isinstance(old, dict):
        return ["it was written without a record of the code and robot files (an older bioform_mj)"]
    why = []
    if old.get("version") != new["version"]:
        why.append(f"package version changed: {old.get('version')} -> {new['version']}")
    if old.get("code") != new["code"]:
        why.append("code changed (source hash of bioform_mj)")
    if old.get("mujoco") != new["mujoco"]:
        why.append(f"MuJoCo version changed: {old.get('mujoco')} -> {new['mujoco']}")
    of, nf = old.get("files") or {}, new["files"]
    for f in sorted(set(of) | set(nf)):
        if of.get(f) != nf.get(f):
            what = "added" if f not in of else ("no longer used" if f not in nf else "changed")
            why.append(f"robot file {what}: {f}")
    return why

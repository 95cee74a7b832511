"""Where an MJCF robot's files may be (design §12; issue 28): inside the robot's own folder.

A URDF's meshes stay inside the robot's packages (:mod:`bioform_mj.robots.mesh_paths`); an MJCF robot's
``<include file>``, its ``<compiler meshdir/texturedir/assetdir>``, and every ``mesh``, ``skin``, ``hfield``,
``texture`` (``file`` and the cube faces' ``file*``), ``flexcomp`` and ``model`` file stay inside the folder
of the robot's file, once symlinks are followed. Anything else is refused with one
:class:`~bioform_mj.core.errors.InputError` line naming the element and the path, **before MuJoCo reads
anything**: :func:`confine_mjcf` walks the XML (the include chain too) with the standard library's parser;
:func:`open_mjcf` then lets MuJoCo parse it and checks the spec's asset files again as its compiler will
resolve them (:func:`spec_escape`), before compiling.

A user who keeps assets elsewhere names the folders: ``asset_roots = ["DIR", …]`` in the robot's table
(relative to the scenario file), or ``--asset-root DIR`` (repeatable) on the command line
(:func:`grant_roots`, for every robot of the process). No MuJoCo import at module level.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from bioform_mj.core.errors import InputError
from bioform_mj.robots.sanity import IMAGE_MAX_PIXELS
from bioform_mj.robots.spec_files import CUBE_FACES, spec_files

__all__ = [
    "MJCF_MAX_MB",
    "INCLUDE_DEPTH",
    "MJCF_MAX_BODIES",
    "MJCF_MAX_GEOMS",
    "MJCF_MAX_ELEMENTS",
    "MJCF_MAX_INCLUDES",
    "MJCF_MAX_FILES_MB",
    "MJCF_MAX_KEYS",
    "MJCF_MAX_USER",
    "MJCF_MAX_HFIELD",
    "MJCF_MAX_TEXTURE",
    "AssetEscape",
    "grant_roots",
    "granted_roots",
    "roots_from_args",
    "add_flag",
    "allowed_roots",
    "confine_mjcf",
    "spec_escape",
    "open_mjcf",
]

#: largest MJCF file (main or included) walked, MB; a published robot's is well under 1 MB
MJCF_MAX_MB = 64
#: most ``<body>`` and ``<geom>`` elements an MJCF robot (includes and attached models together) may have: a
#: published robot has a few hundred; 10^5 bodies ran ``robot check`` past 590 s, deaf to SIGTERM (issue 28)
MJCF_MAX_BODIES, MJCF_MAX_GEOMS = 5000, 20000
#: most elements an MJCF robot may have in all (sites, sensors, keys, … too), each counted as many times as
#: the ``<replicate count>`` elements around it repeat it: 10^6 sites, or one geom in ``<replicate
#: count="1000000">``, ran ``robot check`` past 45 s (issue 28)
MJCF_MAX_ELEMENTS = 100_000
#: most keyframes (``<size nkey>``) and user numbers per element (``<size nuser_*>``) a robot may ask for:
#: ``nkey="100000000"`` allocated for minutes (MuJoCo sizes them before reading anything else)
MJCF_MAX_KEYS, MJCF_MAX_USER = 10_000, 1000
#: most samples of a height field (``nrow`` × ``ncol``) and pixels of a texture (``width`` × ``height``, × 6
#: for a cube) a robot may declare: 10^5 × 10^5 samples allocated gigabytes before failing (issue 28)
MJCF_MAX_HFIELD, MJCF_MAX_TEXTURE = 10**7, IMAGE_MAX_PIXELS
#: most bytes of asset files (meshes, textures, height fields, …) one robot file may load, MB, a file named by
#: several elements counted each time: MuJoCo loads it for each
MJCF_MAX_FILES_MB = 512
#: most ``<include>`` files read for one robot, the same file counted each time it is included
MJCF_MAX_INCLUDES = 1000
#: deepest ``<include>`` chain walked (MuJoCo refuses a recursive one itself; this bounds the walk)
INCLUDE_DEPTH = 32
#: element → attributes naming a file MuJoCo reads
_FILE_ATTRS = {"texture": ("file", *CUBE_FACES)}
_HOW = 'assets kept elsewhere: --asset-root DIR, or asset_roots = ["DIR"] in the robot\'s table (design §12)'

#: ``--asset-root`` folders of this process (real paths), added to every MJCF robot's own folder
_GRANT: list[tuple[str, ...]] = [()]


class AssetEscape(InputError):
    """An MJCF robot names a file outside its folder and the granted asset roots (exit 2)."""


def grant_roots(dirs: Iterable[str | Path]) -> None:
    """``--asset-root DIR``: let every MJCF robot of this process read files under ``dirs`` too."""
    _GRANT[0] = tuple(os.path.realpath(os.path.expanduser(str(d))) for d in dirs)


def granted_roots() -> tuple[str, ...]:
    """The folders :func:`grant_roots` granted (real paths)."""
    return _GRANT[0]


def roots_from_args(values: Iterable[str] | None, flag: str = "--asset-root") -> tuple[str, ...]:
    """``--asset-root DIR`` flags as real paths; raises :class:`InputError` naming the flag for a missing folder."""
    out = []
    for v in values or ():
        d = Path(v).expanduser()
        if not d.is_dir():
            raise InputError(f"{flag} {v}: no such directory")
        out.append(os.path.realpath(d))
    return tuple(out)


def add_flag(p: argparse.ArgumentParser, scenario: bool = False) -> None:
    """``--asset-root DIR`` (repeatable)."""
    whose = "the scenario's MJCF robots" if scenario else "MJCF"
    p.add_argument(
        "--asset-root",
        action="append",
        default=[],
        metavar="DIR",
        help=f"{whose}: also read meshes, textures, height fields, skins and includes under DIR (repeatable; "
        "default: only the robot file's own folder; asset_roots in a robot's table)",
    )


def allowed_roots(model: str | Path, extra: Iterable[str] = ()) -> tuple[str, ...]:
    """The folders (real paths) an MJCF robot at ``model`` may read: its own folder, ``extra``, the granted."""
    own = os.path.realpath(os.path.dirname(os.path.abspath(model)))
    return (own, *(os.path.realpath(os.path.expanduser(e)) for e in extra), *granted_roots())


def _inside(path: str, roots: tuple[str, ...]) -> bool:
    real = os.path.realpath(path)
    return any(real == r or real.startswith(r.rstrip(os.sep) + os.sep) for r in roots)


def _refuse(model: Path, where: str, element: str, name: str, full: str, roots: tuple[str, ...]) -> AssetEscape:
    return AssetEscape(f"{model}: {where}{_named(element, name, full, roots)}")


def _named(element: str, name: str, full: str, roots: tuple[str, ...]) -> str:
    """``<mesh file="NAME"/>`` (resolved to …, a symlink to …) outside …: not read (how to allow it)."""
    tag, _, attr = element.partition(" ")
    lexical, real = os.path.normpath(full), os.path.realpath(full)
    at = f" ('{lexical}')" if lexical != name else ""
    via = f", a symlink to '{real}'," if real != lexical else ""
    allowed = f"'{roots[0]}'" + (f" or the asset roots {', '.join(repr(r) for r in roots[1:])}" if roots[1:] else "")
    return f'<{tag} {attr}="{name}"/>{at}{via} is outside the robot\'s folder {allowed}: not read ({_HOW})'


def _read_xml(f: Path, model: Path, what: str) -> ET.Element:
    from bioform_mj.robots.sanity import not_regular, parse_xml

    why = not_regular(f)
    if why:
        raise InputError(f"{model}: {what} {why}")
    try:
        size = f.stat().st_size
    except OSError as exc:
        raise InputError(f"{model}: {what} '{f}' cannot be read ({exc.strerror})") from None
    if size > MJCF_MAX_MB * 10**6:
        raise InputError(
            f"{model}: {what} '{f}' is {size / 1e6:.0f} MB, above the {MJCF_MAX_MB} MB an MJCF file may be"
        )
    try:
        return parse_xml(f)
    except ET.ParseError as exc:  # refused, never handed to MuJoCo's laxer parser unwalked
        where = "" if what == "model file" else f"{what} '{f}': "
        raise InputError(f"{model}: does not compile: {where}not well-formed XML ({exc})") from None
    except OSError as exc:
        raise InputError(f"{model}: {what} '{f}' cannot be read ({exc.strerror})") from None


def confine_mjcf(model: str | Path, extra: Iterable[str] = ()) -> None:
    """Refuse (:class:`AssetEscape`, exit 2) an MJCF file whose includes, compiler folders or asset files
    resolve outside :func:`allowed_roots`, before MuJoCo reads anything (see the module docstring).

    Resolution as MuJoCo 3–4 does it: ``<include file>`` (at any depth) relative to the main file's folder;
    ``meshdir``/``texturedir``/``assetdir`` relative to it; a mesh, skin, height field or flexcomp file
    relative to ``meshdir`` (else ``assetdir``), a texture's to ``texturedir`` (else ``assetdir``); an
    attached ``<model file>`` relative to the main file's folder, walked in turn with the same roots. To be
    safe against another resolution, every name is also checked against the folder of the file that holds
    it, and where a file holds several ``<compiler>`` elements, against every folder they name."""
    model = Path(model)
    _confine(model, allowed_roots(model, extra), model, "", ())


def _confine(
    file: Path, roots: tuple[str, ...], model: Path, prefix: str, models: tuple[str, ...]
) -> tuple[int, int, int]:
    """:func:`confine_mjcf` of ``file`` (the robot's ``model``, or a ``<model file>`` it attaches: ``prefix``
    names the way there, ``models`` the attached files above it, real paths). Returns its ``(elements, bodies,
    geoms)``, each ``<attach>`` of an attached model counting that model's once more."""
    from bioform_mj.robots.sanity import mesh_problem

    base = os.path.dirname(os.path.abspath(file))
    # (where, element, its file's folder, how many times <replicate> repeats it), includes inlined
    elements: list[tuple[str, ET.Element, str, int]] = []

    def check(where: str, element: str, name: str, folders: list[str], read: bool = False) -> None:
        for d in folders:
            full = os.path.join(base, d, name)
            if not _inside(full, roots):
                raise _refuse(model, where, element, name, full, roots)
            if read and (why := mesh_problem(full)):  # a FIFO blocks MuJoCo's parser (a flexcomp's file) or compiler
                tag, _, attr = element.partition(" ")
                raise InputError(f"{model}: {where}<{tag} {attr}=\"{name}\"/> ('{os.path.normpath(full)}'): {why}")

    reads = [0, 0]  # <include> reads, and the bytes of XML they read

    def walk(f: Path, where: str, chain: tuple[str, ...], times: int) -> None:
        if len(chain) + len(models) > INCLUDE_DEPTH:
            raise InputError(f"{model}: includes nested deeper than {INCLUDE_DEPTH} ({' -> '.join(chain)})")
        reads[0] += 1
        if reads[0] > MJCF_MAX_INCLUDES:  # two includes of the next file at each of 20 levels: 2^20 reads
            raise InputError(f"{model}: {where}more than {MJCF_MAX_INCLUDES} <include> reads (not compiled)")
        with contextlib.suppress(OSError):  # (unreadable: _read_xml says why)
            reads[1] += os.stat(f).st_size
        if reads[1] > MJCF_MAX_MB * 10**6:  # a 60 MB file included 1000 times would be parsed 1000 times
            raise InputError(
                f"{model}: {where}the XML read comes to more than {MJCF_MAX_MB} MB (each include counted each time)"
            )
        root = _read_xml(f, model, "included file" if chain[1:] or models else "model file")
        own = os.path.relpath(os.path.dirname(os.path.abspath(f)), base)
        stack = [(root, times)]
        while stack:  # document order, as root.iter(); each element with the product of its replicate counts
            el, n = stack.pop()
            if el.tag == "include":
                name = el.get("file") or ""
                check(where, "include file", name, ["", os.path.relpath(f.parent, base)])
                full = os.path.join(base, name)
                real = os.path.realpath(full)
                if real in chain:
                    raise InputError(f"{model}: <include file> '{name}' includes itself ({' -> '.join(chain)})")
                walk(Path(full), f'{where}<include file="{name}"/> → ', (*chain, real), n)
                continue
            if isinstance(el.tag, str):
                elements.append((where, el, own, n))
                if el.tag == "replicate":
                    n *= max(1, _int(el.get("count")))
            stack.extend((c, n) for c in reversed(el))

    walk(file, prefix, (os.path.realpath(file),), 1)
    for tag, most in (("body", MJCF_MAX_BODIES), ("geom", MJCF_MAX_GEOMS)):
        n = sum(k for _, el, _, k in elements if el.tag == tag)
        if n > most:
            raise InputError(f"{model}: {prefix}{n} <{tag}> elements, above the {most} a robot may have (not compiled)")
    if (n := sum(k for *_, k in elements)) > MJCF_MAX_ELEMENTS:
        raise InputError(
            f"{model}: {prefix}{n} elements (<replicate> repeats counted), above the {MJCF_MAX_ELEMENTS} a robot "
            "may have (not compiled)"
        )
    for where, el, _, _ in elements:
        if bad := _declared_size(el):
            raise InputError(f"{model}: {where}{bad} (not compiled)")
    dirs: dict[str, list[str]] = {"meshdir": [], "texturedir": [], "assetdir": []}
    for where, el, _, _ in elements:
        if el.tag == "compiler":
            for k in dirs:
                v = el.get(k)
                if v is not None:
                    check(where, f"compiler {k}", v, [""])
                    dirs[k].append(v)
    sizes: dict[str, tuple[int, int, int]] = {}  # an attached model's name → its (elements, bodies, geoms)
    loaded = 0  # bytes of the asset files named, each as often as it is named
    for where, el, own, _ in elements:
        kind = "texturedir" if el.tag == "texture" else "meshdir"
        folders = dirs[kind] or dirs["assetdir"] or [""]
        if el.tag == "model":  # an attached MJCF: relative to the main file's folder, walked in turn
            name = el.get("file") or ""
            check(where, "model file", name, ["", own])
            real = os.path.realpath(os.path.join(base, name))
            if name and (real in models or real == os.path.realpath(file)):  # MuJoCo recursed until it crashed
                raise InputError(f'{model}: {where}<model file="{name}"/> attaches a model that attaches it')
            if name:
                way = f'{where}<model file="{name}"/> → '
                sizes[el.get("name") or ""] = _confine(Path(base) / name, roots, model, way, (*models, real))
            continue
        for attr in _FILE_ATTRS.get(el.tag, ("file",)):
            name = el.get(attr)
            if name:
                candidates = [*folders, *(os.path.join(own, d) for d in folders)]
                check(where, f"{el.tag} {attr}", name, candidates, True)
                loaded += next(
                    (os.path.getsize(f) for d in candidates if os.path.isfile(f := os.path.join(base, d, name))), 0
                )
                if loaded > MJCF_MAX_FILES_MB * 10**6:  # 300 meshes of one 7.5 MB STL: 75 s, gigabytes (issue 28)
                    raise InputError(
                        f'{model}: {where}<{el.tag} {attr}="{name}"/>: the files the robot loads come to more than '
                        f"{MJCF_MAX_FILES_MB} MB (a file named by several elements counted each time; not compiled)"
                    )
    total = [sum(k for *_, k in elements), *(sum(k for _, e, _, k in elements if e.tag == t) for t in ("body", "geom"))]
    for _, el, _, k in elements:  # each <attach> copies the model it names (2 of the next file at each of 20 levels)
        if el.tag == "attach":
            total = [a + k * b for a, b in zip(total, sizes.get(el.get("model") or "", (0, 0, 0)), strict=True)]
    for n, most, what in zip(total, (MJCF_MAX_ELEMENTS, MJCF_MAX_BODIES, MJCF_MAX_GEOMS), ("", " <body>", " <geom>")):
        if n > most:
            raise InputError(
                f"{model}: {prefix}{n}{what} elements with the attached models' copies, above the {most} a robot may "
                "have (not compiled)"
            )
    return total[0], total[1], total[2]


def _int(text: str | None) -> int:
    """An integer attribute (``""``, a malformed or a non-integer one: 0; MuJoCo's parser says why)."""
    try:
        return int(float(text or "0"))
    except (ValueError, OverflowError):
        return 0


def _declared_size(el: ET.Element) -> str:
    """Why an element's declared size would allocate without bound (``""``: it would not): ``<size nkey>``
    and ``nuser_*``, a height field's ``nrow`` × ``ncol``, a flexcomp's ``count``, a texture's ``width`` ×
    ``height``."""
    if el.tag == "size":
        for k, v in el.attrib.items():
            most = MJCF_MAX_KEYS if k == "nkey" else MJCF_MAX_USER if k.startswith("nuser_") else None
            if most is not None and _int(v) > most:
                return f"<size {k}='{v}'>: at most {most}"
    elif el.tag == "hfield" and _int(el.get("nrow")) * _int(el.get("ncol")) > MJCF_MAX_HFIELD:
        return (
            f"<hfield nrow='{el.get('nrow')}' ncol='{el.get('ncol')}'>: above the {MJCF_MAX_HFIELD:.0e} samples a "
            "height field may have"
        )
    elif el.tag == "flexcomp" and math.prod(max(1, _int(c)) for c in (el.get("count") or "1").split()[:3]) > (
        MJCF_MAX_ELEMENTS
    ):
        return f"<flexcomp count='{el.get('count')}'>: above the {MJCF_MAX_ELEMENTS} points a flexcomp may have"
    elif el.tag == "texture":
        faces = 6 if el.get("type") in ("cube", "skybox") else 1
        if faces * _int(el.get("width")) * _int(el.get("height")) > MJCF_MAX_TEXTURE:
            return (
                f"<texture width='{el.get('width')}' height='{el.get('height')}'>: above the {MJCF_MAX_TEXTURE} "
                "pixels a texture may have"
            )
    return ""


def spec_escape(spec: Any, roots: tuple[str, ...]) -> str:
    """Why a parsed ``MjSpec``'s mesh, skin, height-field or texture file (:func:`spec_files`) is outside
    ``roots`` (``""``: none), resolved as MuJoCo's compiler resolves it (the model's folder,
    ``meshdir``/``texturedir``)."""
    top = spec.modelfiledir or "."
    for f in spec_files(spec):
        full = f.path(top)
        if not _inside(full, roots):
            return _named(f"{f.kind} {f.attr}", f.name, full, roots)
    return ""


def open_mjcf(model: str | Path, extra: Iterable[str] = ()) -> Any:
    """``mujoco.MjSpec.from_file(model)`` once :func:`confine_mjcf` passed, the spec's asset files checked
    again (:func:`spec_escape`); raises :class:`AssetEscape`/:class:`InputError` (exit 2) otherwise.
    Errors of MuJoCo's own parser propagate as MuJoCo raises them."""
    import mujoco

    extra = tuple(extra)
    confine_mjcf(model, extra)
    spec = mujoco.MjSpec.from_file(str(model))
    why = spec_escape(spec, allowed_roots(model, extra))
    if why:
        raise AssetEscape(f"{model}: {why}")
    return spec

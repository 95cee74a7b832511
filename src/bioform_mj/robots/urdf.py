"""URDF robots as robots (design §12): a ``.urdf`` (or xacro) file imported through ``mujoco.MjSpec``.

MuJoCo compiles URDF, but as it stands a URDF robot does not drive: the compiler welds the root
link to the world and fuses every link on a fixed joint into its parent (``fusestatic``), keeps
``package://`` URIs as file names, reads no COLLADA, infers the mass of a link without
``<inertial>`` silently and ignores ``<gazebo>`` and ``<transmission>``. :func:`import_urdf` makes
it the robot its maker published:

- the file is read with ElementTree, as data (a file that needs xacro is expanded only when asked,
  ``--xacro`` or ``xacro = true``, in a sandboxed process: :mod:`bioform_mj.robots.xacro_sandbox`):
  one root link (two roots, a cycle or no link: exit 2 naming it); a massless root ``world`` link
  fixed to the robot is dropped (a robot fixed to the world does not drive);
- every mesh URI resolved to an absolute file: ``package://NAME/…`` through the search path
  (:func:`find_package`: the robot's/scenario's ``package_path``, ``--package-path``, then
  ``BIOFORM_PACKAGE_PATH``, ``ROS_PACKAGE_PATH``, ``AMENT_PREFIX_PATH``, then the URDF file's own
  ancestors), ``file://``, paths relative to the URDF file. A visual mesh that cannot be found or
  read is dropped (said); a collision mesh is exit 2 naming the mesh, the link and the file. A
  mesh MuJoCo cannot decode (COLLADA ``.dae``, ``.ply``, ``.glb``…) is converted with trimesh
  (optional extra ``urdf``) into inline vertices, or (collision) exit 2 saying how to convert;
- compiled by MuJoCo with ``<mujoco><compiler discardvisual="false" fusestatic="false"
  strippath="false"/></mujoco>`` (links stay bodies with their URDF names, visuals stay for looks),
  then a free joint on the root link; ``<gazebo reference=LINK>`` ``mu1`` (``mu2``) becomes the
  sliding friction of that link's collision geoms;
- self-collision follows the format: URDF/Gazebo do not collide a model's links with each other,
  so every pair of the robot's bodies gets a ``<contact><exclude>`` (contacts with the floor and
  with other robots stay), unless the mapping says ``self_collide = true``;
- the base is the root link (a base named in the mapping that is welded to the root is the root);
  without a wheel mapping the two driven wheels are found: the revolute/continuous joints along
  the base's y axis right below the base whose links touch the floor, one on each side (exit 2
  when none or several);
- every guess is a note (:attr:`UrdfImport.notes`): the mass MuJoCo inferred for a link without
  ``<inertial>``, transmissions and ``<gazebo>`` tags ignored, joint limits, friction read,
  meshes dropped or converted, the wheels found. ``robot check`` prints them, runs print them as
  ``warning:`` lines and keep them in ``summary.json`` (``import_warnings``).

:func:`check_file` does the checks that need no MuJoCo (the file, its tree, its meshes), so a
scenario is refused before any work.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from bioform_mj.core.errors import InputError
from bioform_mj.robots.compile_hints import compile_hint
from bioform_mj.robots.mesh_convert import INSTALL_HINT, have_trimesh, one_line, trimesh_read
from bioform_mj.robots.mesh_paths import absolute_escape, symlink_escape
from bioform_mj.robots.mjcf_assets import MJCF_MAX_FILES_MB, MJCF_MAX_MB
from bioform_mj.robots.packages import find_package, package_search_path, resolve_uri
from bioform_mj.robots.refs import PackagePath, RobotRef
from bioform_mj.robots.sanity import mesh_problem, not_regular, urdf_value_problem
from bioform_mj.robots.urdf_wheels import find_wheels, left_of

__all__ = [
    "UrdfError",
    "UrdfImport",
    "URDF_SUFFIXES",
    "MESH_NATIVE",
    "is_urdf",
    "wheel_velocity_limit",
    "load_urdf",
    "find_package",
    "package_search_path",
    "check_file",
    "import_urdf",
]

#: priority of a collision geom whose friction a ``<gazebo>`` tag gives (= ``scene.CONTACT_PRIORITY``)
URDF_FRICTION_PRIORITY = 2
#: sliding friction of the scene's floor (MuJoCo's default): a ``<gazebo>`` mu1 at or above it is the floor's
#: (Gazebo's ODE takes the smaller mu of a pair), so the floor and its friction patches decide those contacts
FLOOR_MU = 1.0

#: file suffixes read as URDF (``.urdf.xacro`` ends with ``.xacro``)
URDF_SUFFIXES = (".urdf", ".xacro")
#: mesh files MuJoCo reads itself; others are converted with trimesh (design §12)
MESH_NATIVE = (".stl", ".obj", ".msh")
#: most links (and joints) a URDF may have: a published robot has a few hundred
URDF_MAX_LINKS = 5000
#: most elements of any kind a URDF may have (its materials, visuals, Gazebo tags, … together)
URDF_MAX_ELEMENTS = 100_000
#: the compiler settings that keep a URDF robot a robot (design §12)
_COMPILER = {"discardvisual": "false", "fusestatic": "false", "strippath": "false"}


class UrdfError(InputError):
    """A URDF that cannot be made a robot: names the element and the file (exit 2)."""


@dataclass
class UrdfImport:
    """What :func:`import_urdf` made of one URDF: the spec (free root, excludes, frictions), its
    compiled model, the mapping completed (``base`` = root link, wheels found) and the notes."""

    spec: Any  # mujoco.MjSpec
    model: Any  # mujoco.MjModel of ``spec``
    ref: RobotRef
    root: str
    notes: tuple[str, ...]


def load_urdf(ref: RobotRef, path: Path) -> tuple[Any, ...]:
    """``(spec, model, ref, import notes, keyframe, keyframe qpos, keyframe notes)`` of the URDF (or xacro) file
    ``path``, imported by :func:`import_urdf` (design §12: a URDF stays a robot: free root, links kept, meshes
    found); the format's loader in :mod:`bioform_mj.robots.formats`. A URDF has no keyframes: a mapping that names
    one is refused. Raises :class:`~bioform_mj.robots.layout.ModelError` (exit 2) naming the file."""
    from bioform_mj.robots.layout import ModelError

    if ref.keyframe and ref.keyframe.lower() != "none":
        raise ModelError(f"{path}: keyframe '{ref.keyframe}': a URDF has no keyframes (remove the mapping's keyframe)")
    try:
        imp = import_urdf(ref)
    except InputError as exc:
        raise ModelError(str(exc)) from None
    return imp.spec, imp.model, imp.ref, imp.notes, "", (), ()


def is_urdf(path: str | Path) -> bool:
    """True for a ``.urdf``/``.xacro`` file, or an ``.xml`` whose root element is ``<robot>``."""
    p = str(path).lower()
    if p.endswith(URDF_SUFFIXES):
        return True
    if not p.endswith(".xml") or not_regular(path):
        return False
    try:  # the root's start tag: the first 64 kB, else the rest in one piece (expat 2.5 parses a token fed in
        with open(path, "rb") as fh:  # chunks again for each chunk: a 50 MB root attribute ran past 60 s, issue 28)
            parser = ET.XMLPullParser(events=("start",))
            for data in (fh.read(1 << 16), fh.read(64 * 10**6)):
                parser.feed(data)
                for _event, elem in parser.read_events():
                    return elem.tag == "robot"
    except (OSError, ET.ParseError):
        return False
    return False


def wheel_velocity_limit(ref: RobotRef, path: Path, wheel_joints: list[str]) -> float | None:
    """The least ``<limit velocity>`` (rad/s) of the named wheel joints of the URDF ``path`` (the format's
    ``wheel_speed``, :mod:`bioform_mj.robots.formats`), the file read as the import reads it: ``ref``'s package path,
    xacro flag and arguments and ``asset_roots`` (a mesh let in only through ``asset_roots`` must not hide the top
    speed; issue 28). None when a wheel has none; raises (:class:`UrdfError`, :class:`InputError`) when the file
    cannot be read again."""
    pr = _parse(Path(path), ref.package_path, ref.xacro, ref.xacro_args, ref.asset_roots)
    vel = [pr.limits.get(j, ("", None, None, None, None))[4] for j in wheel_joints]
    if not vel or any(v is None or v <= 0 for v in vel):
        return None
    return float(min(vel))


# ------------------------------------------------------------------ reading the file
@dataclass
class _Parsed:
    """The URDF as ElementTree read it, checked and rewritten for MuJoCo."""

    text: str
    root: str
    links: list[str]
    no_inertial: list[str]
    friction: dict[str, tuple[float, float | None]]
    convert: dict[str, tuple[str, list[str]]]  # absolute mesh file → (visual|collision, links)
    hinges: list[str]
    limits: dict[str, tuple[str, float | None, float | None, float | None, float | None]]
    drive: dict[str, Any] = field(default_factory=dict)  # a Gazebo diff-drive plugin's wheels and torque
    notes: list[str] = field(default_factory=list)


def _read_text(
    path: Path, packages: PackagePath, xacro: bool = False, xacro_args: tuple[tuple[str, str], ...] = ()
) -> str:
    """The URDF text: the file as it is (data, never evaluated); a file that needs xacro is refused
    unless ``xacro`` (the mapping's ``xacro = true``) or ``--xacro`` allows it, then expanded in a
    sandboxed process with ``xacro_args`` (:mod:`bioform_mj.robots.xacro_sandbox`, design §12)."""
    from bioform_mj.robots.xacro_sandbox import expand, granted, needs_xacro, refusal

    if not_regular(path):
        raise UrdfError(f"model file {not_regular(path)}")
    if not path.is_file():
        raise UrdfError(f"model file '{path}' does not exist")
    if (size := path.stat().st_size) > MJCF_MAX_MB * 10**6:  # a 10 GB (sparse) file was read whole (issue 28)
        raise UrdfError(f"model file '{path}' is {size / 1e6:.0f} MB, above the {MJCF_MAX_MB} MB a robot file may be")
    text = None
    if not str(path).lower().endswith(".xacro"):
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise UrdfError(f"model file '{path}' cannot be read: {one_line(exc)}") from None
    if not needs_xacro(path, text):
        return text
    allowed, args = granted()
    if not (xacro or allowed):
        raise refusal(path, text is not None)
    return expand(path, packages, (*xacro_args, *((n, v) for n, v in args if n not in dict(xacro_args))))


def _float(text: str | None) -> float | None:
    try:
        return float(text) if text is not None and text.strip() else None
    except ValueError:
        return None


def _gz_value(parent: ET.Element, path: str) -> str | None:
    """``<gazebo>`` element ``path``'s ``value`` attribute, else its text (``<mu1 value="0.5"/>`` is
    ``<mu1>0.5</mu1>`` to Gazebo's URDF parser)."""
    el = parent.find(path)
    return None if el is None else el.get("value", el.text)


def _gz_names(plugin: ET.Element, tags: tuple[str, ...]) -> list[str]:
    return [v.strip() for t in plugin if t.tag in tags and (v := t.get("value", t.text)) and v.strip()]


def _parse(
    path: Path,
    packages: PackagePath,
    xacro: bool = False,
    xacro_args: tuple[tuple[str, str], ...] = (),
    asset_roots: tuple[str, ...] = (),
) -> _Parsed:
    """Read, check and rewrite the URDF (no MuJoCo): raises :class:`UrdfError` naming the element."""
    from bioform_mj.robots.xacro_sandbox import XACRO_NOTE, Expanded, env_note, sandbox_note

    text = _read_text(path, packages, xacro, xacro_args)
    expanded = isinstance(text, Expanded)
    try:
        robot = ET.fromstring(text)
    except ET.ParseError as exc:
        raise UrdfError(f"{path}: not valid XML ({exc})") from None
    if robot.tag != "robot":
        raise UrdfError(f"{path}: the root element is <{robot.tag}>, not <robot> (is it a URDF?)")
    n_el = sum(1 for el in robot if el.tag in ("link", "joint"))
    if n_el > 2 * URDF_MAX_LINKS:  # 10^5 links compiled for 9 minutes, deaf to SIGTERM (issue 28)
        raise UrdfError(
            f"{path}: {n_el} <link> and <joint> elements, above the {2 * URDF_MAX_LINKS} a robot may have "
            f"(at most {URDF_MAX_LINKS} links; a published robot has a few hundred)"
        )
    n_all = sum(1 for _ in robot.iter())
    if n_all > URDF_MAX_ELEMENTS:  # 3·10^5 <material> elements ran robot check past 60 s (issue 28)
        raise UrdfError(
            f"{path}: {n_all} elements, above the {URDF_MAX_ELEMENTS} a robot may have (a published robot has a few "
            "thousand)"
        )
    bad_value = urdf_value_problem(robot)  # NaN, negative, zero where it cannot be: refused naming it
    if bad_value:
        raise UrdfError(f"{path}: {bad_value}")
    notes: list[str] = [XACRO_NOTE, sandbox_note(text.sandbox)] if expanded else []
    if expanded and (env_said := env_note(text.env, text.unused_args)):
        notes.append(env_said)
    links = {}
    for link in robot.findall("link"):
        name = link.get("name")
        if not name:
            raise UrdfError(f"{path}: a <link> without a name")
        if name in links:
            raise UrdfError(f"{path}: <link name='{name}'> is defined twice")
        links[name] = link
    if not links:
        raise UrdfError(f"{path}: no <link>: the URDF has no root link")
    joints = robot.findall("joint")
    parent_of: dict[str, str] = {}
    seen: set[str] = set()
    for j in joints:
        jn = j.get("name") or "?"
        if j.get("name") and jn in seen:  # was taken silently
            raise UrdfError(f"{path}: <joint name='{jn}'> is defined twice")
        seen.add(jn)
        par, chi = j.find("parent"), j.find("child")
        pl, cl = (par.get("link") if par is not None else None), (chi.get("link") if chi is not None else None)
        if not pl or not cl:
            raise UrdfError(f"{path}: <joint name='{jn}'> lacks its <parent link> or <child link>")
        for which, ln in (("parent", pl), ("child", cl)):
            if ln not in links:
                raise UrdfError(f"{path}: <joint name='{jn}'>: {which} link '{ln}' is not a <link> of the file")
        if cl in parent_of:
            raise UrdfError(
                f"{path}: link '{cl}' is the child of two joints ('{parent_of[cl]}' and '{jn}'): the links are no tree"
            )
        parent_of[cl] = jn
    roots = [n for n in links if n not in parent_of]
    if not roots:
        raise UrdfError(f"{path}: no root link: every <link> is the child of a <joint> (the joints form a cycle)")
    if len(roots) > 1:
        raise UrdfError(
            f"{path}: {len(roots)} root links ({', '.join(repr(r) for r in roots[:6])}): links not connected "
            "by joints; the robot needs one root link"
        )
    root = roots[0]
    if root == "world" and not list(links["world"]):  # a robot fixed to the world does not drive
        out = [j for j in joints if j.find("parent").get("link") == "world"]
        if len(out) == 1:
            j = out[0]
            child = j.find("child").get("link")
            robot.remove(links.pop("world"))
            robot.remove(j)
            joints.remove(j)
            del parent_of[child]
            notes.append(
                f"link 'world' and its {j.get('type', 'fixed')} joint '{j.get('name')}' to '{child}' dropped: "
                f"the robot drives, '{child}' is its root"
            )
            root = child
    # reachable from the root (a cycle among other links would leave them out)
    children: dict[str, list[str]] = {}
    for j in joints:
        children.setdefault(j.find("parent").get("link"), []).append(j.find("child").get("link"))
    seen, todo = set(), [root]
    while todo:
        n = todo.pop()
        seen.add(n)
        todo += [c for c in children.get(n, []) if c not in seen]
    if len(seen) != len(links):
        lost = [n for n in links if n not in seen]
        raise UrdfError(
            f"{path}: links {', '.join(repr(n) for n in lost[:6])} are not below the root '{root}' (a cycle)"
        )
    hinges = [j.get("name") or "?" for j in joints if j.get("type") in ("continuous", "revolute")]
    if not hinges:
        raise UrdfError(
            f"{path}: no continuous or revolute <joint>: nothing in the URDF could be a wheel "
            f"({len(joints)} joint(s): {', '.join(sorted({str(j.get('type')) for j in joints})) or 'none'})"
        )

    # <axis> as ROS reads it (urdfdom): none on a fixed or floating joint (ignored there: the Fetch/Freight URDF's
    # fixed joints say <axis xyz="0 0 0"/>, which the value check refused), and xyz 1 0 0 where it lacks xyz (MuJoCo's
    # parser refuses "required attribute missing: 'xyz' Element 'axis'": MobileRobots' Pioneer 3-DX xacro has
    # <axis xzy="0 0 1"/>, a typo, on a fixed joint, so the published robot could not be read at all)
    no_xyz = []
    for j in joints:
        for ax in j.findall("axis"):
            if j.get("type") in ("fixed", "floating"):
                j.remove(ax)
            elif ax.get("xyz") is None:
                ax.set("xyz", "1 0 0")
                no_xyz.append(f"'{j.get('name') or '?'}' ({j.get('type', '?')})")
    if no_xyz:
        notes.append(
            f"<axis> without xyz on joint(s) {', '.join(no_xyz[:6])}"
            + (f" and {len(no_xyz) - 6} more" if len(no_xyz) > 6 else "")
            + ": taken as 1 0 0, the URDF default (ROS's urdfdom does the same; MuJoCo's parser would refuse it)"
        )

    # <mujoco><compiler>: ours, and a meshdir the file may give for its relative mesh names
    mj = robot.find("mujoco")
    if mj is None:
        mj = ET.Element("mujoco")
        robot.insert(0, mj)
    comp = mj.find("compiler")
    if comp is None:
        comp = ET.SubElement(mj, "compiler")
    for k, v in _COMPILER.items():
        if comp.get(k, v).lower() != v:
            notes.append(f'the URDF\'s <mujoco><compiler {k}="{comp.get(k)}"> overridden with {v} (design §12)')
        comp.set(k, v)
    meshdir = path.parent.resolve()
    if comp.get("meshdir"):
        meshdir = (meshdir / comp.get("meshdir")).resolve()
        del comp.attrib["meshdir"]

    # meshes: absolute files; a visual that cannot be had is dropped, a collision one is an error
    convert: dict[str, tuple[str, list[str]]] = {}
    found_by: set[str] = set()
    dropped: list[str] = []
    trimesh_ok: bool | None = None
    loaded = 0  # bytes of the mesh files kept, each as often as it is named
    for lname, link in links.items():
        for role in ("visual", "collision"):
            for el in link.findall(role):
                mesh = el.find("geometry/mesh")
                if mesh is None:
                    continue
                uri = (mesh.get("filename") or "").strip()
                file, why, how = resolve_uri(uri, packages, path, meshdir) if uri else (None, "no filename", "")
                if how.endswith("a parent folder of the URDF file"):
                    found_by.add(how)
                if file is not None and (bad := symlink_escape(uri, packages, path, meshdir)):
                    why = bad  # never copied into a run's assets/ under the target's name
                elif file is not None and (bad := mesh_problem(file)):
                    why = f"mesh file {file}: {bad}"  # a FIFO, a device, a zip bomb: never opened or unpacked
                elif file is not None and (bad := absolute_escape(uri, file, packages, path, asset_roots)):
                    why = bad  # /etc/… named as a mesh: never read (issue 28)
                elif file is not None and not file.is_file():
                    why = f"no file {file}"
                elif file is not None and not os.access(file, os.R_OK):
                    why = f"file {file} cannot be read"
                if not why and file.suffix.lower() not in MESH_NATIVE:
                    if trimesh_ok is None:
                        trimesh_ok = have_trimesh()
                    if trimesh_ok:
                        was = convert.get(str(file), ("visual", []))
                        convert[str(file)] = ("collision" if "collision" in (role, was[0]) else role, [*was[1], lname])
                    else:
                        why = (
                            f"MuJoCo cannot read {file.suffix} meshes: {INSTALL_HINT} to convert it on import, "
                            f"or convert it to STL yourself (e.g. `meshlab`/`assimp export {file.name} "
                            f"{file.stem}.stl`) and point the URDF at the STL"
                        )
                if why:
                    if role == "collision":
                        raise UrdfError(f"{path}: <collision> mesh '{uri}' of link '{lname}': {why}")
                    link.remove(el)  # said with paths from the URDF's folder: a run's scene.xml keeps the notes
                    why = why.replace(str(file), os.path.relpath(file, path.parent)) if file is not None else why
                    dropped.append(f"'{uri}' of link '{lname}' ({why})")
                    continue
                mesh.set("filename", str(file))
                loaded += file.stat().st_size  # MuJoCo loads a mesh for each element naming it (issue 28)
                if loaded > MJCF_MAX_FILES_MB * 10**6:
                    raise UrdfError(
                        f"{path}: <{role}> mesh '{uri}' of link '{lname}': the meshes the robot loads come to more "
                        f"than {MJCF_MAX_FILES_MB} MB (a file named by several links counted each time)"
                    )
    if dropped:
        notes.append(
            f"{len(dropped)} visual mesh(es) dropped (looks only; contacts and inertia unchanged; paths from the "
            "URDF file's folder): "
            + "; ".join(dropped[:4])
            + (f" and {len(dropped) - 4} more" if len(dropped) > 4 else "")
        )
    for how in sorted(found_by):
        notes.append(f"package:// resolved through {how} (no search path named it)")

    no_inertial = [n for n, link in links.items() if link.find("inertial") is None]

    # <gazebo>: friction read, the rest said
    friction: dict[str, tuple[float, float | None]] = {}
    ignored: list[str] = []
    drive: dict[str, Any] = {}
    for gz in robot.findall("gazebo"):
        ref = gz.get("reference")
        if ref is None:
            plugs = [p.get("filename") or p.get("name") or "?" for p in gz.iter("plugin")]
            for p in gz.iter("plugin"):  # a diff-drive plugin names the driven wheels and their torque
                what = f"{p.get('filename', '')} {p.get('name', '')}".lower()
                if "diff_drive" in what or "diffdrive" in what or "diff-drive" in what:
                    # ROS 1 gazebo_ros: leftJoint/rightJoint/wheelTorque; ROS 2 and gz-sim: left_joint/...
                    drive = {
                        "plugin": p.get("filename") or p.get("name") or "?",
                        "left": _gz_names(p, ("leftJoint", "left_joint")),
                        "right": _gz_names(p, ("rightJoint", "right_joint")),
                        "torque": _float(_gz_value(p, "wheelTorque") or _gz_value(p, "max_wheel_torque")),
                    }
            said = [
                f"'{p}'" + (" (beyond its wheels and wheel torque)" if drive.get("plugin") == p else "") for p in plugs
            ]
            ignored.append("plugin " + ", ".join(said) if plugs else "a <gazebo> block")
            continue
        mu1 = _float(_gz_value(gz, "mu1"))
        mu2 = _float(_gz_value(gz, "mu2"))
        if mu1 is None:  # SDF style: <collision><surface><friction><ode><mu>
            mu1 = _float(_gz_value(gz, ".//surface/friction/ode/mu"))
            mu2 = _float(_gz_value(gz, ".//surface/friction/ode/mu2")) if mu1 is not None else mu2
        if mu1 is not None and ref in links:
            friction[ref] = (mu1, mu2)
        rest = sorted({c.tag for c in gz if c.tag not in ("mu1", "mu2") or ref not in links})
        if mu1 is None and gz.find(".//surface") is not None:
            rest = sorted(set(rest) | {"surface"})
        if rest:
            ignored.append(f"reference '{ref}': " + ", ".join(rest))
    if ignored:
        notes.append(
            "<gazebo> tags ignored (MuJoCo has no Gazebo): "
            + "; ".join(ignored[:6])
            + (f" and {len(ignored) - 6} more" if len(ignored) > 6 else "")
        )
    trans = robot.findall("transmission")
    if trans:
        names = [t.get("name") or "?" for t in trans]
        notes.append(
            f"{len(trans)} <transmission> element(s) ignored ({', '.join(repr(n) for n in names[:4])}"
            f"{' …' if len(names) > 4 else ''}): the plant drives the wheel joints with its own torque motors"
        )
    limits = {}
    for j in joints:
        lim = j.find("limit")
        if lim is None:
            continue
        limits[j.get("name") or "?"] = (
            str(j.get("type")),
            _float(lim.get("lower")),
            _float(lim.get("upper")),
            _float(lim.get("effort")),
            _float(lim.get("velocity")),
        )
    return _Parsed(
        text=ET.tostring(robot, encoding="unicode"),
        root=root,
        links=list(links),
        no_inertial=no_inertial,
        friction=friction,
        convert=convert,
        hinges=hinges,
        limits=limits,
        drive=drive,
        notes=notes,
    )


def _unbalanced(spec: Any) -> dict[str, tuple[float, float, float]]:
    """The bodies of ``spec`` whose given inertia breaks the triangle inequality ``A + B >= C`` of its principal
    moments (which MuJoCo's ``balanceinertia`` replaces), with those moments (kg·m², ascending)."""
    out = {}
    for b in spec.bodies:
        if b.name == "world" or not b.explicitinertial:
            continue
        fi = np.asarray(b.fullinertia, float)
        if np.all(np.isfinite(fi)):
            eig = np.linalg.eigvalsh(np.array([[fi[0], fi[3], fi[4]], [fi[3], fi[1], fi[5]], [fi[4], fi[5], fi[2]]]))
        else:
            eig = np.sort(np.asarray(b.inertia, float))
        if eig[0] + eig[1] < eig[2] * (1 - 1e-9):
            out[b.name] = (float(eig[0]), float(eig[1]), float(eig[2]))
    return out


def check_file(ref: RobotRef) -> None:
    """The checks of :func:`import_urdf` that need no MuJoCo: the file reads, has one root link,
    a joint that could be a wheel, and its collision meshes resolve. Raises :class:`UrdfError`."""
    _parse(Path(ref.model), ref.package_path, ref.xacro, ref.xacro_args, ref.asset_roots)


# ------------------------------------------------------------------ meshes MuJoCo cannot read
def _load_mesh(file: str, role: str, links: list[str], path: Path) -> tuple[np.ndarray, np.ndarray, str]:
    """``(vertices, faces, note)`` of a mesh MuJoCo cannot read; a visual one that trimesh cannot
    read either comes back empty (dropped, said), a collision one is an error."""
    st = os.stat(file)
    got = trimesh_read(file, st.st_mtime_ns, st.st_size)
    where = f"of link{'s' if len(links) > 1 else ''} {', '.join(repr(n) for n in links)}"
    if isinstance(got, str):
        if role == "collision":
            raise UrdfError(
                f"{path}: <collision> mesh '{file}' {where} cannot be converted ({got}); "
                f"convert it to STL and point the URDF at it ({INSTALL_HINT} reads COLLADA)"
            )
        rel = os.path.relpath(file, path.parent)  # a run's scene.xml keeps the notes: no machine path
        return np.zeros((0, 3)), np.zeros((0, 3), int), f"visual mesh '{rel}' {where} dropped: {got}"
    v, f, unit = got
    note = (
        f"{role} mesh '{Path(file).name}' {where} converted with trimesh ({len(v)} vertices, "
        f"{len(f)} faces{f', COLLADA unit {unit:g} m applied' if unit != 1 else ''})"
    )
    return v, f, note


# ------------------------------------------------------------------ import
def import_urdf(ref: RobotRef) -> UrdfImport:
    """Import the URDF ``ref.model`` as a drivable robot spec (see the module docstring).

    Returns the spec and its compiled model, ``ref`` with ``base`` (the root link) and, when the
    mapping gives none, the wheel joints filled in, and the notes. Raises :class:`UrdfError`
    (exit 2) naming the element and the file.
    """
    import mujoco

    path = Path(ref.model)
    pr = _parse(path, ref.package_path, ref.xacro, ref.xacro_args, ref.asset_roots)
    notes = list(pr.notes)
    try:
        spec = mujoco.MjSpec.from_string(pr.text)
    except Exception as exc:
        raise UrdfError(f"{path}: MuJoCo cannot read the URDF: {one_line(exc)}") from None

    for m in list(spec.meshes):
        if m.file in pr.convert:
            role, links = pr.convert[m.file]
            v, f, note = _load_mesh(m.file, role, sorted(set(links)), path)
            notes.append(note)
            if len(f) == 0:  # a visual that trimesh could not read: its geoms go
                for g in list(spec.geoms):
                    if g.meshname == m.name:
                        spec.delete(g)
                spec.delete(m)
                continue
            m.file = ""
            m.uservert = v.ravel()
            m.userface = f.ravel()

    root = spec.body(pr.root)
    names = {j.name for j in spec.joints}
    free = f"{pr.root}_free"
    while free in names:
        free += "_"
    root.add_freejoint(name=free)
    notes.append(
        f"root link '{pr.root}' gets a free joint '{free}' (MuJoCo welds a URDF root to the world); "
        "links on fixed joints stay bodies"
    )

    for lname, (mu1, mu2) in pr.friction.items():
        geoms = [g for g in spec.body(lname).geoms if g.contype or g.conaffinity]
        low = mu1 < FLOOR_MU
        for g in geoms:
            fr = np.array(g.friction, float)
            fr[0] = min(mu1, FLOOR_MU)
            g.friction = fr
            # ODE takes the smaller mu of a pair, MuJoCo the larger unless a geom's priority is higher: a mu below
            # the floor's wins by priority (scene.CONTACT_PRIORITY, design §13); one above is the floor's (a
            # priority would beat the floor's own μ 1, and a mu of 200 starves the contact's normal load in
            # MuJoCo's pyramidal cone: a MiR100's driven wheels carried 0 N of 850 N)
            if low:
                g.priority = URDF_FRICTION_PRIORITY
        extra = ""
        if mu2 is not None and mu2 != mu1:
            extra = f"; mu2 {mu2:g} not used (MuJoCo's sliding friction is one number)"
        how = (
            "winning against the floor's as in Gazebo (ODE takes the smaller of a pair)"
            if low
            else f"at or above the floor's {FLOOR_MU:g}: the floor's and its friction patches' decide, as the "
            "smaller of a pair does in Gazebo"
        )
        notes.append(
            f"link '{lname}': sliding friction {mu1:g} from <gazebo> mu1 on its {len(geoms)} collision geom(s), "
            f"{how}{extra}"
        )

    # a link without <inertial> is massless (the URDF spec: "zero mass and zero inertia if not specified");
    # MuJoCo's importer would give it its collision geometry at 1000 kg/m³ (a Husky: 176 kg for ~57).
    # A link that moves on its own joint needs a mass in MuJoCo: it keeps the geometry's, said below.
    massless = []
    for lname in pr.no_inertial:
        b = spec.body(lname)
        if b is not None and all(j.type == mujoco.mjtJoint.mjJNT_FREE for j in b.joints):  # the root: welded mass
            b.mass = 0.0
            b.inertia = [0.0, 0.0, 0.0]
            b.explicitinertial = True
            massless.append(lname)
    if massless:
        notes.append(
            "links without <inertial> are massless, as the URDF spec says: " + ", ".join(f"'{n}'" for n in massless)
        )
    bad = []
    for b in spec.bodies:  # an inertia that is not positive definite: Gazebo takes it, MuJoCo refuses it
        fi = np.asarray(b.fullinertia, float)
        if b.name == "world" or not np.all(np.isfinite(fi)) or not np.any(fi[3:]):
            continue
        mat = np.array([[fi[0], fi[3], fi[4]], [fi[3], fi[1], fi[5]], [fi[4], fi[5], fi[2]]])
        if np.linalg.eigvalsh(mat).min() <= 0:
            bad.append(b.name)
            b.fullinertia = [float(x) for x in np.abs(fi[:3])] + [0.0, 0.0, 0.0]
    if bad:
        notes.append(
            "inertia tensors that are not positive definite (MuJoCo refuses them): products of inertia dropped "
            "for " + ", ".join(f"'{n}'" for n in bad)
        )
    unbalanced = _unbalanced(spec) if ref.balance_inertia else {}
    if ref.balance_inertia:  # the mapping's balance_inertia (design §12)
        spec.compiler.balanceinertia = True
    try:
        model = spec.compile()
    except Exception as exc:
        raise UrdfError(f"{path}: does not compile: {one_line(exc)}{compile_hint(exc)}") from None
    body_id = {mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b): b for b in range(1, model.nbody)}
    if unbalanced:  # never silent: balancing changes the robot's inertia, and with it b_eff (design §12)
        notes.append(
            "balance_inertia: MuJoCo balanced the inertia of "
            + ", ".join(
                f"'{n}' (principal moments {' '.join(f'{x:.4g}' for x in eig)} -> "
                f"{' '.join(f'{x:.4g}' for x in model.body_inertia[body_id[n]])} kg·m²)"
                for n, eig in unbalanced.items()
                if n in body_id
            )
            + ": the robot simulated (its yaw inertia, b_eff) is the balanced one, not the file's"
        )
    inferred = []
    for lname in pr.no_inertial:
        b = body_id.get(lname)
        if b is not None and lname not in massless and model.body_mass[b] > 0:
            inferred.append((lname, float(model.body_mass[b])))
    if inferred:
        total = float(model.body_subtreemass[body_id[pr.root]])
        notes.append(
            "links without <inertial>: "
            + ", ".join(f"'{n}' {m:.4g} kg" for n, m in inferred)
            + f" (MuJoCo's inertiafromgeom: the collision geometry at 1000 kg/m³; "
            f"{sum(m for _, m in inferred):.4g} of the robot's {total:.4g} kg); give each an <inertial> "
            "with its real mass"
        )

    # the mapping: base = root link (or a body welded to it), wheels found unless mapped
    base = ref.base or pr.root
    if base != pr.root:
        b = body_id.get(base)
        if b is None:
            raise UrdfError(f"{path}: no link '{base}' (the base; the URDF's root link is '{pr.root}')")
        from bioform_mj.robots.layout import welded_to  # MuJoCo only when a URDF is read

        if b not in welded_to(model, body_id[pr.root]).tolist():
            raise UrdfError(
                f"{path}: base '{base}' moves against the root link '{pr.root}' (a joint lies between them): "
                f"the base of a URDF robot is its root link; leave base unset or map '{pr.root}'"
            )
        notes.append(
            f"base '{base}' is welded to the root link '{pr.root}', which carries the free joint: "
            f"'{pr.root}' is the base"
        )
        base = pr.root
    ref = replace(ref, base=base)
    joint_id = {mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j): j for j in range(model.njnt)}
    drive = pr.drive
    if not (ref.left_wheel or ref.right_wheel) and not ("left_wheel" in joint_id and "right_wheel" in joint_id):
        hinge = int(mujoco.mjtJoint.mjJNT_HINGE)
        named = [drive.get("left", []), drive.get("right", [])]
        if all(len(n) == 1 and n[0] in joint_id and model.jnt_type[joint_id[n[0]]] == hinge for n in named):
            lw, rw = named[0][0], named[1][0]  # the maker's own simulation drives these
            swap = left_of(model, body_id[pr.root], rw, lw)  # ROS 1 legacyMode (its default) drives them swapped
            lw, rw = (rw, lw) if swap else (lw, rw)
            notes.append(
                f"wheels from the Gazebo diff-drive plugin '{drive['plugin']}': left '{lw}', right '{rw}' "
                + (f"(its leftJoint '{rw}' is the right wheel, as legacyMode drives it) " if swap else "")
                + "(map left_wheel/right_wheel to choose others)"
            )
        else:
            lw, rw, note = find_wheels(model, body_id[pr.root], path)
            notes.append(note)
        ref = replace(ref, left_wheel=lw, right_wheel=rw)
    wheels = {ref.left_wheel or "left_wheel", ref.right_wheel or "right_wheel"}
    torque = drive.get("torque")
    if not ref.tau_max and torque and torque > 0:
        effort = [pr.limits.get(w, ("", None, None, None, None))[3] for w in wheels]
        if not all(e and e > 0 for e in effort):  # the URDF's own <limit effort> comes first
            ref = replace(ref, tau_max=float(torque))
            notes.append(
                f"wheel torque limit {torque:g} N·m from the Gazebo diff-drive plugin's wheel torque (the wheel "
                "joints have no <limit effort>); map tau_max for the real motor's"
            )

    # limits: a wheel turns without end; the others are kept and said
    kept, efforts, vel = [], [], 0
    for jn, (jtype, lo, hi, effort, velocity) in pr.limits.items():
        if jn in wheels:
            if jtype == "revolute" and lo is not None and hi is not None and jn in joint_id:
                spec.joint(jn).limited = mujoco.mjtLimited.mjLIMITED_FALSE
                notes.append(
                    f"wheel joint '{jn}' is revolute with limits [{lo:g}, {hi:g}] rad: removed (a wheel turns "
                    "without end)"
                )
            if effort:
                efforts.append(f"'{jn}' {effort:g} N·m")
        elif jtype in ("revolute", "prismatic") and lo is not None and hi is not None:
            kept.append(f"'{jn}' [{lo:g}, {hi:g}] {'rad' if jtype == 'revolute' else 'm'}")
        if velocity and jtype != "fixed":
            vel += 1
    if kept:
        notes.append(f"joint limits kept: {', '.join(kept[:6])}{f' and {len(kept) - 6} more' if len(kept) > 6 else ''}")
    if efforts:
        notes.append(
            f"wheel <limit effort>: {', '.join(efforts)} (MuJoCo's actuatorfrcrange: the motor limit unless "
            "tau_max is mapped)"
        )
    if vel:
        notes.append(
            f"<limit velocity> of {vel} joint(s): MuJoCo has no joint speed limit; a wheel joint's is read as the "
            "robot's top speed unless the mapping gives top_speed (design §21)"
        )

    # self-collision: off between the robot's own links (URDF/Gazebo), unless asked
    if not ref.self_collide:  # the bodies that collide, or may (a wheel gets a contact proxy: scene.py)
        root_id = body_id[pr.root]
        bodies = [
            b
            for b in range(1, model.nbody)
            if (model.body_jntnum[b] and b != root_id)
            or any(
                model.geom_contype[g] or model.geom_conaffinity[g]
                for g in range(model.body_geomadr[b], model.body_geomadr[b] + model.body_geomnum[b])
            )
        ]
        names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) for b in bodies]
        pairs = 0
        for i, a in enumerate(names):
            for c in names[i + 1 :]:
                spec.add_exclude(bodyname1=a, bodyname2=c)
                pairs += 1
        if pairs:
            notes.append(
                f"self-collision off (the URDF/Gazebo convention): {pairs} pair(s) of its {len(names)} links "
                "excluded from contacts with each other (floor and other robots still collide); "
                "self_collide = true keeps them"
            )
    try:
        model = spec.compile()
    except Exception as exc:
        raise UrdfError(f"{path}: does not compile: {one_line(exc)}{compile_hint(exc)}") from None
    return UrdfImport(spec=spec, model=model, ref=ref, root=pr.root, notes=tuple(notes))

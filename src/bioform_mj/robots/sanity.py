"""Bounded answers to hostile or broken inputs (design §12, §14; issue 28 item 2).

Each check here answers before any work, in one :class:`~bioform_mj.core.errors.InputError` line (exit 2)
naming the file and the element:

- :func:`regular_file`: a file that is read must be a regular file (a FIFO named ``package.xml`` on
  ``ROS_PACKAGE_PATH``, or a device, would block the reader forever); checked with ``os.stat``
  (``stat.S_ISREG``) before it is opened;
- :func:`mesh_problem`: a mesh file's size (at most :data:`MESH_MAX_MB` MB), a PNG's declared pixels (at most
  :data:`IMAGE_MAX_PIXELS`), and for a zip archive
  (COLLADA ``.zae``, or a ``.dae`` that is a zip) the sizes its directory declares, before anything
  is decompressed (at most :data:`MESH_MAX_MB` MB unpacked, :data:`ZIP_MAX_ENTRIES` entries, a
  compression ratio of :data:`ZIP_MAX_RATIO`);
- :func:`urdf_value_problem`: masses, inertias, joint axes, dynamics, limits, Gazebo friction and
  mesh scales of a URDF: finite, non-negative where negative means nothing, non-zero where zero
  cannot be (a moving link's mass, an axis, a scale);
- :func:`model_value_problem`: the same on a compiled ``MjModel`` (an MJCF robot), its ``<option>`` too
  (:func:`option_problem`: a timestep > 0, finite gravity, bounded solver iterations);
- names (URDF and MJCF) that hold a control character or a bidirectional/invisible format character
  (:data:`~bioform_mj.core.errors.UNSAFE_TEXT`: a newline, U+202E) are refused (:func:`one_line` escapes them
  in output that names what a user wrote);
- :func:`check_step_budget`: a timestep that would make automatic work (robot check, identification)
  take longer than :data:`CHECK_BOUND_S` s, refused with the estimate;
- :class:`StepPace`: the same bound on the measured wall time of the steps taken so far (a robot whose
  geoms overlap in a thousand contacts steps 1000x slower than the estimate assumes).
"""

from __future__ import annotations

import math
import os
import stat
import time
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from typing import Any

from bioform_mj.core.errors import UNSAFE_TEXT, InputError, escape_unsafe

__all__ = [
    "unstatable",
    "mesh_resolver",
    "MESH_MAX_MB",
    "ZIP_MAX_ENTRIES",
    "ZIP_MAX_RATIO",
    "IMAGE_MAX_PIXELS",
    "CHECK_BOUND_S",
    "STEP_WALL_S",
    "regular_file",
    "not_regular",
    "mesh_problem",
    "urdf_value_problem",
    "model_value_problem",
    "option_problem",
    "MAX_SOLVER_ITERATIONS",
    "check_step_budget",
    "StepPace",
    "one_line",
    "spec_file_problem",
    "parse_xml",
]

#: largest mesh file, and largest unpacked archive, taken (MB); a published robot's meshes are a few MB
MESH_MAX_MB = 256
#: most entries of a mesh archive
ZIP_MAX_ENTRIES = 1000
#: most pixels of a texture or height-field image (a PNG's declared width × height; an MJCF texture's
#: width × height, ×6 for a cube): 2^26, an 8192 × 8192 image, 192 MB as RGB
IMAGE_MAX_PIXELS = 2**26
#: largest unpacked/packed size ratio of a mesh archive (a mesh compresses 3–10×; a zip bomb 1000×+)
ZIP_MAX_RATIO = 200
#: bound on the automatic work a robot file's timestep can ask (robot check, identification): s of wall time
CHECK_BOUND_S = 300.0
#: wall time of one physics step of one robot through the plant, s (measured ~50 µs on the 2-core
#: development machine; the estimate is a lower bound on a slower one)
STEP_WALL_S = 2e-5


def parse_xml(path: str | Path) -> ET.Element:
    """``ET.parse(path).getroot()``, the file fed to expat whole: ``ET.parse`` feeds it in 64 kB chunks, and
    expat 2.5 parses a token that spans chunks again for each chunk, so a 60 MB attribute took 114 s (6 MB:
    1.8 s; whole: 1.9 s and 0.14 s; issue 28). Raises ``OSError``/``ET.ParseError`` as ``ET.parse``."""
    with open(path, "rb") as fh:
        return ET.fromstring(fh.read())


def not_regular(path: str | Path) -> str:
    """Why ``path`` cannot be read without blocking (``""``: a regular file; a missing file is the reader's)."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return ""
    if stat.S_ISREG(mode):
        return ""
    kind = (
        "a FIFO (named pipe)"
        if stat.S_ISFIFO(mode)
        else "a device"
        if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
        else "a socket"
        if stat.S_ISSOCK(mode)
        else "a directory"
        if stat.S_ISDIR(mode)
        else "not a regular file"
    )
    return f"'{path}' is {kind}, not a regular file: not read (reading it could block)"


def unstatable(path: str | Path) -> str:
    """Why ``path`` cannot even be looked up (``""``: it can, or it is simply missing): a name too long
    for the file system, a symlink loop, a permission error on a folder above it (issue 28)."""
    try:
        os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        return ""
    except OSError as exc:
        shown = str(path) if len(str(path)) <= 120 else f"{str(path)[:60]}…{str(path)[-40:]}"
        return f"'{shown}' cannot be looked up ({exc.strerror or exc})"
    except ValueError as exc:  # an embedded NUL
        return f"{str(path)!r} is no file name ({exc})"
    return ""


def regular_file(path: str | Path, what: str = "file") -> None:
    """Raise :class:`InputError` unless ``path`` is a regular file (or missing: the reader says so)."""
    why = not_regular(path)
    if why:
        raise InputError(f"{what} {why}")


def mesh_problem(file: str | Path) -> str:
    """Why the mesh ``file`` is not read (``""``: fine): not a regular file, too large, or an archive
    whose declared contents are too large, too many or too compressed. Reads only the zip directory."""
    why = not_regular(file)
    if why:
        return why
    try:
        size = os.path.getsize(file)
    except FileNotFoundError:
        return ""  # missing: the caller says so
    except OSError as exc:
        return f"cannot be read ({exc.strerror})"
    if size > MESH_MAX_MB * 10**6:
        return f"{size / 1e6:.0f} MB, above the {MESH_MAX_MB} MB a mesh may be (simplify it)"
    try:
        with open(file, "rb") as fh:
            magic = fh.read(4)
    except OSError as exc:
        return f"cannot be read ({exc.strerror})"
    if magic == b"\x89PNG":  # a PNG declares its size in IHDR: a 3 MB file can decode to gigabytes
        try:
            with open(file, "rb") as fh:
                head = fh.read(24)
        except OSError as exc:
            return f"cannot be read ({exc.strerror})"
        w, h = (int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")) if len(head) == 24 else (0, 0)
        if w * h > IMAGE_MAX_PIXELS:
            return f"a PNG image of {w} × {h} pixels, above the {IMAGE_MAX_PIXELS} an image may have: not decoded"
        return ""
    if magic != b"PK\x03\x04":
        return ""
    try:
        with zipfile.ZipFile(file) as zf:
            infos = zf.infolist()
    except (zipfile.BadZipFile, OSError, ValueError) as exc:
        return f"a broken zip archive ({exc})"
    unpacked = sum(i.file_size for i in infos)
    packed = max(1, sum(i.compress_size for i in infos))
    if len(infos) > ZIP_MAX_ENTRIES:
        return f"a zip archive of {len(infos)} entries (at most {ZIP_MAX_ENTRIES}): not unpacked"
    if unpacked > MESH_MAX_MB * 10**6:
        return (
            f"a zip archive that unpacks to {unpacked / 1e6:.0f} MB (above the {MESH_MAX_MB} MB a mesh may be): "
            "not unpacked"
        )
    if unpacked > 10**6 and unpacked / packed > ZIP_MAX_RATIO:
        return f"a zip archive compressed {unpacked / packed:.0f}× (at most {ZIP_MAX_RATIO}×): not unpacked"
    return ""


def mesh_resolver(file: str | Path) -> Any:
    """trimesh's resolver for the files a mesh ``file`` names (a glTF's buffers, a COLLADA's images): only
    its own folder, as trimesh ≥ 5 confines it, and only a regular file of at most :data:`MESH_MAX_MB` MB
    (issue 28: a FIFO ``x.bin`` beside an ``x.gltf`` hung the import). A refused file raises ValueError."""
    from trimesh.resolvers import FilePathResolver

    class _Resolver(FilePathResolver):
        def get(self, name: str) -> bytes:
            full = self.absolute(name)  # ValueError for a name outside the mesh's folder
            why = not_regular(full)
            if not why and full.is_file() and full.stat().st_size > MESH_MAX_MB * 10**6:
                why = f"'{full}' is above the {MESH_MAX_MB} MB a mesh's file may be"
            if why:
                raise ValueError(why)
            return super().get(name)

    return _Resolver(str(file))


def _num(text: str | None) -> float | None:
    try:
        return float(text) if text is not None and text.strip() else None
    except ValueError:
        return math.nan


def _vec(text: str | None) -> list[float] | None:
    if text is None or not text.strip():
        return None
    try:
        return [float(x) for x in text.split()]
    except ValueError:
        return [math.nan]


def urdf_value_problem(robot: ET.Element) -> str:
    """The first bad number of a URDF ``<robot>`` as ``"<element> of link/joint 'N': why"`` (``""``: none).

    Masses finite and >= 0 (> 0 on a link that moves on its joint: MuJoCo cannot move a massless body);
    inertia moments finite and >= 0, products finite; joint axes three finite numbers, not all zero;
    ``<dynamics>`` damping/friction and ``<limit>`` effort/velocity finite and >= 0, limits finite;
    ``<gazebo>`` mu1/mu2/mu finite and >= 0; mesh scales finite and > 0.
    """
    for el in robot.iter():
        name = el.get("name")
        if name is not None and _CONTROL.search(name):
            return f"<{el.tag} name={escape_unsafe(repr(name))}>: {_UNSAFE_WHY}; rename it"
    moving = {
        (j.find("child").get("link") if j.find("child") is not None else None)
        for j in robot.findall("joint")
        if j.get("type", "fixed") != "fixed"
    }
    for link in robot.findall("link"):
        name = link.get("name") or "?"
        inertial = link.find("inertial")
        if inertial is not None:
            mass = inertial.find("mass")
            m = _num(mass.get("value")) if mass is not None else None
            if m is not None and not (math.isfinite(m) and m >= 0):
                return f"<mass value='{mass.get('value')}'> of link '{name}': a mass must be a finite number >= 0 kg"
            if m == 0 and name in moving:
                return (
                    f"<mass value='{mass.get('value')}'> of link '{name}': a link that moves on its joint needs a "
                    "mass > 0 kg (MuJoCo cannot move a massless body); give its real mass"
                )
            inertia = inertial.find("inertia")
            if inertia is not None:
                for k in ("ixx", "iyy", "izz", "ixy", "ixz", "iyz"):
                    v = _num(inertia.get(k))
                    if v is not None and not (math.isfinite(v) and (v >= 0 or k not in ("ixx", "iyy", "izz"))):
                        return f"<inertia {k}='{inertia.get(k)}'> of link '{name}': " + (
                            "a moment of inertia must be a finite number >= 0 kg·m²" if k[1] == k[2] else "not finite"
                        )
        for role in ("visual", "collision"):
            for el in link.findall(role):
                mesh = el.find("geometry/mesh")
                if mesh is None or mesh.get("scale") is None:
                    continue
                s = _vec(mesh.get("scale"))
                if s is not None and not (len(s) in (1, 3) and all(math.isfinite(x) and x > 0 for x in s)):
                    return (
                        f"<{role}><mesh scale='{mesh.get('scale')}'> of link '{name}': a mesh scale must be 3 "
                        "finite numbers > 0 (mirror the mesh file instead of a negative scale)"
                    )
    for j in robot.findall("joint"):
        name = j.get("name") or "?"
        axis = j.find("axis")
        moves = j.get("type") not in ("fixed", "floating")  # urdfdom reads no axis of those (Fetch: xyz 0 0 0)
        if moves and axis is not None and axis.get("xyz") is not None:
            a = _vec(axis.get("xyz"))
            if a is None or len(a) != 3 or not all(math.isfinite(x) for x in a) or not any(a):
                return f"<axis xyz='{axis.get('xyz')}'> of joint '{name}': an axis must be 3 finite numbers, not all 0"
        for tag, keys in (("dynamics", ("damping", "friction")), ("limit", ("effort", "velocity"))):
            el = j.find(tag)
            for k in keys if el is not None else ():
                v = _num(el.get(k))
                if v is not None and not (math.isfinite(v) and v >= 0):
                    return f"<{tag} {k}='{el.get(k)}'> of joint '{name}': must be a finite number >= 0"
        lim = j.find("limit")
        for k in ("lower", "upper") if lim is not None else ():
            v = _num(lim.get(k))
            if v is not None and not math.isfinite(v):
                return f"<limit {k}='{lim.get(k)}'> of joint '{name}': must be a finite number"
    for gz in robot.findall("gazebo"):
        for el in gz.iter():
            if el.tag in ("mu1", "mu2", "mu"):
                v = _num(el.get("value", el.text))
                if v is not None and not (math.isfinite(v) and v >= 0):
                    return (
                        f"<gazebo reference='{gz.get('reference', '')}'> <{el.tag}> "
                        f"{el.get('value', el.text)}: a friction coefficient must be a finite number >= 0"
                    )
    return ""


#: control and bidirectional/format characters (a newline in a name forged ``error:`` lines of a run that exits 0;
#: U+202E shows a name reversed; issue 28): the one definition is :data:`bioform_mj.core.errors.UNSAFE_TEXT`
_CONTROL = UNSAFE_TEXT
_UNSAFE_WHY = (
    "a name holds a control character or a bidirectional-format one (a newline would forge lines of bioform's output, "
    "U+202E shows it reversed)"
)


#: longest line :func:`one_line` gives, characters: a 100,000-character ``--xacro-arg`` value was echoed whole in
#: its error line, a CSV header of 10^7 columns made a line of 119 MB (trust5)
LINE_MAX = 4000


def one_line(text: str) -> str:
    """``text`` with its control and bidirectional-format characters escaped (``\\n``, ``\\u202e``): one line of
    output that reads as stored, whatever a name holds; at most :data:`LINE_MAX` characters (the rest counted)."""
    if len(text) > LINE_MAX:
        text = f"{text[: LINE_MAX - 60]} … [{len(text) - LINE_MAX + 60} more characters not shown]"
    return escape_unsafe(text)


def model_value_problem(model: Any) -> str:
    """The first bad number of a compiled ``MjModel`` (an MJCF robot), naming the body, joint or geom
    (``""``: none): masses and inertias finite and >= 0, joint axes finite and not zero, friction
    finite and >= 0, mesh scales finite, every keyframe's numbers finite (named; an unnamed one by its index)."""
    import mujoco
    import numpy as np

    def name(obj: Any, i: int) -> str:
        return mujoco.mj_id2name(model, obj, i) or f"#{i}"

    if bad := option_problem(model.opt):
        return bad
    for raw in bytes(model.names).split(b"\0"):  # every element name of the model
        text = raw.decode("utf-8", "replace")
        if _CONTROL.search(text):
            return f"name {escape_unsafe(repr(text))}: {_UNSAFE_WHY}; rename it"

    for b in range(1, model.nbody):
        if not (np.isfinite(model.body_mass[b]) and model.body_mass[b] >= 0):
            return f"body '{name(mujoco.mjtObj.mjOBJ_BODY, b)}': mass {model.body_mass[b]:g} kg (a finite number >= 0)"
        if not (np.all(np.isfinite(model.body_inertia[b])) and np.all(model.body_inertia[b] >= 0)):
            return f"body '{name(mujoco.mjtObj.mjOBJ_BODY, b)}': inertia {model.body_inertia[b].tolist()} kg·m²"
    for j in range(model.njnt):
        ax = model.jnt_axis[j]
        if not np.all(np.isfinite(ax)) or (model.jnt_type[j] in (2, 3) and not np.any(ax)):
            return f"joint '{name(mujoco.mjtObj.mjOBJ_JOINT, j)}': axis {ax.tolist()} (3 finite numbers, not all 0)"
    for g in range(model.ngeom):
        fr = model.geom_friction[g]
        if not (np.all(np.isfinite(fr)) and np.all(fr >= 0)):
            return f"geom '{name(mujoco.mjtObj.mjOBJ_GEOM, g)}': friction {fr.tolist()} (finite numbers >= 0)"
    for k in range(model.nkey):  # a NaN keyframe passed with MuJoCo's warning only (issue 28)
        for field in ("time", "qpos", "qvel", "act", "ctrl", "mpos", "mquat"):
            v = np.atleast_1d(getattr(model, f"key_{field}")[k])
            if not np.all(np.isfinite(v)):
                shown = " ".join(f"{x:g}" for x in v[:12]) + (" …" if v.size > 12 else "")
                return f"keyframe '{name(mujoco.mjtObj.mjOBJ_KEY, k)}': {field} '{shown}' (finite numbers)"
    for m in range(model.nmesh):
        sc = model.mesh_scale[m] if hasattr(model, "mesh_scale") else np.ones(3)
        if not np.all(np.isfinite(sc)):
            return f"mesh '{name(mujoco.mjtObj.mjOBJ_MESH, m)}': scale {np.asarray(sc).tolist()} (finite numbers)"
        a, n = model.mesh_vertadr[m], model.mesh_vertnum[m]
        if not np.all(np.isfinite(model.mesh_vert[a : a + n])):  # a NaN refpos/refquat: the scale was blamed
            return (
                f"mesh '{name(mujoco.mjtObj.mjOBJ_MESH, m)}': vertices not finite once placed (its file, refpos, "
                "refquat and scale must be finite numbers)"
            )
    return ""


#: least downward gravity of a robot file's ``<option>``, m/s² (a thousandth of the Earth's): a differential-drive
#: robot moves by its wheels' friction, which its weight presses on the floor; without gravity (0, pointing up,
#: disabled) the robot check quoted a weight of 240 N it did not have, and the wheels could not drive (issue 28)
MIN_GRAVITY = 9.81e-3
_NO_WEIGHT = (
    "the robot has no weight here: its wheels drive by friction, which needs gravity pressing them on the floor "
    "(MuJoCo's default is 0 0 -9.81)"
)

#: most iterations a robot file's ``<option>`` may ask of one physics step's solvers (MuJoCo's defaults: 100
#: solver, 50 line search, 0 noslip, 35 CCD, 10 SDF); with a tolerance of 0, 10^9 of them made one step of
#: ``robot check`` run past 45 s (issue 28)
MAX_SOLVER_ITERATIONS = 1000


def option_problem(opt: Any) -> str:
    """The first bad number of a compiled model's ``<option>`` (``""``: none): a timestep finite and > 0
    (0, a negative or NaN one was an internal error); gravity, wind and the magnetic field finite; density,
    viscosity, the tolerances finite and >= 0, impratio finite and > 0; the solvers' iteration counts at most
    :data:`MAX_SOLVER_ITERATIONS` (each step could otherwise run for minutes); gravity enabled and pulling down
    by at least :data:`MIN_GRAVITY` (the wheels drive by friction)."""
    import numpy as np

    def shown(v: Any) -> str:
        return " ".join(f"{x:g}" for x in np.atleast_1d(v))

    if not (math.isfinite(opt.timestep) and opt.timestep > 0):
        return f"<option timestep='{opt.timestep:g}'>: a timestep must be a finite number > 0 s"
    for k in ("gravity", "wind", "magnetic"):
        if not np.all(np.isfinite(getattr(opt, k))):
            return f"<option {k}='{shown(getattr(opt, k))}'>: must be finite numbers"
    import mujoco

    if opt.disableflags & int(mujoco.mjtDisableBit.mjDSBL_GRAVITY):
        return f"<option><flag gravity='disable'>: gravity must act: {_NO_WEIGHT}"
    if not -opt.gravity[2] >= MIN_GRAVITY:
        return f"<option gravity='{shown(opt.gravity)}'>: must pull down (z <= -{MIN_GRAVITY:g} m/s²): {_NO_WEIGHT}"
    for k in ("density", "viscosity", "tolerance", "ls_tolerance", "noslip_tolerance", "ccd_tolerance"):
        v = float(getattr(opt, k, 0.0))
        if not (math.isfinite(v) and v >= 0):
            return f"<option {k}='{v:g}'>: must be a finite number >= 0"
    if not (math.isfinite(opt.impratio) and opt.impratio > 0):
        return f"<option impratio='{opt.impratio:g}'>: must be a finite number > 0"
    for k in ("iterations", "ls_iterations", "noslip_iterations", "ccd_iterations", "sdf_iterations"):
        n = int(getattr(opt, k, 0))
        if n > MAX_SOLVER_ITERATIONS:
            return (
                f"<option {k}='{n}'>: at most {MAX_SOLVER_ITERATIONS} (MuJoCo's default is far lower; so many "
                "could make one physics step run for minutes)"
            )
    return ""


def _human(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    if seconds < 2 * 86400:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.3g} days"


def check_step_budget(sim_seconds: float, dt: float, what: str, hint: str, robots: int = 1) -> None:
    """Refuse (``InputError``) work of ``sim_seconds`` s of simulated time at step ``dt`` s for ``robots``
    robots whose estimate (:data:`STEP_WALL_S` per robot-step) exceeds :data:`CHECK_BOUND_S` s."""
    if not (math.isfinite(dt) and dt > 0):
        raise InputError(f"{what}: timestep {dt!r} s: expected a finite number > 0")
    steps = sim_seconds / dt
    est = steps * robots * STEP_WALL_S
    if est > CHECK_BOUND_S:
        raise InputError(
            f"{what}: timestep {dt:g} s makes {steps:.3g} physics steps for {sim_seconds:.3g} s of simulated time, "
            f"about {_human(est)} (at {STEP_WALL_S * 1e6:g} µs a step; the bound is {CHECK_BOUND_S:g} s); {hint}"
        )


class StepPace:
    """Refuses automatic work whose physics steps, timed as they run, put ``steps`` of them above
    :data:`CHECK_BOUND_S` s (``InputError``). :func:`check_step_budget` assumes :data:`STEP_WALL_S` a step; a
    robot whose 50 wheels overlap in 1176 contacts stepped at 45 ms and ``robot check`` ran for many minutes
    (issue 28). Call it with the steps done so far: the clock starts at the first call (the steps before it
    hold the compiled kernels' first load or compile, seconds on a cold cache) and it decides once
    :data:`PACE_MIN_STEPS` more steps are timed (the first steps of a robot dropped onto the floor have no
    contacts)."""

    def __init__(self, steps: float, what: str, hint: str, data: Any = None) -> None:
        """``steps``: the physics steps the work will take; ``what``: who asks (named first in the line);
        ``hint``: what to change; ``data``: the ``MjData`` stepped (its contact count is said)."""
        self.steps, self.what, self.hint, self.data = float(steps), what, hint, data
        self.start: tuple[float, int] | None = None  # (clock, steps done) at the first call

    def __call__(self, done: int) -> None:
        """Raise ``InputError`` when the steps timed since the first call put ``steps`` above the bound."""
        now = time.perf_counter()
        if self.start is None:
            self.start = (now, done)
            return
        timed = done - self.start[1]
        if timed < PACE_MIN_STEPS:
            return
        per = (now - self.start[0]) / timed
        est = per * self.steps
        if est > CHECK_BOUND_S:
            ncon = f", {int(self.data.ncon)} contacts" if self.data is not None else ""
            raise InputError(
                f"{self.what}: one physics step takes {per * 1e3:.3g} ms here{ncon}: its {self.steps:.3g} steps "
                f"would take about {_human(est)} (the bound is {CHECK_BOUND_S:g} s); {self.hint}"
            )


#: steps :class:`StepPace` times before it decides
PACE_MIN_STEPS = 20


def spec_file_problem(spec: Any) -> str:
    """Why an MJCF ``MjSpec``'s mesh, skin, height-field or texture file (a cube face too:
    :func:`~bioform_mj.robots.mjcf_assets.spec_files`) is not loaded (``""``: none): checked by
    :func:`mesh_problem` before MuJoCo's compiler opens it (a FIFO blocks it, a 10 GB STL exhausts
    memory). Names resolve as the compiler resolves them (the model's folder and its
    ``meshdir``/``texturedir``); files of the spec's own asset dictionary are not files."""
    from bioform_mj.robots.spec_files import spec_files

    top = spec.modelfiledir or "."
    for f in spec_files(spec):
        full = f.path(top)
        why = mesh_problem(full)
        if why:
            what = f"{f.kind} file" if f.attr == "file" else f"{f.kind} {f.attr}"
            return f"{what} {full}: {why}"
    return ""

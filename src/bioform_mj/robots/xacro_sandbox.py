"""xacro, only when asked, in a process of its own (design §12): a xacro file is a program.

A robot file is data. A ``.urdf`` or ``.xml`` is parsed as XML and never evaluated; a file that
needs xacro (a ``.xacro`` file, or one holding ``<xacro:…>``, ``${…}`` or ``$(find|arg|env|optenv|eval …)``
outside comments and ``<gazebo>`` blocks: :func:`needs_xacro`) is refused with one ``error:``
line saying how to ask (:func:`refusal`), unless the user asked: ``--xacro`` (``robot check``,
``identify``, ``run``, ``table1``; a sweep refuses it) or ``xacro = true`` in the robot's table, with
``$(arg NAME)`` values from ``--xacro-arg NAME=VALUE`` or ``xacro_args = {NAME = "VALUE"}``.

:func:`expand` then runs xacro in a child process (``bioform_mj/robots/_xacro_child.py`` under
``python -I -B``) that

- has no variable of the user's environment (only the package search path it is told, for ``$(find)``),
  its working folder the robot file's folder;
- is limited to :data:`XACRO_MEMORY_MB` MiB of address space and :data:`XACRO_TIME_S` s (CPU and
  wall clock), writes no file, and answers at most :data:`XACRO_OUTPUT_MB` MB;
- reads no environment variable: ``$(optenv NAME default)`` is its default and ``$(env NAME)`` is
  refused, unless ``--xacro-arg NAME=VALUE`` gives ``NAME`` (:func:`env_note` says which it took);
- evaluates ``$(eval)`` without builtins, refuses the expressions that leave xacro's sandbox (dunders,
  ``format``, ``vars``, ``type``, …), reads only the robot's packages (``xacro:include``,
  ``xacro.load_yaml``) and, through an audit hook, starts no process, opens no socket and reads no file
  outside them.

Every failure is one :class:`~bioform_mj.robots.urdf.UrdfError` line (exit 2) naming the file. Expansions are
remembered in the process by file, its ``(mtime, size)``, the search path and the arguments.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import selectors
import signal
import subprocess
import sys
import time
from pathlib import Path

from bioform_mj.core.errors import InputError
from bioform_mj.robots.packages import find_package, package_search_path
from bioform_mj.robots.refs import PackagePath, RobotRef

__all__ = [
    "XACRO_MEMORY_MB",
    "XACRO_TIME_S",
    "XACRO_OUTPUT_MB",
    "XACRO_NOTE",
    "sandbox_note",
    "env_note",
    "XacroRefused",
    "Expanded",
    "needs_xacro",
    "refusal",
    "expand",
    "grant",
    "granted",
    "fold_grant",
    "xacro_args_from_flags",
    "add_flags",
    "grant_from_args",
]

#: address space of the xacro process (MiB): a 2 kB file of nested macros grew bioform to 3.6 GB
XACRO_MEMORY_MB = 1024
#: CPU and wall-clock limit of one expansion (s); a published robot expands in ~0.3 s
XACRO_TIME_S = 30
#: largest expansion taken (MB of XML); a published robot's is well under 1 MB
XACRO_OUTPUT_MB = 64
#: the import note of a robot xacro made (design §12)
XACRO_NOTE = (
    "expanded by xacro, which runs the file as a program: in a separate process with no environment, "
    f"at most {XACRO_MEMORY_MB} MiB and {XACRO_TIME_S} s, reading only the robot's packages "
    "(no environment variable: $(optenv) takes its default, $(env) is refused, unless --xacro-arg sets them); "
    "expand only files you trust"
)

#: what marks xacro in a file: a xacro element, a ``${…}`` expression, ``$(find …)``/``$(arg …)``/…
_XACRO = re.compile(r"<xacro:|\$\{|\$\((find|arg|env|optenv|eval|dirname|cwd)[ )]")
_CHILD = Path(__file__).with_name("_xacro_child.py")
_SEARCH_VARS = ("BIOFORM_PACKAGE_PATH", "ROS_PACKAGE_PATH", "AMENT_PREFIX_PATH")


class Expanded(str):
    """URDF text that xacro made (its import notes say so, :data:`XACRO_NOTE`); ``includes``: the
    files it included or loaded (``xacro:include``, ``load_yaml``), real paths, for provenance."""

    includes: tuple[str, ...] = ()
    #: the OS layers the child applied (``{layer: "on…" | "unavailable: why"}``, :func:`sandbox_note`)
    sandbox: dict[str, str] = {}
    #: ``((NAME, value, "default" | "arg"), …)``: the ``$(optenv)``/``$(env)`` names it read (:func:`env_note`)
    env: tuple[tuple[str, str, str], ...] = ()
    #: the ``--xacro-arg`` names the file never declared nor read (:func:`env_note`)
    unused_args: tuple[str, ...] = ()


class XacroRefused(InputError):
    """A file that needs xacro, not asked for; or an expansion the sandbox refused or stopped (exit 2)."""


#: ``(allowed, args)`` the command line granted to every robot of this process (``--xacro``)
_GRANT: list = [False, ()]


def sandbox_note(layers: dict[str, str]) -> str:
    """The import note of the OS layers around xacro's process: those on, and those unavailable with why."""
    on = [k for k, v in layers.items() if v.startswith("on")]
    off = [f"{k} ({v.removeprefix('unavailable: ')})" for k, v in layers.items() if not v.startswith("on")]
    return (
        "xacro's process was also confined by the OS: "
        + (", ".join(on) or "nothing")
        + (f"; unavailable here: {', '.join(off)} (the audit hook and limits still apply)" if off else "")
    )


#: how many ``$(optenv)`` defaults :func:`env_note` names (a Husky reads 91; each is in the file)
ENV_NOTE_DEFAULTS = 12


def env_note(env: tuple[tuple[str, str, str], ...], unused: tuple[str, ...] = ()) -> str | None:
    """The import note of the environment variables a xacro file read (``Expanded.env``), or None: each
    ``$(optenv NAME)`` resolved to its default (the environment is never read; the first
    :data:`ENV_NOTE_DEFAULTS` named), every value ``--xacro-arg`` set, and the ``--xacro-arg`` names the file
    never declared nor read (``unused``: a misspelt name?)."""
    defaults = [f"{n}={v!r}" for n, v, src in env if src == "default"]
    given = [f"{n}={v!r}" for n, v, src in env if src != "default"]
    parts = []
    if defaults:
        more = len(defaults) - ENV_NOTE_DEFAULTS
        shown = ", ".join(defaults[:ENV_NOTE_DEFAULTS]) + (f" and {more} more" if more > 0 else "")
        parts.append(
            f"$(optenv) resolved to the file's default, never the environment's value: {shown} "
            "(set one with --xacro-arg NAME=VALUE)"
        )
    if given:
        parts.append(f"$(optenv)/$(env) set by --xacro-arg: {', '.join(given)}")
    if unused:
        parts.append(
            f"--xacro-arg {', '.join(unused)}: the file declares and reads no $(arg), $(optenv) or $(env) of "
            f"{'that name' if len(unused) == 1 else 'those names'} (misspelt?)"
        )
    return "; ".join(parts) or None


def grant(allowed: bool, args: tuple[tuple[str, str], ...] = ()) -> None:
    """``--xacro`` / ``--xacro-arg``: let every robot of this process be expanded (with ``args`` under its own)."""
    _GRANT[0], _GRANT[1] = bool(allowed), tuple(args)


def granted() -> tuple[bool, tuple[tuple[str, str], ...]]:
    """What :func:`grant` said: ``(allowed, args)``."""
    return bool(_GRANT[0]), tuple(_GRANT[1])


def fold_grant(robots: tuple) -> tuple:
    """The robots (:class:`~bioform_mj.robots.refs.RobotRef`) with what :func:`grant` said written into the table of
    each that xacro expands: ``xacro = true`` and the ``--xacro-arg`` values under its own ``xacro_args`` (the
    table's win, as at expansion). The expansion is the same; a run's ``resolved.toml`` then records it, so the
    run reproduces without the flags (a flag's ``$(optenv)`` value is not lost to the default). A robot that is
    not a URDF file needing xacro is left as it is."""
    import dataclasses

    allowed, args = granted()
    if not allowed:
        return tuple(robots)
    out = []
    for r in robots:
        if not isinstance(r, RobotRef) or not (r.xacro or _file_needs_xacro(Path(r.model))):
            out.append(r)
            continue
        own = dict(r.xacro_args)
        out.append(
            dataclasses.replace(r, xacro=True, xacro_args=(*r.xacro_args, *((n, v) for n, v in args if n not in own)))
        )
    return tuple(out)


def _file_needs_xacro(path: Path) -> bool:
    """:func:`needs_xacro` of a robot file; False for what is not a readable URDF file (its import says why)."""
    if path.suffix.lower() not in (".urdf", ".xacro", ".xml") or not path.is_file():
        return False
    if path.name.lower().endswith(".xacro"):
        return True
    try:
        if path.stat().st_size > XACRO_OUTPUT_MB * 10**6:
            return False
        return needs_xacro(path, path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError):
        return False


def xacro_args_from_flags(values: list[str] | None, flag: str = "--xacro-arg") -> tuple[tuple[str, str], ...]:
    """``--xacro-arg NAME=VALUE`` flags as ``((NAME, VALUE), …)``; raises :class:`InputError` naming the flag."""
    out = []
    for v in values or ():
        name, sep, value = v.partition("=")
        name = name.strip()
        if not sep or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.-]*", name) or "\n" in value or "\x00" in value:
            raise InputError(f"{flag} {v!r}: expected NAME=VALUE (NAME a xacro arg name), e.g. {flag} prefix=left_")
        out.append((name, value))
    return tuple(out)


def add_flags(p: argparse.ArgumentParser, scenario: bool = False) -> None:
    """``--xacro`` and ``--xacro-arg NAME=VALUE`` (``scenario``: for every robot of the scenario)."""
    whose = "the scenario's URDF robots" if scenario else "URDF"
    p.add_argument(
        "--xacro",
        action="store_true",
        help=f"{whose}: expand a xacro file (a program: run in a separate process with no environment, "
        f"{XACRO_MEMORY_MB} MiB, {XACRO_TIME_S} s, reading only the robot's packages; design §12). "
        "Default: a file that needs xacro is refused",
    )
    p.add_argument(
        "--xacro-arg",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="with --xacro: the value of xacro's $(arg NAME), and of $(optenv NAME)/$(env NAME), which never "
        "read the environment ($(optenv) takes the file's default; repeatable)",
    )


def grant_from_args(args: argparse.Namespace) -> None:
    """:func:`grant` what a command line's ``--xacro``/``--xacro-arg`` say (nothing: refused), before any work."""
    values = xacro_args_from_flags(getattr(args, "xacro_arg", None))
    if values and not getattr(args, "xacro", False):
        raise InputError("--xacro-arg without --xacro: xacro runs only when asked (add --xacro)")
    if getattr(args, "xacro", False) and getattr(args, "command", "") == "sweep":  # its runs are other processes
        raise InputError(
            "sweep --xacro: a sweep's runs are other processes; write xacro = true (and "
            'xacro_args = {NAME = "VALUE"}) in the robot\'s table of the scenario instead (design §12)'
        )
    grant(bool(getattr(args, "xacro", False)), values)


def needs_xacro(path: Path, text: str | None) -> bool:
    """True for a ``.xacro`` file, or a text holding xacro outside comments and ``<gazebo>`` blocks
    (published URDFs keep commented-out includes, and Gazebo plugin parameters ROS's own ``$(find …)``)."""
    if str(path).lower().endswith(".xacro") or text is None:
        return True
    bare = re.sub(r"<gazebo\b.*?</gazebo>", "", re.sub(r"<!--.*?-->", "", text, flags=re.S), flags=re.S)
    return _XACRO.search(bare) is not None


def refusal(path: Path, macros: bool) -> XacroRefused:
    """The one line for a file that needs xacro when the user did not ask for it."""
    stem = path.name[: -len(".xacro")] if path.name.lower().endswith(".xacro") else path.stem + ".expanded"
    stem = stem if stem.endswith(".urdf") else stem + ".urdf"
    return XacroRefused(
        f"{path} is a xacro file{' (it holds xacro macros)' if macros else ''}: a xacro file is a program, and "
        "bioform runs it only when asked: pass --xacro (robot check, identify, run; $(arg NAME) values with "
        '--xacro-arg NAME=VALUE) or map xacro = true (xacro_args = {NAME = "VALUE"}) in the robot\'s table; '
        f"or expand it yourself (`xacro {path} > {stem}`, ROS's xacro tool) and give the .urdf (design §12)"
    )


def _package_root(path: Path) -> Path:
    """The folder of the robot file's package: the nearest folder above it with a ``package.xml``, else its own."""
    for d in path.resolve().parents:
        if (d / "package.xml").is_file():
            return d
        if d == d.parent:
            break
    return path.resolve().parent


def _search_dirs() -> list[str]:
    """Folders of the environment's package search path (their ``package.xml`` files are read by ``$(find)``)."""
    out = []
    for var in _SEARCH_VARS:
        for entry in filter(None, os.environ.get(var, "").split(os.pathsep)):
            d = entry.partition("=")[2] if var == "BIOFORM_PACKAGE_PATH" and "=" in entry else entry
            out.append(str(Path(d).expanduser()))
    return out


#: expansions of this process: a scene builds a robot several times (an included file edited while one
#: process runs is not seen: a process builds its robots once, at start)
_EXPANDED: dict[tuple, str] = {}


def expand(path: Path, packages: PackagePath, args: tuple[tuple[str, str], ...] = ()) -> Expanded:
    """The URDF text of the xacro file ``path``, expanded in the sandboxed child (module docstring).

    ``packages``: the robot's package search path (``$(find NAME)`` resolves as ``package://NAME``);
    ``args``: ``$(arg NAME)`` values. Raises :class:`XacroRefused` (exit 2) naming the file.
    """
    st = path.stat()
    env_key = tuple(os.environ.get(v, "") for v in _SEARCH_VARS)
    key = (str(path.resolve()), st.st_mtime_ns, st.st_size, tuple(packages), env_key, tuple(args))
    if key in _EXPANDED:
        return _EXPANDED[key]
    roots = [str(_package_root(path))]
    for _name, d in packages:
        roots.append(str(Path(d).expanduser().resolve()))
    req = {
        "file": str(path.resolve()),
        "args": [list(a) for a in args],
        "packages": [list(p) for p in packages],
        "roots": roots,
        "search_dirs": _search_dirs(),
        "search_env": {v: os.environ[v] for v in _SEARCH_VARS if os.environ.get(v)},
        "package_dir": str(Path(__file__).resolve().parents[1]),  # bioform_mj/ (this file: bioform_mj/robots/)
        "find_module": find_package.__module__,
        "mem_bytes": XACRO_MEMORY_MB * 2**20,
        "cpu_s": XACRO_TIME_S,
        "max_out_bytes": XACRO_OUTPUT_MB * 10**6,
    }
    answer = _run_child(path, req)
    if isinstance(answer.get("xml"), str):
        out = Expanded(answer["xml"])
        out.includes = tuple(str(f) for f in answer.get("includes") or () if isinstance(f, str))
        box = answer.get("sandbox")
        out.sandbox = {str(k): str(v) for k, v in box.items()} if isinstance(box, dict) else {}
        env = answer.get("env")
        out.env = tuple(
            (str(e[0]), str(e[1]), str(e[2])) for e in (env if isinstance(env, list) else ()) if len(e) == 3
        )
        unused = answer.get("unused_args")
        out.unused_args = tuple(str(n) for n in (unused if isinstance(unused, list) else ()))
        _EXPANDED[key] = out
        return out
    kind, why = answer.get("kind"), " ".join(str(answer.get("error", "")).split())
    if kind == "missing":
        pkg = answer.get("package", "?")
        raise XacroRefused(
            f"{path}: $(find {pkg}): package '{pkg}' is on no search path (searched: "
            f"{'; '.join(package_search_path(packages))}; give --package-path {pkg}=DIR)"
        )
    if kind == "no_xacro":
        stem = path.name[: -len(".xacro")] if path.name.lower().endswith(".xacro") else path.stem + ".expanded.urdf"
        raise XacroRefused(
            f"{path}: --xacro needs the xacro package: pip install 'bioform-mj[urdf]', or expand it yourself "
            f"(`xacro {path} > {stem}`, ROS's xacro tool) and give the .urdf"
        )
    if kind == "memory":
        raise XacroRefused(
            f"{path}: xacro stopped: it needed more than {XACRO_MEMORY_MB} MiB (a macro that multiplies itself?); "
            "nothing was imported"
        )
    if kind == "size":
        raise XacroRefused(f"{path}: xacro stopped: {why}, above the {XACRO_OUTPUT_MB} MB a robot can be")
    if kind == "refused":
        raise XacroRefused(f"{path}: xacro refused: {why}")
    raise XacroRefused(f"{path}: xacro cannot expand it: {why}")


def _run_child(path: Path, req: dict) -> dict:
    """Start the child, send ``req``, read its answer within the limits; a dict with ``xml`` or ``error``."""
    env = {"LC_ALL": "C.UTF-8", "PYTHONHASHSEED": "0"}  # nothing of the user's environment
    limit_s = XACRO_TIME_S
    cap = XACRO_OUTPUT_MB * 10**6 + 2**20
    try:
        proc = subprocess.Popen(
            [sys.executable, "-I", "-B", str(_CHILD)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            cwd=str(path.resolve().parent),
            env=env,
            start_new_session=True,  # its own process group: stopped as a whole
            close_fds=True,
        )
    except OSError as exc:
        raise XacroRefused(f"{path}: xacro's process cannot start: {exc}") from None
    chunks: list[bytes] = []
    size = 0
    start = time.monotonic()
    why = ""
    try:
        assert proc.stdin is not None and proc.stdout is not None
        try:
            proc.stdin.write(json.dumps(req).encode())
            proc.stdin.close()
        except BrokenPipeError:
            pass
        sel = selectors.DefaultSelector()
        sel.register(proc.stdout, selectors.EVENT_READ)
        while True:
            left = limit_s - (time.monotonic() - start)
            if left <= 0:
                why = "time"
                break
            if not sel.select(timeout=min(left, 1.0)):
                continue
            data = os.read(proc.stdout.fileno(), 1 << 16)
            if not data:
                break
            size += len(data)
            if size > cap:
                why = "size"
                break
            chunks.append(data)
        sel.close()
    finally:
        if why or proc.poll() is None:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if proc.stdout is not None:
            proc.stdout.close()
    if why == "time" or proc.returncode in (-signal.SIGXCPU, -signal.SIGKILL):
        raise XacroRefused(
            f"{path}: xacro stopped after {XACRO_TIME_S} s, its time limit (a macro that never ends?); "
            "nothing was imported"
        )
    if why == "size":
        return {"kind": "size", "error": f"its expansion is over {XACRO_OUTPUT_MB} MB"}
    try:
        answer = json.loads(b"".join(chunks).decode("utf-8"))
    except (UnicodeDecodeError, ValueError):
        answer = None
    if not isinstance(answer, dict):
        how = f"signal {-proc.returncode}" if proc.returncode and proc.returncode < 0 else f"status {proc.returncode}"
        return {"kind": "error", "error": f"its process ended with {how} and no answer"}
    return answer

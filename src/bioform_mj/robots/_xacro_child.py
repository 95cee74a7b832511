"""The xacro expansion of one robot file, in a process of its own (design §12): a xacro file is a program.

Run by :func:`bioform_mj.robots.xacro_sandbox.expand` as ``python -I -B _xacro_child.py`` (isolated: no
``PYTHONPATH``, no user site, no current folder on the path), with an environment that holds no
variable of the user's, its working folder the robot file's folder. It reads one JSON request on
stdin and writes one JSON answer on stdout (``{"xml": …}`` or ``{"error": …, "kind": …}``).

Before it reads the robot file it limits itself: address space (``RLIMIT_AS``, bytes), CPU time
(``RLIMIT_CPU``, s), no file written (``RLIMIT_FSIZE`` 0), no core file. Then it narrows xacro:

- a robot file reads no environment variable: ``$(optenv NAME default)`` is ``default`` (empty when
  none) and ``$(env NAME)`` is refused, unless ``--xacro-arg NAME=VALUE`` gives ``NAME`` (the same values
  as ``$(arg NAME)``); the answer lists each ``(NAME, value, source)`` taken;
- ``$(eval …)`` runs without Python's builtins (xacro's own gives it ``open``, ``exec``, ``__import__``);
- a ``${…}`` expression naming a dunder, holding a string with ``__`` or naming ``format``,
  ``format_map``, ``vars``, ``type``, ``getattr``, ``globals``, ``locals``, ``eval``, ``exec``,
  ``compile``, ``open`` or ``__import__`` is refused (the known ways out of xacro's expression sandbox);
- ``xacro:include`` and ``xacro.load_yaml`` read only files inside the allowed folders: the robot
  file's package (the nearest folder above it holding a ``package.xml``, else its own folder), the
  ``package_path`` folders, and the packages ``$(find NAME)`` resolves;
- an audit hook (:func:`sys.addaudithook`, which no code can remove) refuses, for the rest of the
  process: starting or signalling a process, sockets, ``ctypes``, frame and garbage-collector
  introspection, changing a function's code, writing, renaming or deleting a file, and opening a file
  outside the allowed folders (and Python's own installation, for its lazy imports).

This module is run as a script, never imported by the package; it imports ``find_package`` by the
module name its parent passes (``find_module``).
"""

from __future__ import annotations

import importlib
import json
import os
import resource
import signal
import sys
import types
from pathlib import Path


def _limit(mem_bytes: int, cpu_s: int) -> None:
    """Address space ``mem_bytes`` (bytes), CPU time ``cpu_s`` (s), no file written, no core file."""
    resource.setrlimit(resource.RLIMIT_AS, (mem_bytes, mem_bytes))
    resource.setrlimit(resource.RLIMIT_CPU, (cpu_s, cpu_s + 1))
    resource.setrlimit(resource.RLIMIT_FSIZE, (0, 0))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write fails (EFBIG) instead of killing us silently


# ------------------------------------------------------------------ the OS layers (design §12; Linux only)
#: Landlock (kernel >= 5.13): filesystem access rights by ABI version; network (ABI 4), scopes (ABI 6)
_LL_FS = {1: (1 << 13) - 1, 2: (1 << 14) - 1, 3: (1 << 15) - 1, 5: (1 << 16) - 1}
_LL_READ = (1 << 2) | (1 << 3)  # READ_FILE | READ_DIR
_LL_SYS = (444, 445, 446)  # landlock_create_ruleset, _add_rule, _restrict_self (every architecture)
#: system calls refused by the seccomp filter (EPERM): new processes and threads, sockets, tracing, mounts,
#: namespaces, kernel keyrings, bpf, io_uring, modules; per architecture (AUDIT_ARCH, numbers)
_SECCOMP_DENY = {
    "x86_64": (
        0xC000003E,
        (59, 322, 57, 58, 56, 435, 41, 53, 42, 49, 50, 43, 288, 101, 310, 311, 165, 166, 272, 308, 161, 155)
        + (250, 248, 249, 321, 298, 323, 425, 175, 313, 246, 304, 303),
    ),
    "aarch64": (
        0xC00000B7,
        (221, 281, 220, 435, 198, 199, 203, 200, 201, 202, 242, 117, 270, 271, 40, 39, 97, 268, 51, 41)
        + (219, 217, 218, 280, 241, 282, 425, 105, 273, 104, 265, 264),
    ),
}


def os_sandbox(read_dirs: list[str]) -> dict[str, str]:
    """Confine this process with what the kernel offers without root, each layer on its own (a layer that is
    unavailable is said, never fatal): ``no_new_privs`` (``prctl``), a new network namespace (``unshare``:
    no interface but a down loopback), Landlock (reads only beneath ``read_dirs``, no write, no TCP) and a
    seccomp filter (:data:`_SECCOMP_DENY`). Returns ``{layer: "on…" | "unavailable: why"}``. Must run
    single-threaded, before the audit hook (it refuses ``ctypes``)."""
    import ctypes
    import platform

    out: dict[str, str] = {}
    if not sys.platform.startswith("linux"):
        return {"os": f"unavailable: {sys.platform} (Linux only)"}
    libc = ctypes.CDLL(None, use_errno=True)
    libc.syscall.restype = ctypes.c_long
    libc.prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong]

    def err() -> str:
        return os.strerror(ctypes.get_errno())

    nnp = libc.prctl(38, 1, 0, 0, 0) == 0  # PR_SET_NO_NEW_PRIVS
    out["no_new_privs"] = "on" if nnp else f"unavailable: {err()}"
    newnet, newuser = 0x40000000, 0x10000000
    flags = newnet if os.geteuid() == 0 else newuser | newnet  # root keeps its file access (no user ns)
    out["netns"] = "on" if libc.unshare(flags) == 0 else f"unavailable: {err()}"
    out["landlock"] = _landlock(libc, read_dirs, err) if nnp else "unavailable: needs no_new_privs"
    out["seccomp"] = _seccomp(libc, platform.machine(), err) if nnp else "unavailable: needs no_new_privs"
    return out


def _landlock(libc, read_dirs: list[str], err) -> str:
    import ctypes

    abi = libc.syscall(_LL_SYS[0], None, ctypes.c_size_t(0), ctypes.c_uint32(1))  # LANDLOCK_CREATE_RULESET_VERSION
    if abi < 1:
        return f"unavailable: {err()} (kernel < 5.13 or Landlock not enabled)"
    fs = _LL_FS[max(k for k in _LL_FS if k <= abi)]
    attr = (ctypes.c_uint64 * 3)(fs, 3 if abi >= 4 else 0, 3 if abi >= 6 else 0)  # net: bind/connect TCP; scopes
    size = 8 * (3 if abi >= 6 else 2 if abi >= 4 else 1)
    rfd = libc.syscall(_LL_SYS[0], ctypes.byref(attr), ctypes.c_size_t(size), ctypes.c_uint32(0))
    if rfd < 0:
        return f"unavailable: {err()}"
    try:
        for d in read_dirs:
            try:
                fd = os.open(d, os.O_PATH | os.O_CLOEXEC)
            except OSError:
                continue
            rule = (ctypes.c_ubyte * 12)()  # struct landlock_path_beneath_attr, packed: u64 access, s32 fd
            ctypes.memmove(rule, ctypes.byref(ctypes.c_uint64(_LL_READ if os.path.isdir(d) else 1 << 2)), 8)
            ctypes.memmove(ctypes.byref(rule, 8), ctypes.byref(ctypes.c_int32(fd)), 4)
            ok = libc.syscall(_LL_SYS[1], ctypes.c_int(rfd), ctypes.c_int(1), ctypes.byref(rule), ctypes.c_uint32(0))
            os.close(fd)
            if ok != 0:
                return f"unavailable: a rule for {d}: {err()}"
        if libc.syscall(_LL_SYS[2], ctypes.c_int(rfd), ctypes.c_uint32(0)) != 0:
            return f"unavailable: {err()}"
    finally:
        os.close(rfd)
    return f"on (ABI {abi}): reads beneath {len(read_dirs)} folders, no write" + (", no TCP" if abi >= 4 else "")


def _seccomp(libc, machine: str, err) -> str:
    import ctypes

    if machine not in _SECCOMP_DENY:
        return f"unavailable: no filter for {machine}"
    arch, deny = _SECCOMP_DENY[machine]
    eperm = 0x00050000 | 1  # SECCOMP_RET_ERRNO | EPERM
    prog = [(0x20, 0, 0, 4), (0x15, 1, 0, arch), (0x06, 0, 0, eperm), (0x20, 0, 0, 0)]  # arch, else EPERM; nr
    if machine == "x86_64":
        prog.append((0x35, 0, 1, 0x40000000))  # the x32 ABI: refused
        prog.append((0x06, 0, 0, eperm))
    for nr in deny:
        prog += [(0x15, 0, 1, nr), (0x06, 0, 0, eperm)]
    prog.append((0x06, 0, 0, 0x7FFF0000))  # SECCOMP_RET_ALLOW

    class Filter(ctypes.Structure):
        _fields_ = [("code", ctypes.c_uint16), ("jt", ctypes.c_uint8), ("jf", ctypes.c_uint8), ("k", ctypes.c_uint32)]

    class Prog(ctypes.Structure):
        _fields_ = [("len", ctypes.c_uint16), ("filter", ctypes.POINTER(Filter))]

    arr = (Filter * len(prog))(*[Filter(*f) for f in prog])
    fprog = Prog(len(prog), arr)
    libc.prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_void_p, ctypes.c_ulong, ctypes.c_ulong]
    if libc.prctl(22, 2, ctypes.addressof(fprog), 0, 0) != 0:  # PR_SET_SECCOMP, SECCOMP_MODE_FILTER
        return f"unavailable: {err()}"
    return f"on: {len(deny)} system calls refused (processes, threads, sockets, ptrace, mounts, namespaces, …)"


def _within(path: str, roots: list[str]) -> bool:
    real = os.path.realpath(path)
    return any(real == r or real.startswith(r.rstrip(os.sep) + os.sep) for r in roots)


#: names a ``${…}`` expression may not use: attribute access by string, introspection, code
_DENY_NAMES = frozenset(
    {
        "format",
        "format_map",
        "vars",
        "type",
        "getattr",
        "setattr",
        "delattr",
        "globals",
        "locals",
        "eval",
        "exec",
        "compile",
        "open",
        "breakpoint",
        "mro",
        "gi_frame",
        "gi_code",
        "cr_frame",
        "f_globals",
        "f_locals",
        "f_back",
        "f_builtins",
        "tb_frame",
        "func_globals",
    }
)


def _consts(code: types.CodeType):
    for c in code.co_consts:
        if isinstance(c, types.CodeType):
            yield from _consts(c)
        else:
            yield c


def _names(code: types.CodeType):
    yield from code.co_names
    for c in code.co_consts:
        if isinstance(c, types.CodeType):
            yield from _names(c)


def _check_expr(expr: str, what: str) -> types.CodeType:
    """The compiled expression, or a refusal naming what it uses."""
    code = compile(expr.strip(), "<expression>", "eval")
    bad = sorted({n for n in _names(code) if n.startswith("__") or n in _DENY_NAMES})
    if bad:
        raise _Refused(
            f"{what} '{expr.strip()[:80]}' uses {', '.join(bad)}: refused (design §12: a robot file is data)"
        )
    for c in _consts(code):
        if isinstance(c, (str, bytes)) and ("__" in c if isinstance(c, str) else b"__" in c):
            raise _Refused(
                f"{what} '{expr.strip()[:80]}' holds a string with '__': refused (design §12: a robot file is data)"
            )
    return code


class _Refused(Exception):
    """What the sandbox refuses (reported as kind ``refused``)."""


def _install_hook(roots: list[str], search: list[str], python_dirs: list[str]) -> None:
    """The audit hook: refuses processes, sockets, ctypes, introspection, writes and reads outside ``roots``.

    ``search``: folders of the package search path, whose ``package.xml`` files and listings ``$(find)`` reads.
    The hook keeps no name in any namespace: no code can reach it to change it.
    """
    blocked = (
        "subprocess.",
        "os.system",
        "os.exec",
        "os.posix_spawn",
        "os.spawn",
        "os.fork",
        "os.forkpty",
        "os.kill",
        "os.killpg",
        "os.putenv",
        "os.unsetenv",
        "os.remove",
        "os.unlink",
        "os.rename",
        "os.rmdir",
        "os.mkdir",
        "os.chmod",
        "os.chown",
        "os.chdir",
        "os.chroot",
        "os.symlink",
        "os.link",
        "os.truncate",
        "os.setxattr",
        "os.removexattr",
        "os.startfile",
        "os.add_dll_directory",
        "socket.",
        "ctypes.",
        "mmap.",
        "shutil.",
        "urllib.",
        "http.",
        "ftplib.",
        "smtplib.",
        "webbrowser.",
        "pty.",
        "sys._getframe",
        "sys._current_frames",
        "sys._current_exceptions",
        "sys.settrace",
        "sys.setprofile",
        "sys.addaudithook",
        "gc.",
        "code.__new__",
        "function.__new__",
        "cpython.run_",
        "cpython.remote_debugger",
        "marshal.",
        "pickle.",
        "sqlite3.",
        "resource.setrlimit",
        "resource.prlimit",
    )
    banned_modules = frozenset(
        {
            "ctypes",
            "_ctypes",
            "subprocess",
            "_posixsubprocess",
            "multiprocessing",
            "socket",
            "_socket",
            "pty",
            "gc",
            "pickle",
            "_pickle",
            "marshal",
            "mmap",
        }
    )
    write_flags = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC | os.O_APPEND

    def hook(event: str, args: tuple) -> None:
        if event.startswith(blocked):
            raise PermissionError(f"refused by bioform's xacro sandbox: {event}")
        if event == "import" and args and (args[0] in banned_modules or str(args[0]).split(".")[0] in banned_modules):
            raise PermissionError(f"refused by bioform's xacro sandbox: import {args[0]}")
        if event == "object.__setattr__" and len(args) > 1 and str(args[1]).startswith("__"):
            if str(args[1]) in ("__code__", "__globals__", "__closure__", "__defaults__", "__kwdefaults__"):
                raise PermissionError(f"refused by bioform's xacro sandbox: setting {args[1]}")
        if event == "open" and args:
            path, mode, flags = (list(args) + [None, None])[:3]
            if isinstance(path, int):
                return
            if (isinstance(mode, str) and any(c in mode for c in "wax+")) or (
                isinstance(flags, int) and flags & write_flags
            ):
                raise PermissionError(f"refused by bioform's xacro sandbox: writing {path}")
            p = os.fsdecode(path)
            if _within(p, roots + python_dirs):
                return
            if os.path.basename(p) == "package.xml" and _within(p, search):
                return
            raise PermissionError(f"refused by bioform's xacro sandbox: reading {p} (outside the robot's packages)")
        if event in ("os.listdir", "os.scandir", "glob.glob") and args:
            p = args[0]
            p = "." if p is None else os.fsdecode(p) if not isinstance(p, int) else None
            if p is not None and not _within(p, roots + python_dirs + search):
                raise PermissionError(f"refused by bioform's xacro sandbox: listing {p}")

    sys.addaudithook(hook)


def _answer(obj: dict) -> None:
    """The answer, on the real stdout (xacro's prints went to stderr)."""
    sys.__stdout__.buffer.write(json.dumps(obj).encode())
    sys.__stdout__.flush()


def main() -> int:
    """Read the request, limit the process, expand the file, answer. Returns the exit status."""
    req = json.loads(sys.stdin.read())
    _limit(int(req["mem_bytes"]), int(req["cpu_s"]))
    sys.dont_write_bytecode = True
    sys.stdout = sys.stderr  # xacro's own prints never reach the answer
    try:
        xml, includes = _expand(req)
    except MemoryError:
        _answer({"kind": "memory", "error": "it needed more memory than the limit"})
        return 3
    except _Refused as exc:
        _answer({"kind": "refused", "error": str(exc)})
        return 3
    except PermissionError as exc:
        _answer({"kind": "refused", "error": str(exc)})
        return 3
    except _Missing as exc:
        _answer({"kind": "missing", "error": str(exc), "package": exc.package})
        return 3
    except _NoXacro:
        _answer({"kind": "no_xacro", "error": "the xacro package is not installed"})
        return 3
    except RecursionError:
        _answer({"kind": "error", "error": "too deeply nested (a macro that calls itself?)"})
        return 3
    except Exception as exc:  # noqa: BLE001 - xacro's errors (XacroException, a bad include, bad XML) in one line
        chain, e = [], exc
        while e is not None and len(chain) < 4:
            if isinstance(e, (_Refused, PermissionError, _Missing)):
                kind = "missing" if isinstance(e, _Missing) else "refused"
                extra = {"package": e.package} if isinstance(e, _Missing) else {}
                _answer({"kind": kind, "error": str(e), **extra})
                return 3
            if isinstance(e, MemoryError):
                _answer({"kind": "memory", "error": "it needed more memory than the limit"})
                return 3
            chain.append(e)
            e = getattr(e, "exc", None) or e.__cause__ or e.__context__
        _answer({"kind": "error", "error": " ".join(str(exc).split()) or type(exc).__name__})
        return 3
    if len(xml) > int(req["max_out_bytes"]):
        _answer({"kind": "size", "error": f"its expansion is {len(xml) / 1e6:.0f} MB"})
        return 3
    env_used = [list(e) for e in _ENV_USED]
    _answer({"xml": xml, "includes": includes, "sandbox": _SANDBOX, "env": env_used, "unused_args": _UNUSED})
    return 0


#: what :func:`os_sandbox` applied, for the answer
_SANDBOX: dict[str, str] = {}
#: ``$(optenv)``/``$(env)`` the file read, in order, each ``(NAME, value, "default" | "arg")`` once (a name whose
#: defaults differ from place to place appears with each)
_ENV_USED: dict[tuple[str, str, str], None] = {}
#: given ``--xacro-arg`` names the file never asked about
_UNUSED: list[str] = []


class _SeenArgs(dict):
    """xacro's ``$(arg)`` mapping, remembering every name the file asked about: read (``$(arg NAME)``,
    ``xacro.arg``) or declared (``<xacro:arg name=NAME>`` tests whether it is given)."""

    def __init__(self, *args: object) -> None:
        super().__init__(*args)
        self.seen: set[str] = set()

    def __getitem__(self, key: str) -> str:
        self.seen.add(key)
        return super().__getitem__(key)

    def __contains__(self, key: object) -> bool:
        self.seen.add(str(key))
        return super().__contains__(key)

    def get(self, key: str, default: object = None) -> object:
        self.seen.add(key)
        return super().get(key, default)


class _NoXacro(Exception):
    """The xacro package is not installed where this Python looks."""


class _Missing(Exception):
    """``$(find NAME)`` of a package on no search path."""

    def __init__(self, package: str) -> None:
        super().__init__(f"$(find {package}): package '{package}' is on no search path")
        self.package = package


def _expand(req: dict) -> tuple[str, list[str]]:
    """The expanded XML of ``req["file"]`` (see the module docstring) and the files it included or loaded."""
    for var, val in req["search_env"].items():  # the package search path only, for $(find)
        os.environ[var] = val
    # bioform_mj's find_package (same search path as package://), without the package's __init__
    pkg = types.ModuleType("bioform_mj")
    pkg.__path__ = [req["package_dir"]]
    sys.modules["bioform_mj"] = pkg
    find_mod = importlib.import_module(req["find_module"])
    packages = tuple((str(n), str(d)) for n, d in req["packages"])  # find_package takes (NAME, DIR) pairs

    import xml.dom.expatbuilder  # noqa: F401 - imported before the hook: minidom imports it lazily
    import xml.dom.minidom  # noqa: F401

    try:
        import xacro
        import xacro.substitution_args as subst
    except ImportError:
        raise _NoXacro() from None

    try:
        import xacro.color  # noqa: F401
        import yaml  # noqa: F401 - load_yaml imports it; before the hook
    except ImportError:
        pass

    path = req["file"]
    roots = [os.path.realpath(r) for r in req["roots"]]
    search = [os.path.realpath(s) for s in req["search_dirs"]]

    def find(name: str) -> str:
        found, _ = find_mod.find_package(name, packages, Path(path))
        if found is None:
            raise _Missing(name)
        real = os.path.realpath(str(found))
        if real not in roots:
            roots.append(real)
        return str(found)

    given = {str(n): str(v) for n, v in req["args"]}  # --xacro-arg / xacro_args: the only "environment"

    def env(name: str, *_a: object, **_k: object) -> str:
        if name in given:
            _ENV_USED[(name, given[name], "arg")] = None
            return given[name]
        raise _Refused(
            f"$(env {name}): refused: a robot file reads no environment variable (design §12); set it with "
            f'--xacro-arg {name}=VALUE (or xacro_args = {{{name} = "VALUE"}} in the robot\'s table)'
        )

    def optenv(name: str, default: str = "", *_a: object, **_k: object) -> str:
        value, source = (given[name], "arg") if name in given else (str(default), "default")
        _ENV_USED[(name, value, source)] = None
        return value

    subst._eval_find = find
    subst._eval_env = env
    subst._eval_optenv = optenv
    subst._eval_dict["env"] = env
    subst._eval_dict["optenv"] = optenv
    subst._eval_dict["find"] = find

    # the original's eval(s, {}, ...) gets the real builtins from its empty globals: replaced
    def restricted_eval(s: str, context: dict) -> str:
        code = _check_expr(s, "$(eval …)")
        context.setdefault("arg", {})
        functions = {
            "arg": lambda name: subst.convert_value(subst._eval_arg(name, args=context["arg"]), "auto"),
            "dirname": lambda: subst._eval_dirname(context["filename"]),
        }
        functions.update(subst._eval_dict)
        functions["__builtins__"] = {}
        return str(eval(code, {"__builtins__": {}}, subst._DictWrapper(context["arg"], functions)))

    subst._eval = restricted_eval

    def safe_eval(expr: str, globals: dict, locals: dict | None = None) -> object:  # noqa: A002 - xacro's names
        code = _check_expr(expr, "expression ${…}")
        globals.update(__builtins__={})
        return eval(code, globals, locals)

    xacro.safe_eval = safe_eval
    # python.vars / python.type reach attributes by string (python['vars'](...)['…']): gone
    for table in (xacro._global_symbols, xacro._global_symbols.get("python", {})):
        for name in ("vars", "type", "getattr", "globals", "locals", "eval", "exec", "compile", "open"):
            table.pop(name, None)

    def check_read(filename: str, what: str) -> None:
        if not _within(filename, roots):
            raise _Refused(
                f"{what} '{filename}' is outside the robot's packages ({', '.join(roots)}): refused "
                "(design §12: xacro reads only the robot's packages; give its package with --package-path NAME=DIR)"
            )

    original_load_yaml = xacro.load_yaml

    def load_yaml(filename: str) -> object:
        check_read(xacro.abs_filename_spec(filename), "xacro.load_yaml")
        return original_load_yaml(filename)

    for table in (xacro._global_symbols, xacro._global_symbols.get("xacro", {})):
        if "load_yaml" in table:
            table["load_yaml"] = load_yaml
    xacro.load_yaml = load_yaml

    original_parse = xacro.parse

    def parse(inp: object, filename: str | None = None) -> object:
        if inp is None and filename is not None:
            check_read(os.path.join(xacro.root_dir, filename), "include")
        return original_parse(inp, filename)

    xacro.parse = parse

    python_dirs = sorted({os.path.realpath(p) for p in sys.path if p and os.path.isdir(p)})  # lazy imports
    # the OS layers first (they use ctypes, which the hook refuses); $(find) packages lie under the search dirs
    _SANDBOX.update(os_sandbox(sorted({*roots, *search, *python_dirs, os.path.realpath(req["package_dir"])})))
    _install_hook(roots, search, python_dirs)
    mappings = _SeenArgs((str(n), str(v)) for n, v in req["args"])
    doc = xacro.process_file(path, mappings=mappings)
    # a given NAME the file never declared nor read ($(arg), <xacro:arg>, $(optenv), $(env)): a misspelt flag?
    _UNUSED.extend(n for n in dict(req["args"]) if n not in mappings.seen and n not in {e[0] for e in _ENV_USED})
    return doc.toxml(), sorted({os.path.realpath(f) for f in getattr(xacro, "all_includes", [])})


if __name__ == "__main__":
    sys.exit(main())

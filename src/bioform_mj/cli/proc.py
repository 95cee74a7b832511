"""The ``bioform`` process's plumbing (design §10, §17): standard streams that survive a closed pipe
or a full device, the MuJoCo distribution check, signal handling and MuJoCo's log capture. Used by
:mod:`bioform_mj.cli.main`; imports nothing of it."""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

from bioform_mj.core.errors import UNSAFE_TEXT, InputError, Interrupted, escape_unsafe

_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class _PipeSafe:
    """``sys.stdout``/``sys.stderr`` that survive a closed reader (``bioform run … | head -1``),
    a full device (``> /dev/full``) or a closed descriptor (``>&-``, where Python sets the stream
    to None): on the first ``OSError`` of a write the stream's descriptor is pointed at
    ``/dev/null`` (as Python's documentation of SIGPIPE recommends) and every later write is
    dropped, so the command goes on writing its files and exits with its own code (design §17).
    A control or bidirectional-format character other than tab, newline and carriage return
    (:data:`~bioform_mj.core.errors.UNSAFE_TEXT`: U+202E, ESC) is written escaped (``\\u202e``), as is a
    character the stream's encoding lacks (``PYTHONIOENCODING=ascii``: ``²`` as ``\\xb2``).
    A closed pipe is silence, as Unix tools do; any other error (``error``) is said on stderr at
    the end, if stderr still works. Everything else is the wrapped stream's."""

    def __init__(self, stream: Any, name: str) -> None:
        self._stream = stream
        self.name = name
        self.broken = stream is None
        self.error: OSError | None = None

    def write(self, text: str) -> int:
        if not self.broken:
            try:  # bidi/format and control characters of names escaped, as one_line does (issue 28)
                return self._stream.write(escape_unsafe(text, keep="\t\n\r") if UNSAFE_TEXT.search(text) else text)
            except UnicodeEncodeError:  # PYTHONIOENCODING=ascii: '·', '²' were an internal error (issue 28)
                enc = getattr(self._stream, "encoding", None) or "ascii"
                return self.write(text.encode(enc, "backslashreplace").decode(enc))
            except OSError as exc:
                self._break(exc)
        return len(text)

    def flush(self) -> None:
        if not self.broken:
            try:
                self._stream.flush()
            except OSError as exc:
                self._break(exc)

    def isatty(self) -> bool:
        return not self.broken and self._stream.isatty()

    def _break(self, exc: OSError) -> None:
        self.broken = True
        if not isinstance(exc, BrokenPipeError):
            self.error = exc
        _silence(self._stream)

    def __getattr__(self, name: str) -> Any:
        if self._stream is None:
            raise AttributeError(name)
        return getattr(self._stream, name)


def _silence(stream: Any) -> None:
    """Point ``stream``'s file descriptor at /dev/null, so that its buffered bytes, the flush at
    exit and child processes writing there find a sink instead of a closed pipe."""
    try:
        fd = stream.fileno()
    except (AttributeError, OSError, ValueError):  # a test's capture buffer: nothing to redirect
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, fd)
    finally:
        os.close(null)


def _guard_streams():
    """Wrap ``sys.stdout`` and ``sys.stderr`` in :class:`_PipeSafe`; returns the function undoing
    it, which first says on stderr what a failing stdout dropped (never silent)."""
    old = sys.stdout, sys.stderr
    out, err = _PipeSafe(sys.stdout, "stdout"), _PipeSafe(sys.stderr, "stderr")
    sys.stdout, sys.stderr = out, err

    def undo() -> None:
        if out.error is not None:
            err.write(
                f"warning: stdout could not be written ({out.error.strerror or out.error}); its output was dropped\n"
            )
            err.flush()
        sys.stdout, sys.stderr = old

    return undo


def _kept_beside(path: str) -> str:
    """What is in the folder of the file that could not be written (for the error line)."""
    folder = Path(path).parent
    try:
        names = sorted(e.name + ("/" if e.is_dir() else "") for e in os.scandir(folder) if not e.name.startswith("."))
    except OSError:
        return "nothing kept"
    if not names:
        return f"nothing kept in {folder}"
    shown = ", ".join(names[:6]) + (f" and {len(names) - 6} more" if len(names) > 6 else "")
    return f"kept in {folder}: {shown}"


def check_mujoco_distributions() -> None:
    """Exit 2 (an :class:`InputError`) when the installed distributions that provide the
    ``mujoco`` package disagree on the release (design §17): ``mujoco`` is a metapackage over
    ``mujoco-core`` from 4.0 on, and both install files into ``mujoco/``; ``mujoco`` 3.x under
    ``mujoco-core`` 4.x (what ``mujoco-warp`` plus ``mujoco-core>=4.0.1`` resolves to) overwrites
    one with the other silently. Reads package metadata only (no import of MuJoCo)."""
    from bioform_mj.core.deps import mujoco_distribution_problem

    problem = mujoco_distribution_problem()
    if problem:
        raise InputError(problem)


def _catch_signals():
    """SIGINT and SIGTERM raise :class:`Interrupted` (a ``KeyboardInterrupt``) once; signals that
    arrive while the run cleans up are ignored. Returns the function restoring the old handlers.

    Python runs the handler between bytecodes: inside the compiled loop it waits for the end
    of the chunk in progress (at most one log interval of simulated time).
    """

    def handler(signum, _frame):
        _ignore_signals()
        raise Interrupted(signum)

    try:
        old = {s: signal.signal(s, handler) for s in _SIGNALS}
    except ValueError:  # not the main thread (an embedding application): leave signals alone
        return lambda: None

    def restore() -> None:
        for s, h in old.items():
            signal.signal(s, h)

    return restore


def exit_deaf(main: Callable[[], int]) -> NoReturn:
    """Run ``main()`` and exit with its code, ignoring SIGINT/SIGTERM from its return on: a signal in the
    interpreter's teardown killed a finished run or sweep (exit -15, no line; issue 28)."""
    try:
        code = main()
    finally:  # --help ends in argparse's SystemExit
        _ignore_signals()
    raise SystemExit(code)


def _ignore_signals() -> None:
    try:
        for s in _SIGNALS:
            signal.signal(s, signal.SIG_IGN)
    except ValueError:
        pass


def _mujoco_log():
    """MuJoCo's warnings: echoed on stderr and kept for the run folder, never MUJOCO_LOG.TXT in the cwd."""
    from bioform_mj.outputs.mjlog import capture

    return capture()


def progress_bar(enabled: bool, label: str):
    """A progress callback drawing a bar on a terminal, or None when stderr is not one."""
    if not enabled or not sys.stderr.isatty():
        return None
    state = {"last": -1}

    def phase(text: str | None) -> None:  # what happens before the steps (a compile): one line
        if text:
            sys.stderr.write(f"\r{label}: {text}\n")
            sys.stderr.flush()

    def cb(k: int, n: int) -> None:
        pct = int(100 * k / max(1, n))
        if pct != state["last"]:
            state["last"] = pct
            bar = "#" * (pct // 4)
            sys.stderr.write(f"\r{label} [{bar:<25}] {pct:3d}%")
            if k >= n:
                sys.stderr.write("\n")
            sys.stderr.flush()

    cb.phase = phase  # type: ignore[attr-defined]
    return cb

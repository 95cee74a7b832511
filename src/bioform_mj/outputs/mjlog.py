"""MuJoCo's own warnings go into the run folder's ``MUJOCO_LOG.TXT``, not the working directory.

MuJoCo's default warning handler appends ``MUJOCO_LOG.TXT`` in the *current directory* and
prints to stderr. :func:`capture` replaces it (``mujoco.set_mju_user_warning``, in every
MuJoCo version we support; the handler is called with the GIL taken, also from the compiled
loop's ``mj_step``) with one that only remembers the message; the CLI echoes each as a
``warning: MuJoCo: …`` line and :meth:`MujocoLog.write` appends them, in MuJoCo's own format,
to ``DIR/MUJOCO_LOG.TXT``. Errors need nothing: the Python bindings turn ``mju_error`` into
an exception and log nothing. No ``chdir``: the working directory stays the user's.
"""

from __future__ import annotations

import functools
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

FILENAME = "MUJOCO_LOG.TXT"


class MujocoLog:
    """Messages of MuJoCo's warning handler since :meth:`install`, with their times."""

    def __init__(self, echo: bool = True) -> None:
        self.messages: list[tuple[float, str]] = []
        self.echo = echo
        self.written = 0
        self._installed = False

    def _handler(self, msg: str) -> None:  # never raises: it is called from C
        try:
            self.messages.append((time.time(), str(msg)))
            if self.echo:  # the current sys.stderr (tests swap it)
                sys.stderr.write(f"warning: MuJoCo: {msg}\n")
                sys.stderr.flush()
        except Exception:  # noqa: BLE001
            pass

    def install(self) -> MujocoLog:
        import mujoco

        mujoco.set_mju_user_warning(self._handler)
        self._installed = True
        return self

    def uninstall(self) -> None:
        if self._installed:
            import mujoco

            mujoco.set_mju_user_warning(None)
            self._installed = False

    def write(self, folder: str | Path) -> Path | None:
        """Append the messages not yet written to ``folder/MUJOCO_LOG.TXT`` (MuJoCo's format); None if none."""
        new = self.messages[self.written :]
        if not new:
            return None
        path = Path(folder) / FILENAME
        try:
            with open(path, "a", encoding="utf-8") as fh:
                for t, msg in new:
                    fh.write(f"WARNING {time.strftime('%a %b %d %H:%M:%S %Y', time.localtime(t))}: {msg}\n\n")
        except OSError as exc:  # disk full, ulimit -f: named like every other output (design §17)
            from bioform_mj.core.errors import WriteFailed

            raise WriteFailed(str(path), exc) from exc
        self.written += len(new)
        return path

    def __enter__(self) -> MujocoLog:
        return self.install()

    def __exit__(self, *exc) -> None:
        self.uninstall()


def capture(echo: bool = True) -> MujocoLog:
    """A :class:`MujocoLog` installed now (use as a context manager to restore MuJoCo's handler)."""
    return MujocoLog(echo).install()


def api_warnings(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Decorate a Python-API entry point (:func:`bioform_mj.simulate`): while it runs, MuJoCo's warnings
    become Python ``RuntimeWarning``s (``"MuJoCo: …"``) instead of a ``MUJOCO_LOG.TXT`` appended in the
    caller's working folder (issue 28). A handler someone already installed (the CLI's
    :class:`MujocoLog`, the user's own) is left alone."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        sc = args[0] if args else next(iter(kwargs.values()), None)
        if getattr(getattr(sc, "plant", None), "kind", "") == "ideal" and "mujoco" not in sys.modules:
            return fn(*args, **kwargs)  # the ideal plant: MuJoCo is not even imported (a registered kind may use it)
        import mujoco

        if mujoco.get_mju_user_warning() is not None:
            return fn(*args, **kwargs)
        log = MujocoLog(echo=False)
        log.install()
        try:
            return fn(*args, **kwargs)
        finally:
            log.uninstall()
            for _t, msg in log.messages:
                warnings.warn(f"MuJoCo: {msg}", RuntimeWarning, stacklevel=2)

    return wrapper

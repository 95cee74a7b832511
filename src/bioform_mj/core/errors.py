"""Exception types shared by the library and the CLI.

Each maps to one exit code of the ``bioform`` command (design §10): input errors
exit 2 with a single ``error:`` line, a diverging simulation exits 3. :data:`UNSAFE_TEXT` and
:func:`escape_unsafe`: the characters of a name that would change how a line of output reads.
"""

from __future__ import annotations

import contextlib
import re
import warnings
from collections.abc import Iterator

#: characters of a user's text (a joint, body or robot name, a scenario string) that change how a line of output
#: reads: the C0 and C1 control characters and DEL (a newline in a joint name forged ``error:`` lines, issue 28),
#: and Unicode's bidirectional and invisible format characters (U+202E, the right-to-left override, shows
#: ``wheel_left`` as ``tfel_leehw``; U+2028 is a line break; U+200B is invisible). Refused in names a robot file
#: or a scenario gives, escaped (``\\u202e``) wherever such text is printed or written into a text file.
UNSAFE_TEXT = re.compile(
    "[\x00-\x1f\x7f-\x9f\u061c\u200b-\u200f\u2028-\u202e\u2060-\u2064\u2066-\u206f\ufeff\ufff9-\ufffb]"
)


def escape_unsafe(text: str, keep: str = "") -> str:
    """``text`` with each :data:`UNSAFE_TEXT` character not in ``keep`` escaped as Python writes it (``\\n``,
    ``\\x85``, ``\\u202e``): one line that reads as it is stored."""
    return UNSAFE_TEXT.sub(lambda m: m.group() if m.group() in keep else repr(m.group())[1:-1], text)


class BioformError(Exception):
    """Base class of every error the CLI reports without a traceback."""


class InputError(BioformError, ValueError):
    """Bad user input: a scenario key, a graph, a model file, a CLI flag (exit 2)."""


class ScenarioError(InputError):
    """A scenario value is missing, mistyped or out of range; names the key."""

    def __init__(self, key: str, message: str) -> None:
        self.key = key
        super().__init__(f"scenario key '{key}': {message}" if key else message)


class GraphError(InputError):
    """The communication graph violates Assumption 1 or is malformed."""


class RobotWarning(UserWarning):
    """What a scenario asks beyond a robot's margins (traction, tip-over), said before the run;
    the CLI prints each as one ``warning:`` line on stderr."""


class CacheWarning(UserWarning):
    """The compiled kernels cannot be cached where they usually are (a read-only home): where they are cached
    instead, or that they are not (each run then compiles again, design §2)."""


class OutcomeWarning(UserWarning):
    """How a run ended badly, issued by :func:`~bioform_mj.run.simulate.simulate` once it has the summary
    (never silent, design §18.1): one per follower with an outcome other than ``ok`` (``tipped``,
    ``lost``, ...; every kind with its detail), and one when the run diverged. ``follower``: the
    follower's id (1-based; None for the divergence), ``outcomes``: its ``{"kind", "detail", "t"}``
    list as in the summary. Filter it to silence a loop that reads the outcomes itself:
    ``warnings.simplefilter("ignore", bioform_mj.OutcomeWarning)``, or run within :func:`quiet_outcomes`
    (sweeps and calibration do)."""

    def __init__(self, message: str, follower: int | None = None, outcomes: list | None = None) -> None:
        super().__init__(message)
        self.follower = follower
        self.outcomes = list(outcomes or [])


@contextlib.contextmanager
def quiet_outcomes() -> Iterator[None]:
    """Within: no :class:`OutcomeWarning` (the other warnings as before). For whoever reports the
    outcomes itself or has no use for them: ``bioform run``, a sweep's row, calibration, timing loops,
    the kernels' warm-up (design §18.1)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutcomeWarning)
        yield


class Diverged(BioformError, RuntimeError):
    """The closed loop produced NaN/inf or a state beyond the configured limits (exit 3)."""

    def __init__(self, message: str, *, step: int, time: float) -> None:
        self.step = step
        self.time = time
        super().__init__(message)


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived (the CLI exits ``128 + signum``: 130 or 143).

    A ``KeyboardInterrupt``, so code that cleans up on Ctrl-C cleans up on SIGTERM too.
    ``result``: a partial run result, if whoever caught it on the way attached one.
    """

    def __init__(self, signum: int) -> None:
        import signal

        self.signum = signum
        self.result = None
        super().__init__(signal.Signals(signum).name)


class ControllerError(BioformError, TypeError):
    """A user's controller or observer breaks its protocol (``control/base.py``, ``sim.Observer``):
    a missing method (raised when :func:`~bioform_mj.run.simulate.simulate` starts, before any step) or a
    return of the wrong shape (raised at the step; the run's log so far is attached as ``result``)."""


class WriteFailed(BioformError, OSError):
    """An output file could not be written (disk full, read-only file system, ``ulimit -f``):
    names the file; the CLI adds what was kept and exits 1 (design §17).

    ``path``: the file that was being written; ``errno``/``strerror``: the operating system's."""

    def __init__(self, path: str, exc: OSError) -> None:
        self.path = str(path)
        self.kept = ""  # what the command kept, filled in by whoever knows (the CLI)
        super().__init__(exc.errno, f"cannot write '{path}': {exc.strerror or exc}")

    def __str__(self) -> str:
        return str(self.strerror) + (f"; {self.kept}" if self.kept else "")

"""Whether the robot check a run makes before it starts is skipped (design §14.2): ``BIOFORM_NO_ROBOT_CHECK=1``,
which ``--no-robot-check`` sets for one command. A module of its own, so that the check, the pre-run check and
the batch engine read one rule without importing each other."""

from __future__ import annotations

import os

#: the environment variable that skips the pre-run robot check (any value but "" and "0")
SKIP_ENV = "BIOFORM_NO_ROBOT_CHECK"


def skipped() -> bool:
    """True when :data:`SKIP_ENV` asks to skip the pre-run robot check."""
    return os.environ.get(SKIP_ENV, "").strip() not in ("", "0")

"""What to do about a model MuJoCo refuses, in bioform's terms (design §12).

MuJoCo's compile errors name a compiler option that fixes some of them (``inertia must satisfy A + B >= C;
use 'balanceinertia' to fix``: a URDF whose inertia breaks the triangle inequality, as Gazebo accepts). A user
of bioform cannot set MuJoCo's ``<compiler>`` of a URDF, so the hint names the mapping key and the flag that
set it (:data:`OPTIONS`), or says that none does.
"""

from __future__ import annotations

import re

__all__ = ["OPTIONS", "compile_hint"]

#: MuJoCo compiler option -> (the robot mapping key, the ``robot check`` / ``identify`` flag) that sets it
OPTIONS = {"balanceinertia": ("balance_inertia = true", "--balance-inertia")}

_USE = re.compile(r"use '(?P<opt>\w+)' to fix")


def compile_hint(msg: str) -> str:
    """A suffix for a compile error ``msg``: how to set the compiler option it names from bioform (the robot's
    mapping key, the flag), or that no key sets it; ``""`` when it names none."""
    m = _USE.search(str(msg))
    if m is None:
        return ""
    opt = m["opt"]
    if opt in OPTIONS:
        key, flag = OPTIONS[opt]
        return f" (bioform sets MuJoCo's '{opt}': map {key} in the robot's table, or pass {flag})"
    return (
        f" (no bioform key sets MuJoCo's compiler option '{opt}': set <compiler {opt}=\"true\"/> in a copy of the file)"
    )

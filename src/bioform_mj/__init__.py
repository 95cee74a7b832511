"""bioform_mj: distributed leader-follower formation control (Xu et al., IEEE T-IV 2024)
on an ideal unicycle plant and on MuJoCo differential-drive robots.

The Python API at the top level: :func:`load` a scenario, :func:`simulate` it, read the
:class:`RunResult` (``.summary``, ``.log``, ``.table()``); :class:`Controller` is the protocol a
controller of your own implements, and :func:`register_controller` names one so that ``method = "NAME"``
runs it; :class:`OutcomeWarning` is what ``simulate`` warns of a follower
that tipped, was lost, ... or a run that diverged. The names are imported on first use, so ``import bioform_mj``
stays cheap (no numba, no MuJoCo).
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

from bioform_mj._version import __version__

#: public name -> (module, attribute), imported on first access
_LAZY = {
    "load": ("bioform_mj.scenario.loader", "load"),
    "Scenario": ("bioform_mj.scenario.config", "Scenario"),
    "simulate": ("bioform_mj.run.simulate", "simulate"),
    "RunResult": ("bioform_mj.run.simulate", "RunResult"),
    "Controller": ("bioform_mj.control.base", "Controller"),
    "register_controller": ("bioform_mj.control.registry", "register_controller"),
    "OutcomeWarning": ("bioform_mj.core.errors", "OutcomeWarning"),
}

__all__ = [
    "Controller",
    "OutcomeWarning",
    "RunResult",
    "Scenario",
    "__version__",
    "load",
    "register_controller",
    "simulate",
]

if TYPE_CHECKING:  # for type checkers and editors; at run time __getattr__ imports lazily
    from bioform_mj.control.base import Controller
    from bioform_mj.control.registry import register_controller
    from bioform_mj.core.errors import OutcomeWarning
    from bioform_mj.run.simulate import RunResult, simulate
    from bioform_mj.scenario.config import Scenario
    from bioform_mj.scenario.loader import load


def __getattr__(name: str) -> Any:
    try:
        module, attr = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'bioform_mj' has no attribute {name!r}") from None
    if name == "load":  # a scenario with "auto" scale is resolved by the run package's resolver (design §21)
        import_module("bioform_mj.run")
    value = getattr(import_module(module), attr)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))

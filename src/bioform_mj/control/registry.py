"""The controller registry: the names ``method`` (a scenario's key, ``--method``, ``sweep --methods``,
``table1 --methods``) may take, each with the factory that builds its controller (design §22).

The paper's four methods are its first entries (:data:`~bioform_mj.control.stack.METHODS`, built by
:func:`~bioform_mj.control.params.paper_stack`). A user adds one from Python with
:func:`register_controller` (``bioform_mj.register_controller``), or from an installed package through
the entry-point group :data:`ENTRY_POINT_GROUP`, which the CLI reads too::

    [project.entry-points."bioform_mj.controllers"]
    kanayama = "my_package.control:make_kanayama"

A factory is called as ``factory(scenario, plant)`` and returns a
:class:`~bioform_mj.control.base.Controller` of ``scenario.n`` followers. Entry points are read once per
process, and only when a name is not registered already (listing every name reads them too), so the paper's
methods cost no scan of the installed packages; a package's module is imported only when its name is run.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from bioform_mj.control.base import Controller
from bioform_mj.control.params import paper_stack
from bioform_mj.control.stack import METHODS
from bioform_mj.core.errors import ControllerError, InputError

#: the entry-point group an installed package declares its controllers in
ENTRY_POINT_GROUP = "bioform_mj.controllers"
#: what a name may be: it becomes part of a run folder's name (``runs/<scenario>-<plant>-<method>``)
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]{0,63}")

#: ``factory(scenario, plant) -> Controller``
ControllerFactory = Callable[[Any, Any], Controller]


@dataclass(frozen=True)
class ControllerEntry:
    """One registered name: its factory (None until an entry point's module is imported) and where it came
    from (``"bioform_mj"`` for the paper's methods, ``"register_controller"``, or ``"entry point DIST"``)."""

    name: str
    factory: ControllerFactory | None
    source: str
    entry_point: Any = None  # an importlib.metadata.EntryPoint not loaded yet


_ENTRIES: dict[str, ControllerEntry] = {m: ControllerEntry(m, paper_stack, "bioform_mj") for m in METHODS}
_SCANNED = False


def _check_name(name: str) -> None:
    if not isinstance(name, str) or NAME_PATTERN.fullmatch(name) is None:
        raise ValueError(
            f"controller name {name!r}: must be 1-64 characters, letters, digits and _ . + - "
            "(starting with a letter or digit): it becomes part of a run folder's name"
        )


def register_controller(name: str, factory: ControllerFactory, *, replace: bool = False) -> None:
    """Register ``factory`` under ``name``, so that ``method = "NAME"`` (a scenario, ``--method``, a sweep's
    ``methods``, ``table1``'s) runs the controller it builds (design §22).

    Parameters
    ----------
    name : str
        The method's name: 1-64 letters, digits, ``_ . + -``. The paper's four methods cannot be replaced.
    factory : callable
        ``factory(scenario, plant) -> Controller``: called once per run, after the plant is built and before
        its reset, with the checked scenario and the plant; the controller must have ``scenario.n`` followers.
    replace : bool
        Replace a name registered already (else that is a ``ValueError``).
    """
    _check_name(name)
    if not callable(factory):
        raise TypeError(f"controller {name!r}: the factory must be callable, got {type(factory).__name__}")
    old = _ENTRIES.get(name)
    if old is not None and old.source == "bioform_mj":
        raise ValueError(f"controller {name!r} is one of the paper's methods and cannot be replaced")
    if old is not None and not replace:
        raise ValueError(f"controller {name!r} is registered already ({old.source}); pass replace=True to replace it")
    _ENTRIES[name] = ControllerEntry(name, factory, "register_controller")


def unregister_controller(name: str) -> None:
    """Remove a name added by :func:`register_controller` or an entry point (the paper's methods stay).

    Parameters
    ----------
    name : str
        A registered name; an unknown one is a ``KeyError``.
    """
    entry = _ENTRIES.get(name)
    if entry is None:
        raise KeyError(name)
    if entry.source == "bioform_mj":
        raise ValueError(f"controller {name!r} is one of the paper's methods and cannot be removed")
    del _ENTRIES[name]


def _scan_entry_points() -> None:
    """Add the names that installed packages declare in :data:`ENTRY_POINT_GROUP` (once per process; a
    name registered already, the paper's methods included, wins over an entry point)."""
    global _SCANNED
    if _SCANNED:
        return
    _SCANNED = True
    from importlib.metadata import entry_points

    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in _ENTRIES or NAME_PATTERN.fullmatch(ep.name) is None:
            continue
        dist = getattr(getattr(ep, "dist", None), "name", None) or ep.value
        _ENTRIES[ep.name] = ControllerEntry(ep.name, None, f"entry point {dist}", ep)


def controller_names() -> tuple[str, ...]:
    """Every registered name: the paper's four methods first, then the others in registration order
    (the entry points of installed packages included)."""
    _scan_entry_points()
    return tuple(_ENTRIES)


def is_registered(name: str) -> bool:
    """True when ``name`` is a registered controller (reads the entry points only for a name not registered).

    Parameters
    ----------
    name : str
        A method's name.
    """
    if name not in _ENTRIES:
        _scan_entry_points()
    return name in _ENTRIES


def unknown_method(name: str, what: str = "method") -> str:
    """The message for a name that is not registered: ``unknown method 'X' (expected one of: ...)``.

    Parameters
    ----------
    name : str
        The name asked for.
    what : str
        What the message calls it.
    """
    return f"unknown {what} '{name}' (expected one of: {', '.join(controller_names())})"


def parse_methods(text: str, flag: str = "--methods") -> list[str]:
    """The methods a comma-separated list names, in its order, each once; ``all`` stands for the paper's four
    (``all,my-controller`` runs them and a registered one); every name must be registered.

    Parameters
    ----------
    text : str
        ``"all"`` or ``"NAME,NAME,..."``.
    flag : str
        The option it came from, for the :class:`~bioform_mj.core.errors.InputError` that refuses it.
    """
    methods: list[str] = []
    for m in (t.strip() for t in text.split(",")):
        for name in METHODS if m == "all" else (m,) if m else ():
            if not is_registered(name):
                raise InputError(f"{flag}: {unknown_method(name)[:-1]}, or all)")
            if name not in methods:
                methods.append(name)
    if not methods:
        raise InputError(f"{flag}: no method given")
    return methods


def controller_factory(name: str) -> ControllerFactory:
    """The factory registered under ``name`` (an entry point's module is imported now).

    Parameters
    ----------
    name : str
        A registered name; an unknown one is a ``ValueError`` naming the registered ones.
    """
    if not is_registered(name):
        raise ValueError(unknown_method(name))
    entry = _ENTRIES[name]
    if entry.factory is None:
        try:
            factory = entry.entry_point.load()
        except Exception as exc:
            raise ControllerError(
                f"controller {name!r} ({entry.source}): loading {entry.entry_point.value} failed: "
                f"{type(exc).__name__}: {exc}"
            ) from exc
        if not callable(factory):
            raise ControllerError(f"controller {name!r} ({entry.source}): {entry.entry_point.value} is not callable")
        entry = ControllerEntry(name, factory, entry.source)
        _ENTRIES[name] = entry
    return entry.factory  # type: ignore[return-value]


def build_controller(name: str, scenario: Any, plant: Any) -> Any:
    """The controller registered as ``name``, built for ``scenario`` and ``plant``.

    Parameters
    ----------
    name : str
        A registered name (``scenario.method`` for a run).
    scenario : Scenario
        The run's checked scenario.
    plant : Plant
        The plant the controller will drive (built, not reset yet).
    """
    factory = controller_factory(name)
    try:
        return factory(scenario, plant)
    except Exception as exc:
        if _ENTRIES[name].source != "bioform_mj":
            exc.add_note(f"bioform: raised by the factory of controller {name!r} ({_ENTRIES[name].source})")
        raise


def is_builtin(name: str) -> bool:
    """True for the paper's four methods (the stack the compiled loops and the batch engine run).

    Parameters
    ----------
    name : str
        A method's name.
    """
    entry = _ENTRIES.get(name)
    return entry is not None and entry.source == "bioform_mj"

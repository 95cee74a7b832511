"""The plant kinds: ``plant.kind`` → the factory that builds that plant from a scenario (design §8, §22).

A plant kind is one line here, :func:`register_plant`; what a plant offers beyond the :class:`~bioform_mj.plants.base.
Plant` interface is declared by the runtime-checkable protocols of :mod:`bioform_mj.plants.base`, never by its kind.
The shipped kinds (``ideal``, ``mujoco``) read the whole scenario, a floor above this one, so the run package registers
their factories when imported (:mod:`bioform_mj.run.simulate`), as it registers the ``"auto"`` scale; importing the
run package registers :func:`plant_kinds` with the scenario's validation (``scenario.check.register_plant_kinds``), so
that ``plant.kind`` and ``--plant`` accept every registered kind. An installed package declares its plants in the
entry-point group :data:`ENTRY_POINT_GROUP`, which the CLI reads too (read once per process, only when a kind is not
registered already; its module imported only when the kind is built)::

    [project.entry-points."bioform_mj.plants"]
    my-plant = "my_package.plant:make_plant"
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

__all__ = ["ENTRY_POINT_GROUP", "PlantFactory", "plant_factory", "plant_kinds", "register_plant"]

#: the entry-point group an installed package declares its plant kinds in
ENTRY_POINT_GROUP = "bioform_mj.plants"

#: ``factory(scenario) -> plant``: the plant of a checked scenario at its initial poses
PlantFactory = Callable[[Any], Any]

#: what a kind may be: it becomes part of a run folder's name (``runs/<scenario>-<plant>-<method>``)
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]{0,63}")

_FACTORIES: dict[str, PlantFactory] = {}
#: kinds installed packages declare (:data:`ENTRY_POINT_GROUP`), not loaded yet: ``kind -> EntryPoint``
_ENTRY_POINTS: dict[str, Any] = {}
_SCANNED = False


def _scan_entry_points() -> None:
    """Add the kinds installed packages declare (once per process; a kind registered already wins)."""
    global _SCANNED
    if _SCANNED:
        return
    _SCANNED = True
    from importlib.metadata import entry_points

    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name not in _FACTORIES and NAME_PATTERN.fullmatch(ep.name) is not None:
            _ENTRY_POINTS.setdefault(ep.name, ep)


def register_plant(kind: str, factory: PlantFactory) -> None:
    """Register (or replace) the factory of plant kind ``kind``.

    Parameters
    ----------
    kind : str
        The name a scenario's ``plant.kind`` (and ``--plant``) gives: 1-64 letters, digits, ``_ . + -`` (it becomes
        part of a run folder's name). Once registered, a scenario may name it (its validation asks this registry).
    factory : callable
        ``factory(scenario) -> plant``: builds the plant of a checked scenario at its initial poses.
    """
    if not isinstance(kind, str) or NAME_PATTERN.fullmatch(kind) is None:
        raise ValueError(
            f"plant kind {kind!r}: must be 1-64 characters, letters, digits and _ . + - (starting with a letter or "
            "digit): it becomes part of a run folder's name"
        )
    if not callable(factory):
        raise ValueError(f"plant kind {kind!r}: the factory must be callable, got {type(factory).__name__}")
    _FACTORIES[kind] = factory


def plant_kinds() -> tuple[str, ...]:
    """The registered plant kinds, in registration order, then those installed packages declare (entry points)."""
    _scan_entry_points()
    return (*_FACTORIES, *(k for k in _ENTRY_POINTS if k not in _FACTORIES))


def plant_factory(kind: str) -> PlantFactory:
    """The factory of plant kind ``kind``; ValueError naming the registered kinds for an unknown one."""
    if kind not in _FACTORIES:
        _scan_entry_points()
        if kind in _ENTRY_POINTS:  # an installed package's: its module imported now, once
            factory = _ENTRY_POINTS.pop(kind).load()
            register_plant(kind, factory)
    try:
        return _FACTORIES[kind]
    except KeyError:
        known = ", ".join(plant_kinds()) or "none (import bioform_mj.run: it registers the shipped plants)"
        raise ValueError(f"unknown plant kind {kind!r}; registered: {known}") from None

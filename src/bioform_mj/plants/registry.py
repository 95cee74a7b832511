"""The plant kinds: ``plant.kind`` → the factory that builds that plant from a scenario (design §8, §22).

A plant kind is one line here, :func:`register_plant`; what a plant offers beyond the :class:`~bioform_mj.plants.base.
Plant` interface is declared by the runtime-checkable protocols of :mod:`bioform_mj.plants.base`, never by its kind.
The shipped kinds (``ideal``, ``mujoco``) read the whole scenario, a floor above this one, so the run package registers
their factories when imported (:mod:`bioform_mj.run.simulate`), as it registers the ``"auto"`` scale.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["PlantFactory", "plant_factory", "plant_kinds", "register_plant"]

#: ``factory(scenario) -> plant``: the plant of a checked scenario at its initial poses
PlantFactory = Callable[[Any], Any]

_FACTORIES: dict[str, PlantFactory] = {}


def register_plant(kind: str, factory: PlantFactory) -> None:
    """Register (or replace) the factory of plant kind ``kind``.

    Parameters
    ----------
    kind : str
        The name a scenario's ``plant.kind`` gives.
    factory : callable
        ``factory(scenario) -> plant``: builds the plant of a checked scenario at its initial poses.
    """
    if not (isinstance(kind, str) and kind.strip()):
        raise ValueError(f"a plant kind is a non-empty name, got {kind!r}")
    if not callable(factory):
        raise ValueError(f"plant kind {kind!r}: the factory must be callable, got {type(factory).__name__}")
    _FACTORIES[kind] = factory


def plant_kinds() -> tuple[str, ...]:
    """The registered plant kinds, in registration order."""
    return tuple(_FACTORIES)


def plant_factory(kind: str) -> PlantFactory:
    """The factory of plant kind ``kind``; ValueError naming the registered kinds for an unknown one."""
    try:
        return _FACTORIES[kind]
    except KeyError:
        known = ", ".join(_FACTORIES) or "none (import bioform_mj.run: it registers the shipped plants)"
        raise ValueError(f"unknown plant kind {kind!r}; registered: {known}") from None

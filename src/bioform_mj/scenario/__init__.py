"""Scenarios: frozen dataclasses, TOML files, presets, ``--set`` overrides, validation.

The dataclass defaults *are* the paper scenario (one source of defaults); the
shipped ``presets/paper.toml`` restates them with the choices the paper leaves
open, and a test keeps the two equal. Unknown keys are an error, never ignored.
Follower ids are 1-based in files and messages.

The package by concern, importing downwards (config ← check ← loader), never this ``__init__``:

- :mod:`bioform_mj.scenario.config`: the frozen dataclasses (:class:`Scenario` and its tables),
  the allowed values of the string keys and the bounds on a run;
- :mod:`bioform_mj.scenario.check`: :func:`validate` and :func:`run_size`;
- :mod:`bioform_mj.scenario.loader`: presets, TOML files and run records, ``--set`` overrides,
  :func:`load`, and the transforms made on load (:func:`apply_scale`, :func:`apply_robots_to_ideal`);
- :mod:`bioform_mj.scenario.record`: a run's own record as a scenario;
- :mod:`bioform_mj.scenario.doc`: what every key means, the source of the generated reference.

The names in ``__all__`` are the package's public API, imported on first use (so importing one
submodule does not import the others).
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

_CONFIG = (
    "DERIVATIVES ESTIMATOR_INITS EVENT_KINDS GAIN_SCALINGS GRAPH_KINDS LEADER_KINDS MAX_ARRAY MAX_CONTROL_STEPS "
    "MAX_FLOAT MAX_INT MAX_NAME MAX_PHYSICS_STEPS MAX_RUN_BYTES MIN_PHYSICS_DT PAPER_C PLANTS SATURATIONS SENSINGS "
    "DisturbanceCfg EstimatorCfg EventCfg FaultsCfg FormationCfg GraphCfg KinematicCfg LeaderCfg LearnerCfg LimitsCfg "
    "PlantCfg Scenario SimCfg TorqueCfg"
).split()
_CHECK = ["robot_encoder_cpr", "run_size", "validate"]
_LOADER = [
    "apply_robots_to_ideal",
    "apply_scale",
    "from_dict",
    "load",
    "parse_override",
    "preset_descriptions",
    "preset_names",
]
#: public name -> the submodule that defines it
_HOME = {
    **dict.fromkeys(_CONFIG, "config"),
    **dict.fromkeys(_CHECK, "check"),
    **dict.fromkeys(_LOADER, "loader"),
}

__all__ = sorted(_HOME)


def __getattr__(name: str) -> Any:
    try:
        home = _HOME[name]
    except KeyError:
        raise AttributeError(f"module 'bioform_mj.scenario' has no attribute {name!r}") from None
    value = getattr(import_module(f"bioform_mj.scenario.{home}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_HOME))

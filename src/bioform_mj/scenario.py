"""Scenarios: frozen dataclasses, TOML files, presets, ``--set`` overrides, validation.

The dataclass defaults *are* the paper scenario (one source of defaults); the
shipped ``scenarios/paper.toml`` restates them with the choices the paper leaves
open, and a test keeps the two equal. Unknown keys are an error, never ignored.
Follower ids are 1-based in files and messages.

This module gathers the scenario's public names from where they live, by concern:

- :mod:`bioform_mj.scenario_config`: the frozen dataclasses (:class:`Scenario` and its tables),
  the allowed values of the string keys and the bounds on a run;
- :mod:`bioform_mj.scenario_load`: presets, TOML files and run records, ``--set`` overrides,
  :func:`load`, and the transforms made on load (:func:`apply_scale`, :func:`apply_robots_to_ideal`);
- :mod:`bioform_mj.scenario_check`: :func:`validate` and :func:`run_size`.

They import each other downwards (config ← check ← load) and never this module.
"""

from __future__ import annotations

from .control.stack import METHODS
from .errors import InputError, ScenarioError
from .graph import Graph
from .leader import Trajectory
from .obstacles import Obstacle, ObstacleCfg, ObstacleFieldCfg
from .robots import PackagePath, RobotRef
from .safety import SafetyCfg
from .scenario_check import robot_encoder_cpr, run_size, validate
from .scenario_config import (
    DERIVATIVES,
    ESTIMATOR_INITS,
    EVENT_KINDS,
    GAIN_SCALINGS,
    GRAPH_KINDS,
    LEADER_KINDS,
    MAX_CONTROL_STEPS,
    MAX_INT,
    MAX_NAME,
    MAX_PHYSICS_STEPS,
    MAX_RUN_BYTES,
    MIN_PHYSICS_DT,
    PAPER_C,
    PLANTS,
    SATURATIONS,
    SENSINGS,
    DisturbanceCfg,
    EstimatorCfg,
    EventCfg,
    FaultsCfg,
    FormationCfg,
    GraphCfg,
    KinematicCfg,
    LeaderCfg,
    LearnerCfg,
    LimitsCfg,
    PlantCfg,
    Scenario,
    SimCfg,
    TorqueCfg,
)
from .scenario_load import (
    apply_robots_to_ideal,
    apply_scale,
    from_dict,
    load,
    parse_override,
    preset_descriptions,
    preset_names,
)

__all__ = [
    "DERIVATIVES",
    "ESTIMATOR_INITS",
    "EVENT_KINDS",
    "GAIN_SCALINGS",
    "GRAPH_KINDS",
    "LEADER_KINDS",
    "MAX_CONTROL_STEPS",
    "MAX_INT",
    "MAX_NAME",
    "MAX_PHYSICS_STEPS",
    "MAX_RUN_BYTES",
    "METHODS",
    "MIN_PHYSICS_DT",
    "PAPER_C",
    "PLANTS",
    "SATURATIONS",
    "SENSINGS",
    "DisturbanceCfg",
    "EstimatorCfg",
    "EventCfg",
    "FaultsCfg",
    "FormationCfg",
    "Graph",
    "GraphCfg",
    "InputError",
    "KinematicCfg",
    "LeaderCfg",
    "LearnerCfg",
    "LimitsCfg",
    "Obstacle",
    "ObstacleCfg",
    "ObstacleFieldCfg",
    "PackagePath",
    "PlantCfg",
    "RobotRef",
    "SafetyCfg",
    "Scenario",
    "ScenarioError",
    "SimCfg",
    "TorqueCfg",
    "Trajectory",
    "apply_robots_to_ideal",
    "apply_scale",
    "from_dict",
    "load",
    "parse_override",
    "preset_descriptions",
    "preset_names",
    "robot_encoder_cpr",
    "run_size",
    "validate",
]

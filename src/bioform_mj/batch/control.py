"""The control step of many formations on MuJoCo Warp: one thread per world.

:func:`_control` is ``control/kernel.py``'s ``control_step`` (learner, estimator consensus,
command and torques with the world's ``torque.derivative`` mode, estimator advance) plus the loop
bookkeeping of ``engine.py`` (run metrics, divergence guards)
and the plant glue of ``plants/mujoco_kernels.py`` (observe, wheel torques and the
eq. 34 disturbance as chassis ``xfrc_applied``; ``ctrl = scale · τ``, the DC motors' driver
input per N·m, design §8.2; the plant faults of ``faults.py``, actuator limits and pushes, from
per-world tables, :class:`PlantFaults`), for one world per thread, looping over
its followers and graph edges in the same order as the CPU kernels; with each world's network
faults and sensor noise (``faults.Faults.sense``/``comm``: :class:`CommFaults`, :func:`_comm`).
Every equation is
the Warp translation (:mod:`.samesource`) of ``control/equations.py``: only loops,
indexing and bookkeeping are written here.

Precision: controller state, gains and metrics are float64 (the learner is stiff and
``ĉ`` must match the CPU engine to 0.5 %); MuJoCo Warp's physics is float32, converted at
the boundary (``qpos``/``qvel`` in, ``ctrl``/``xfrc_applied`` out).

:func:`run_batch` runs a list of scenarios (one world each) of one composed scene. The
step loop (``n_substeps`` × ``mjw.step``, each followed with ``plant.sensing = "odometry"`` by
:func:`_sense`, the encoders, gyro and dead reckoning of design §8.3, and for DC motors by
:func:`_delivered`, which feeds the learner the torque delivered over the period, design §8.2,
+ one ``_control`` launch per control step) reads nothing back to the host; the step counter lives on the device,
so on CUDA a chunk of control steps is captured once as a CUDA graph and replayed.

The code lives by concern in :mod:`.device` (the Warp equations, per-world columns, structs and device
functions), :mod:`.step` (the control kernel), :mod:`.plant_kernels` (DC-motor feed, events, sensing,
record/replay), :mod:`.tables` (host-side tables), :mod:`.probe` (the physics probe) and :mod:`.runner`
(:class:`BatchRun`, :func:`run_batch`); this module re-exports what callers import from it.
"""

from __future__ import annotations

import sys
import types

from . import probe as _probe
from .device import (
    CAPACITY_EXCEEDED,
    DERIV,
    FAULT_SCALARS,
    GAIN_SCALARS,
    GUARD_FAILED,
    LFRAME,
    ODO,
    OSEED,
    RUNNING,
    SCALARS,
    BatchGains,
    BatchState,
    CommFaults,
    PlantFaults,
)
from .plant_kernels import EVENT_FIELDS
from .probe import PROBE_TOL, SETTLE_S, _probed, check_physics, physics_probe  # noqa: F401 (_probed: see _Reexports)
from .runner import BatchRun, run_batch
from .tables import event_tables, plant_fault_tables

__all__ = [
    "BatchGains",
    "BatchRun",
    "BatchState",
    "CAPACITY_EXCEEDED",
    "CommFaults",
    "DERIV",
    "EVENT_FIELDS",
    "FAULT_SCALARS",
    "GAIN_SCALARS",
    "GUARD_FAILED",
    "LFRAME",
    "ODO",
    "OSEED",
    "PROBE_TOL",
    "PlantFaults",
    "RUNNING",
    "SCALARS",
    "SETTLE_S",
    "check_physics",
    "event_tables",
    "physics_probe",
    "plant_fault_tables",
    "run_batch",
]


class _Reexports(types.ModuleType):
    """This module's class: the physics probe's settings (``PROBE_TOL``, ``SETTLE_S``) and its cache
    (``_probed``) live in :mod:`.probe`; reading or setting them here reads or sets them there, so code
    (and tests) that tune them through ``batch.control`` keep working."""

    _FORWARD = ("PROBE_TOL", "SETTLE_S", "_probed")

    def __getattribute__(self, name: str):
        if name in type(self)._FORWARD:
            return getattr(_probe, name)
        return super().__getattribute__(name)

    def __setattr__(self, name: str, value) -> None:
        if name in type(self)._FORWARD:
            setattr(_probe, name, value)
        else:
            super().__setattr__(name, value)

    def __delattr__(self, name: str) -> None:
        if name in type(self)._FORWARD:
            raise AttributeError(f"{name} lives in bioform_mj.batch.probe; set it, do not delete it")
        super().__delattr__(name)


sys.modules[__name__].__class__ = _Reexports

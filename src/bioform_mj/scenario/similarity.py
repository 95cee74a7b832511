"""Similarity scaling of a scenario: lengths × s, times × σ, every key by its declared unit (design §21).

Every scenario key declares its unit as field metadata (``field(metadata={"unit": "m/s"})``; a
per-channel pair or a row's columns as a tuple of units). :func:`factor` turns a unit into its
similarity factor — ``m`` → s, ``s`` → σ, ``rad`` and ``1`` → 1, products and quotients thereof —
and :func:`transform` multiplies every key by it, so no hand-written list can miss a key
(``tests/test_scenario_similarity.py`` walks every key and fails on one without a unit).

Kept, and why (metadata ``kept``): the numerical steps (``sim.control_dt``, ``physics_dt``,
``log_dt``, ``plant.sensor_dt``: the robot's and the computer's, a slower scenario is stepped finer
relative to its own time), the divergence guards (``limits.*``), the sensor's noise and bias, the
robot itself (``plant.robots``) and the scale keys. A unit carrying a mass (``kg``, ``N``: a torque
limit, ``c_true``, a payload, a push) is the robot's: the scaling cannot know its mass, so it is kept.

Mixed units (metadata ``mixed``; the paper's equations add quantities of different units there, no
scaling is exactly similar; design §21 says what is kept):

- eq. 32 ``V̇ = −(A + |x̃|) V + B x̃``: ``|x̃|`` (m) is added to ``A`` (1/s). ``A, B, D`` are scaled
  as rates (× 1/σ): the neuron is exactly similar in its linear range ``|x̃| ≪ A`` (``V ≈ B x̃ / A``,
  a length × s); its saturating term ``|x̃| V`` is similar only when ``s σ = 1``. At ``σ = 1`` this is
  the lengths-only scaling of before (``k1 B`` not shrunk).
- eq. 37 ``k4`` is both the integral gain of ``S`` (1/s) and the adaptation gain of ``ĉ``. It is
  scaled × σ², which keeps the adaptation rate ``λ = k4 τ² / k5`` × 1/σ (``k5`` × 1/σ) for the same
  robot; the ``k4`` pole of ``S`` then moves (× σ³ off similar; the implicit learner stays
  stable). The length part of the υ channel (× 1/s², with the torque's robot part left to
  ``learner.gain_scaling``) is not applied, as before: at ``σ = 1`` this is today's scaling.
- the torque law's ``phi`` is one boundary layer for ``υ̃`` (m/s) and ``ω̃`` (rad/s): scaled as rad/s.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
import typing
from typing import Any

#: the similarity factor of each base unit: m → s, s → σ; "1" and "-" (a label) dimensionless
_BASE = {"m": (1, 0), "s": (0, 1), "rad": (0, 0), "1": (0, 0), "-": (0, 0)}
#: units that carry a mass: the robot's (the scaling cannot know its mass ratio), kept
_MASS = {"kg", "N"}
_TOKEN = re.compile(r"^([A-Za-z1-]+)(?:\^(-?\d+)|([²³]))?$")


def exponents(unit: str) -> tuple[int, int] | None:
    """``(length exponent, time exponent)`` of ``unit`` (``"m/s^2"`` → ``(1, -2)``); None for a unit
    that carries a mass (kept). Raises ValueError on a unit it cannot read (a programming error)."""
    if not unit:
        raise ValueError("empty unit")
    num, _, den = unit.partition("/")
    if "/" in den:
        raise ValueError(f"unit {unit!r}: at most one '/'")
    el, et, mass = 0, 0, False
    for part, sign in ((num, 1), (den, -1)):
        if not part:
            continue
        for tok in re.split(r"[·*]", part.strip()):
            m = _TOKEN.match(tok.strip())
            if not m:
                raise ValueError(f"unit {unit!r}: cannot read {tok!r}")
            name = m.group(1)
            power = int(m.group(2)) if m.group(2) else {"²": 2, "³": 3}.get(m.group(3) or "", 1)
            if name in _MASS:
                mass = True
                continue
            if name not in _BASE:
                raise ValueError(f"unit {unit!r}: unknown base unit {name!r}")
            dl, dt = _BASE[name]
            el += sign * power * dl
            et += sign * power * dt
    return None if mass else (el, et)


def factor(unit: str, s: float, sigma: float) -> float:
    """The similarity factor of ``unit``: ``s^(length exponent) · σ^(time exponent)`` (1 for a unit
    that carries a mass, the robot's). Dimensionless: ``m/s`` → s/σ, ``rad/s^2`` → 1/σ², ``1/m`` → 1/s."""
    num, den = _num_den(unit, s, sigma)
    return num / den


def _num_den(unit: str, s: float, sigma: float) -> tuple[float, float]:
    """The factor of ``unit`` as ``(numerator, denominator)``, each a product of positive powers
    (``value * num / den``: ``k2 / s**2`` bit for bit as the lengths-only scaling computed it)."""
    ex = exponents(unit)
    if ex is None:
        return 1.0, 1.0
    num, den = 1.0, 1.0
    for base, e in ((s, ex[0]), (sigma, ex[1])):
        if e > 0:
            num *= base**e
        elif e < 0:
            den *= base ** (-e)
    return num, den


def _leaf_fields(cls: Any, prefix: str = "") -> list[tuple[str, Any, dataclasses.Field]]:
    """``(dotted key, type, field)`` of every leaf key of ``cls`` (tables recursed; an array of tables
    as ``key[].field``), internal fields left out."""
    from bioform_mj.robots.refs import PackagePath, RobotRef

    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        if f.metadata.get("internal"):
            continue
        tp = hints[f.name]
        if dataclasses.is_dataclass(tp) and tp not in (RobotRef, PackagePath):
            out += _leaf_fields(tp, f"{prefix}{f.name}.")
            continue
        if typing.get_origin(tp) is tuple:
            inner = typing.get_args(tp)[0]
            if dataclasses.is_dataclass(inner) and inner is not RobotRef:
                out += _leaf_fields(inner, f"{prefix}{f.name}[].")
                continue
        out.append((prefix + f.name, tp, f))
    return out


def key_units() -> dict[str, dict[str, Any]]:
    """``{dotted key: its field metadata}`` for every scenario key (``unit``, and ``kept`` / ``mixed``
    where set). A key without ``unit`` maps to metadata without it (the test refuses that)."""
    from bioform_mj.scenario.config import Scenario

    return {k: dict(f.metadata) for k, _tp, f in _leaf_fields(Scenario)}


def _scaled_value(value: Any, unit: Any, s: float, sigma: float, key: str) -> Any:
    """``value`` (a number, a flat tuple, or rows) times the factor of ``unit`` (one unit for all, or
    one per element / per column)."""
    if isinstance(value, (str, bool)) or value is None:
        return value
    if isinstance(value, tuple):
        if not value:
            return value
        if isinstance(value[0], tuple):  # rows: one unit per column
            return tuple(_scaled_value(r, unit, s, sigma, key) for r in value)
        units = unit if isinstance(unit, tuple) else (unit,) * len(value)
        return tuple(
            _scaled_value(v, units[j] if j < len(units) else units[-1], s, sigma, key) for j, v in enumerate(value)
        )
    if isinstance(unit, tuple):
        raise ValueError(f"{key}: a scalar with units per element {unit}")
    num, den = _num_den(unit, s, sigma)
    if num == 1.0 and den == 1.0:
        return value  # bit for bit, ints stay ints
    if isinstance(value, int):
        raise ValueError(f"{key}: an integer with unit {unit!r} cannot be scaled")
    if num != 1.0:
        value = value * num
    return value / den if den != 1.0 else value


@functools.cache
def _hints(cls: Any) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def transform(obj: Any, s: float, sigma: float, prefix: str = "") -> Any:
    """``obj`` (the :class:`~bioform_mj.scenario.config.Scenario` or one of its tables) with every key
    times the factor of its unit for lengths × ``s`` and times × ``sigma`` (relative factors: the
    caller divides by what is already applied). Keys marked ``kept`` stay; internal fields stay."""
    from bioform_mj.robots.refs import PackagePath, RobotRef

    if isinstance(obj, (RobotRef, PackagePath)):
        return obj
    changes = {}
    hints = _hints(type(obj))
    for f in dataclasses.fields(obj):
        if f.metadata.get("internal"):
            continue
        v = getattr(obj, f.name)
        key = prefix + f.name
        tp = hints[f.name]
        inner = typing.get_args(tp)[0] if typing.get_origin(tp) is tuple else None
        if dataclasses.is_dataclass(tp) and tp not in (RobotRef, PackagePath):
            nv = transform(v, s, sigma, key + ".")
        elif dataclasses.is_dataclass(inner) and inner is not RobotRef:
            nv = tuple(transform(x, s, sigma, key + "[].") for x in v)
        else:
            if "unit" not in f.metadata:
                raise ValueError(f"scenario key {key} declares no unit")
            if f.metadata.get("kept"):
                continue
            nv = _scaled_value(v, f.metadata["unit"], s, sigma, key)
        if nv is not v:
            changes[f.name] = nv
    return dataclasses.replace(obj, **changes) if changes else obj


def check_factor(key: str, value: Any, lo: float = 1e-3, hi: float = 1e3) -> float:
    """``value`` as a scale factor (finite, > 0, within ``[lo, hi]``) or ScenarioError naming ``key``."""
    from bioform_mj.core.errors import ScenarioError

    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScenarioError(key, f'must be a number > 0 or "auto", got {value!r}')
    if not (math.isfinite(value) and value > 0):
        raise ScenarioError(key, f'must be a number > 0 or "auto", got {value:g}')
    if not lo <= value <= hi:  # beyond, k2 / s² and the lengths leave floating point's comfortable range
        raise ScenarioError(key, f"must lie in [{lo:g}, {hi:g}], got {value:g}")
    return float(value)

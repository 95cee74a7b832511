"""Start and domain randomisation of the formation environment (design §20; docs/envs.md).

A trainer turns it on with ``parallel_env(..., randomize={key: (low, high), ...})``: at every
``reset`` each key's value is drawn uniformly in ``[low, high]`` from the episode's own random
stream (seeded by the episode seed, so an episode is a function of its seed alone). The keys:

- ``position`` (m): an offset added to each follower's initial x and y (2·n draws);
- ``heading`` (rad): an offset added to each follower's initial heading (n draws);
- ``c_true`` (factor): on each follower's true ``[a, b]`` (2·n draws; ideal plant);
- ``payload`` (kg): a point mass at each follower's axle midpoint from t = 0 (n draws);
- ``friction`` (factor): on every sliding friction of the scene (1 draw; MuJoCo);
- ``actuator`` (factor): each follower's wheel torque limit for the whole episode (n draws; a fault);
- ``faults.packet_loss``, ``faults.delay``, ``leader.speed``, ``leader.amplitude``,
  ``leader.frequency``, ``leader.radius``, ``plant.gyro_noise``, ``plant.gyro_bias`` (the key's
  unit): the scenario's own number (1 draw), as ``--set KEY=VALUE`` would set it.

The controller's prior is the nominal robot: the velocity action's learner starts from the
scenario's ``ĉ(0)`` whatever ``c_true``, ``payload`` or ``friction`` were drawn (as a payload
event of ``bioform run`` is not told to it). Everything but ``c_true`` and ``friction`` is
written into the episode's scenario (:attr:`~.parallel.FormationParallelEnv.episode_scenario`):
``bioform run`` of that scenario starts the same episode.

Refused with a ``ValueError`` naming the key, at construction (before any step): an unknown
key, a range that is not two finite numbers ``low <= high``, a bound the scenario's checks
(those of :func:`~bioform_mj.scenario.load`) refuse, and a key the plant has no such thing for.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from bioform_mj.core.errors import InputError
from bioform_mj.scenario.config import EventCfg, Scenario

#: the scenario's own scalar numbers a trainer may draw (``section.field``)
SCENARIO_KEYS: tuple[str, ...] = (
    "faults.packet_loss",
    "faults.delay",
    "leader.speed",
    "leader.amplitude",
    "leader.frequency",
    "leader.radius",
    "plant.gyro_noise",
    "plant.gyro_bias",
)
#: the environment's own keys: (unit, meaning)
KEYS: dict[str, tuple[str, str]] = {
    "position": ("m", "offset added to each follower's initial x and y"),
    "heading": ("rad", "offset added to each follower's initial heading"),
    "c_true": ("-", "factor on each follower's true [a, b] (ideal plant)"),
    "payload": ("kg", "point mass at each follower's axle midpoint from t = 0"),
    "friction": ("-", "factor on every sliding friction coefficient of the scene (MuJoCo)"),
    "actuator": ("-", "factor on each follower's wheel torque limit (the actuator fault, whole episode)"),
    **{k: ("as the scenario key", "the scenario's own number") for k in SCENARIO_KEYS},
}
#: how many redraws of the start positions when robots would overlap (MuJoCo) before giving up
MAX_REDRAWS = 100


def _with(sc: Scenario, key: str, value: float) -> Scenario:
    """``sc`` with the scenario key ``section.field`` set to ``value``."""
    section, field = key.split(".")
    return dataclasses.replace(sc, **{section: dataclasses.replace(getattr(sc, section), **{field: value})})


def _payload_events(sc: Scenario, masses: np.ndarray, every: bool = False) -> tuple[EventCfg, ...]:
    """``sc``'s events and a payload event at t = 0 per follower (of a positive mass, or ``every``)."""
    return tuple(sc.events) + tuple(
        EventCfg(time=0.0, kind="payload", follower=i + 1, mass=float(m), inertia=0.0)
        for i, m in enumerate(masses)
        if every or m > 0
    )


def _actuator_rows(sc: Scenario, scales: np.ndarray, t_end: float) -> tuple[tuple[float, ...], ...]:
    return tuple(sc.faults.actuator) + tuple((float(i + 1), 0.0, t_end, float(s)) for i, s in enumerate(scales))


class Randomization:
    """Validated ranges ``{key: (low, high)}`` and the per-episode draw of them (see the module docstring).

    ``base`` is the environment's scenario (checked); ``t_end`` (s) the episode's length.
    """

    def __init__(self, spec: Mapping[str, Any] | None, base: Scenario, t_end: float) -> None:
        from bioform_mj.scenario.loader import checked

        self.ranges: dict[str, tuple[float, float]] = {}
        if spec is None:
            return
        if not isinstance(spec, Mapping):
            raise ValueError(f"randomize must be a mapping {{key: (low, high)}}, got {type(spec).__name__}")
        n, kind = base.n, base.plant.kind
        self.t_end = float(t_end)
        for key, rng in spec.items():
            if key not in KEYS:
                raise ValueError(f"unknown randomisation key {key!r} (expected one of: {', '.join(KEYS)})")
            try:  # strings and booleans were taken as numbers, 10**400 an OverflowError (issue 28)
                if isinstance(rng, (str, bytes)) or any(isinstance(v, (bool, str, bytes)) for v in rng):
                    raise TypeError
                lo, hi = (float(v) for v in rng)
            except (TypeError, ValueError, OverflowError):
                try:
                    shown = repr(rng)
                    shown = shown if len(shown) <= 80 else shown[:60] + "…"
                except ValueError:  # an int of more than 4300 digits has no repr
                    shown = "a number too large to write"
                raise ValueError(
                    f"randomize[{key!r}] must be a range (low, high) of two numbers, got {shown}"
                ) from None
            if not (math.isfinite(lo) and math.isfinite(hi)):
                raise ValueError(f"randomize[{key!r}] must be finite, got ({lo!r}, {hi!r})")
            if lo > hi:
                raise ValueError(f"randomize[{key!r}] is reversed: low {lo:g} > high {hi:g}")
            if key == "c_true" and kind != "ideal":
                raise ValueError(
                    "randomize['c_true'] needs plant.kind = ideal (a MuJoCo robot's c_true follows from its "
                    "model: draw 'payload' instead)"
                )
            if key == "friction" and kind != "mujoco":
                raise ValueError("randomize['friction'] needs plant.kind = mujoco (the ideal plant has no friction)")
            if key == "friction" and not lo > 0:  # load refuses a friction patch of μ 0 (no grip) alike
                raise ValueError(
                    f"randomize['friction'] must be > 0 (a factor 0 leaves the wheels no grip), got low {lo:g}"
                )
            if key == "position":  # a start beyond the divergence guard ended every episode at its first step
                far = float(np.max(np.abs(np.array(base.formation.initial_poses, float).reshape(-1, 3)[:, :2])))
                far += base.formation.init_jitter + max(abs(lo), abs(hi))
                if far >= base.limits.position:
                    raise ValueError(
                        f"randomize['position'] ({lo:g}, {hi:g}) m can put a start at |x| or |y| = {far:g} m, beyond "
                        f"limits.position = {base.limits.position:g} m (every episode would end at its first step)"
                    )
            for v in (lo, hi):  # each bound as the scenario's checks (load's) see it
                try:
                    if key in SCENARIO_KEYS:
                        checked(_with(base, key, v))
                    elif key == "c_true":
                        checked(_with(base, "plant.c_true", tuple(v * c for c in base.plant.c_true)))
                    elif key == "payload":
                        checked(dataclasses.replace(base, events=_payload_events(base, np.full(n, v), every=True)))
                    elif key == "actuator":
                        rows = _actuator_rows(base, np.full(n, v), t_end)
                        checked(dataclasses.replace(base, faults=dataclasses.replace(base.faults, actuator=rows)))
                except InputError as exc:
                    raise ValueError(f"randomize[{key!r}] bound {v:g} is not accepted: {exc}") from None
            self.ranges[key] = (lo, hi)

    def __bool__(self) -> bool:
        return bool(self.ranges)

    def draw(self, seed: int, n: int, attempt: int = 0) -> dict[str, np.ndarray]:
        """Every key's values for the episode of ``seed`` (its own stream, ``default_rng((seed, 0x5EED,
        attempt))``; ``attempt`` > 0: a redraw after a start whose robots overlapped)."""
        rng = np.random.default_rng((int(seed), 0x5EED, int(attempt)))
        sizes = {"position": (n, 2), "heading": (n,), "c_true": (n, 2), "payload": (n,), "actuator": (n,)}
        return {k: rng.uniform(lo, hi, size=sizes.get(k, ())) for k, (lo, hi) in self.ranges.items()}

    def scenario(self, sc: Scenario, draws: Mapping[str, np.ndarray], poses: np.ndarray) -> Scenario:
        """The episode's scenario: ``sc`` with ``poses`` (n, 3) as its initial poses (no further jitter),
        the drawn scenario keys, payload events and actuator faults."""
        form = dataclasses.replace(
            sc.formation,
            initial_poses=tuple(tuple(float(v) for v in p) for p in poses),
            init_jitter=0.0,
            init_jitter_heading=-1.0,
        )
        sc = dataclasses.replace(sc, formation=form)
        for key in SCENARIO_KEYS:
            if key in draws:
                sc = _with(sc, key, float(draws[key]))
        if "payload" in draws:
            sc = dataclasses.replace(sc, events=_payload_events(sc, draws["payload"]))
        if "actuator" in draws:
            faults = dataclasses.replace(sc.faults, actuator=_actuator_rows(sc, draws["actuator"], self.t_end))
            sc = dataclasses.replace(sc, faults=faults)
        return sc

    @staticmethod
    def start_poses(sc: Scenario, draws: Mapping[str, np.ndarray]) -> np.ndarray:
        """(n, 3) initial poses: the scenario's (with its own seeded jitter) plus the drawn offsets."""
        p = np.array(sc.initial_poses(), dtype=float)
        if "position" in draws:
            p[:, :2] += draws["position"]
        if "heading" in draws:
            p[:, 2] = np.angle(np.exp(1j * (p[:, 2] + draws["heading"])))
        return p


def set_start(plant: Any, poses: np.ndarray, built_poses: np.ndarray, built_qpos0: np.ndarray) -> None:
    """Move a MuJoCo plant's robots to start at ``poses`` (n, 3) without recompiling the scene: each
    base's free joint in ``qpos0`` (what ``mj_resetData`` starts from) is the rigid motion of its
    built value (at ``built_poses``) that carries the built axle midpoint and heading to the new
    ones (a yaw about +z and a shift). ``built_poses``: exactly the built ``qpos0`` again."""
    m = plant.model
    m.qpos0[:] = built_qpos0
    for i in range(plant.n):
        if np.array_equal(poses[i], built_poses[i]):
            continue
        a = int(plant._q7[i, 0])
        d = float(poses[i, 2] - built_poses[i, 2])
        c, s = math.cos(d), math.sin(d)
        x, y = built_qpos0[a] - built_poses[i, 0], built_qpos0[a + 1] - built_poses[i, 1]
        m.qpos0[a] = poses[i, 0] + c * x - s * y
        m.qpos0[a + 1] = poses[i, 1] + s * x + c * y
        qz = np.array([math.cos(d / 2), 0.0, 0.0, math.sin(d / 2)])
        q = np.empty(4)
        import mujoco

        mujoco.mju_mulQuat(q, qz, built_qpos0[a + 3 : a + 7])
        m.qpos0[a + 3 : a + 7] = q / np.linalg.norm(q)
    plant.initial_poses = np.array(poses, dtype=float)


def scale_friction(plant: Any, factor: float, nominal: tuple[np.ndarray, np.ndarray]) -> None:
    """Every sliding friction coefficient of a MuJoCo plant's scene (geoms and explicit contact
    pairs) set to ``factor`` × its nominal value (``nominal``: the built ``geom_friction[:, 0]``,
    ``pair_friction[:, :2]``)."""
    m = plant.model
    m.geom_friction[:, 0] = factor * nominal[0]
    if m.npair:
        m.pair_friction[:, :2] = factor * nominal[1]

"""The small interface every plant implements (design §8: plants behind one interface), and the capabilities a
plant may add to it, each a ``runtime_checkable`` protocol that the loop, the summary, the outcomes and the hardware
verdict test with ``isinstance`` (design §22)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np

#: ``d(t)`` → (n, 2) disturbance accelerations ``[d1 m/s², d2 rad/s²]`` (eq. 34).
DisturbanceFn = Callable[[float], np.ndarray]


class Plant(Protocol):
    """A team of ``n`` differential-drive robots driven by wheel torques."""

    n: int
    control_dt: float  # s, one control period

    def reset(self) -> None:
        """Robots at their initial poses, at rest; time 0."""

    def observe(self) -> tuple[np.ndarray, np.ndarray]:
        """Pose (n,3) ``[x m, y m, θ rad ∈ (−π, π]]`` of the axle midpoint and body-frame
        velocity (n,2) ``[υ m/s, ω rad/s]``."""

    def step(self, tau: np.ndarray, t: float) -> None:
        """Apply wheel torques (n,2) ``[τ_L, τ_R]`` N·m for one control period from time ``t`` (s)."""

    def c_true(self) -> np.ndarray:
        """Ground truth ``[a, b]`` (n, 2) of ``υ̇ = a τ_a + d1``, ``ω̇ = b τ_b + d2``."""

    def set_leader(self, pose: np.ndarray, slots: np.ndarray | None) -> None:
        """Show the virtual leader's pose (3,) and the formation slots (n,2); may ignore."""

    def add_payload(self, i: int, mass_kg: float, inertia_kgm2: float) -> None:
        """Follower ``i`` (0-based) picks up a payload at its axle midpoint."""


# ---------------------------------------------------------------------------------------
# Capabilities: what a plant may offer beyond :class:`Plant`, each a protocol checked with ``isinstance``
# by the loop, the summary, the outcomes and the hardware verdict (design §22), never by the plant's kind. What the
# controller's builder reads (torque limits, footprints, obstacles) is declared where it is read, control/base.py.
# ---------------------------------------------------------------------------------------


@runtime_checkable
class CompiledChunk(Protocol):
    """Runs whole chunks of control periods in machine code with the controller's compiled kernel (design §9)."""

    def compiled_chunk(self, ctx: Any) -> Callable[[int, int, int], tuple[int, int, int]] | None:
        """The chunk ``chunk(k0, k1, j) -> (k, j, status)`` over the loop's shared arrays ``ctx``
        (:class:`~bioform_mj.core.engine.Loop`), or None where it cannot run compiled."""


@runtime_checkable
class Sensing(Protocol):
    """Says what its controllers measure, ``"truth"`` or ``"odometry"`` (encoders and gyro, design §8.3)."""

    sensing: str
    odo: Any  # the dead reckoning's state: ``mpose`` (n, 3), ``mvel`` (n, 2), what the controllers measured

    def measurement(self, pose: np.ndarray, vel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The controllers' pose (n, 3) and velocity (n, 2) for the true ``pose`` and ``vel`` (odometry's)."""

    def odometry_drift(self) -> np.ndarray:
        """Per follower (n, 2) the odometry's position error (m) and heading error (rad) now."""


@runtime_checkable
class RobotModels(Protocol):
    """Robots read from model files (MJCF, URDF): each follower's layout (``import_notes``: the guesses of a
    format import, design §12), the identified parameters (``mass``, ``yaw_inertia``, motors; design §14) and the
    compiled MuJoCo ``model`` and ``data`` of the scene."""

    layouts: Sequence[Any]
    params: Sequence[Any]
    model: Any
    data: Any

    def model_xml(self) -> str:
        """The composed scene as MJCF (as built), for a run folder's ``scene.xml`` (design §12)."""


@runtime_checkable
class LumpedBodies(Protocol):
    """Bodies of lumped mass (kg, (n,) or None) and yaw inertia (kg·m², (n,) or None): the ideal plant."""

    mass: np.ndarray | None
    inertia: np.ndarray | None


@runtime_checkable
class TipSlipWatch(Protocol):
    """Watches each robot's tilt and wheel slip in the loop: the control step each was first found tipped or
    slipping (n,) (-1: never), by the one table of thresholds (``core/thresholds.py``: the slip ratio
    ``SLIP_RATIO`` held for ``SLIP_TIME`` s, the tilt ``TIP_ANGLE_DEG``)."""

    tip_step: np.ndarray
    slip_step: np.ndarray
    #: m/s: the slip ratio's speed floor, and ``{"value", "unit", "source", "top_speeds_mps"}`` saying where it
    #: came from (``core.thresholds.slip_floor_entry``; summary.json's ``slip_floor``, design §21)
    slip_floor: float
    slip_floor_entry: dict[str, Any]


@runtime_checkable
class ContactWatch(Protocol):
    """Watches contacts between robots and with obstacles (design §19)."""

    obstacles: Sequence[Any]

    def contact_watch(self) -> Any:
        """What the watch recorded (:func:`bioform_mj.formation.safety.follower_fields` reads it)."""


@runtime_checkable
class Unmodelled(Protocol):
    """Knows the drags the paper's model leaves out (joint damping, frictionloss) at given speeds."""

    def unmodelled(self, v: float, w: float) -> list[dict]:
        """Per follower what damping and frictionloss cost at ``v`` m/s and ``w`` rad/s."""


@runtime_checkable
class DeliveredTorques(Protocol):
    """Motors whose delivered torque differs from the commanded one (DC motors, design §8.2): the learner is
    fed what was delivered when ``feed_delivered``."""

    feed_delivered: bool

    def feed_delivered_torque(self, tau_body: np.ndarray) -> None:
        """Replace ``tau_body`` (n, 2) ``[τ_a, τ_b]`` N·m in place with what the motors delivered last period."""

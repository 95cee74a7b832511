"""What a controller is to the loop: the :class:`Controller` protocol, and :class:`Comm`.

``sim.simulate(scenario, controller=...)`` runs any object that has these methods. Each
control step the loop calls :meth:`Controller.step` with

* the virtual leader's pose (3,) ``[x, y, θ]`` and velocities (2,) ``[υ_r, ω_r]`` at ``t_k``
  (a distributed controller must read them only for followers with leader access);
* each follower's measured pose (n, 3) and body-frame velocity (n, 2) at ``t_k``;
* ``comm``: None for the paper's perfect network, else a :class:`Comm` (faults);

and holds the returned wheel torques ``[τ_L, τ_R]`` (n, 2, N·m) over the period. After the
step it reads :meth:`Controller.signals` for the log and the summary: any of ``est_pose``
(n,3), ``est_vel``, ``cmd``, ``dcmd``, ``tau_raw``, ``c_hat``, ``z_hat`` (n,2), ``vs``,
``saturated`` (n,), ``tracking_error`` (n,3); missing ones are logged as NaN and the
metrics that need them (e.g. ``cmd`` for the Table I metric) are NaN.

A controller that also has ``kernel`` (a ``(Gains, StackState)`` pair for
:func:`~bioform_mj.control.kernel.control_step`), like
:class:`~bioform_mj.control.stack.ControlStack`, can be run by the plants' compiled loops.
See ``examples/`` for a user-written controller.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np


@dataclass
class Comm:
    """What each follower received this control step, for faulty communication.

    The default (no ``Comm``) is the paper's perfect network: follower ``i`` reads its
    neighbours' current estimates and, if ``a_ir = 1``, the leader's current state.

    edge_w : (m,) weight of each graph edge ``src ← dst`` this step (1 = link up, 0 = down).
    leader_w : (n,) weight of each follower's leader link (multiplies ``a_ir``).
    recv_pose : (m, 3) or None: the pose estimate of ``dst`` as ``src`` last received it
        (delayed or held after packet loss); None = ``dst``'s current estimate.
    recv_vel : (m, 2) or None: the same for the velocity estimates.
    """

    edge_w: np.ndarray
    leader_w: np.ndarray
    recv_pose: np.ndarray | None = None
    recv_vel: np.ndarray | None = None


@runtime_checkable
class Controller(Protocol):
    """A formation controller of ``n`` followers (see the module docstring for the contract)."""

    n: int

    def reset(self, est_pose0: np.ndarray, vel0: np.ndarray) -> None:
        """Start of a run: initial leader estimates ``P_ir(0)`` (n,3) and measured velocities (n,2)."""

    def step(
        self,
        leader_pose: np.ndarray,
        leader_vel: np.ndarray,
        pose: np.ndarray,
        vel: np.ndarray,
        comm: Comm | None = None,
    ) -> np.ndarray:
        """Wheel torques ``[τ_L, τ_R]`` (n, 2, N·m) to hold over the next control period."""

    def signals(self) -> Mapping[str, np.ndarray]:
        """Signals of the last step for the log, by channel name."""

    def set_tau_max(self, tau_max: np.ndarray) -> None:
        """The wheel torque limits (n,) N·m changed (actuator faults); may ignore."""


# ---------------------------------------------------------------------------------------
# What a controller's builder reads of a plant (design §19, §22): each a protocol checked with ``isinstance``. They
# are declared here, where they are read, because this floor knows no plant (design §0); a plant offers them by
# having the attributes.
# ---------------------------------------------------------------------------------------


@runtime_checkable
class TorqueLimited(Protocol):
    """Robots with their own wheel torque limits (the MuJoCo plant: each robot's drive limit)."""

    tau_max: np.ndarray  # (n,) N·m


@runtime_checkable
class Footprints(Protocol):
    """Robots of known size: each one's footprint radius about its axle midpoint (the safety filter's, design §19)."""

    footprint_radius: np.ndarray  # (n,) m


@runtime_checkable
class Obstacles(Protocol):
    """Holds obstacles (:class:`~bioform_mj.formation.obstacles.Obstacle` rows, design §19)."""

    obstacles: Sequence[Any]

"""The paper's stack built from a scenario: :func:`stack_params` resolves its numbers into
:class:`~bioform_mj.control.stack.StackParams` (design §2: "Adding a gain"), and :func:`paper_stack` builds the
:class:`~bioform_mj.control.stack.ControlStack` for one of the paper's four methods, the factory that the
controller registry holds for them (:mod:`bioform_mj.control.registry`, design §22).

The scenario is read by attribute, the plant by the protocols of :mod:`bioform_mj.control.base` (this floor knows
neither package, design §0). The opt-in gain sizing (design §14.4) reads robot check's identification, an assessment
a floor above: :mod:`bioform_mj.assess.learner_sizing` registers it (:func:`register_sizing`) when imported, as the
run package does.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bioform_mj.control.base import Footprints, Obstacles, TorqueLimited
from bioform_mj.control.stack import ControlStack, StackParams, parse_method
from bioform_mj.control.tuning import PAPER_C


def paper_stack(sc: Any, plant: Any) -> ControlStack:
    """The paper's control stack for ``sc.method`` (one of :data:`~bioform_mj.control.stack.METHODS`).

    Parameters
    ----------
    sc : Scenario
        The run's scenario (checked); its ``method`` picks the kinematic law and whether the learner runs.
    plant : Plant
        The plant it will drive: its ``c_true()`` (n, 2) sets ``ĉ(0)``, its ``tau_max`` (n,) N·m, if it has
        one, the torque limits, and its footprints and obstacles the safety filter (design §19).
    """
    tau_max = plant.tau_max if isinstance(plant, TorqueLimited) else None
    return ControlStack(sc.build_graph(), stack_params(sc, plant.c_true(), tau_max, plant))


#: the opt-in gain sizing (design §14.4): ``sizer(sc, plant, c_true) -> dict | None``, registered by
#: :mod:`bioform_mj.assess.learner_sizing` on import (:func:`register_sizing`) instead of this module importing upwards
_SIZING: list[Any] = []


def register_sizing(sizer: Any) -> None:
    """Set the sizer of the opt-in ``torque.resistance_margin`` / ``learner.kd_deadband`` (design §14.4).

    Parameters
    ----------
    sizer
        ``sizer(sc, plant, c_true) -> dict | None``: ``c_gain`` (2,) and ``kd`` (2,) for scenario ``sc`` on ``plant``
        whose followers have ``c_true`` (n, 2), with the resistance they were sized to; None where neither is asked.
    """
    _SIZING[:] = [sizer]


def stack_params(sc: Any, c_true: np.ndarray, tau_max: np.ndarray | None = None, plant: Any = None) -> StackParams:
    """Resolve the scenario's numbers into the control stack's per-follower arrays.

    Parameters
    ----------
    sc : Scenario
        The run's scenario; its ``method`` must be one of the paper's four.
    c_true : ndarray
        The plant's ``c = (a, b)``, (2,) or (n, 2), m/(s²·N·m) and rad/(s²·N·m): ``ĉ(0) = c_hat0_scale ⊙ c_true``.
    tau_max : ndarray or None
        Wheel torque limits (n,) N·m (None: ``torque.tau_max`` for every follower).
    plant : Plant or None
        If given, tells the safety filter each robot's footprint radius (m) and the obstacles (design §19).
    """
    law, learning = parse_method(sc.method)
    n = sc.n
    c_hat0 = np.asarray(sc.learner.c_hat0_scale) * c_true
    lo, hi = sc.learner.c_bounds
    sized = None
    if sc.torque.resistance_margin > 0 or sc.learner.kd_deadband:
        # opt-in (design §14.4): c and kd sized to the resistance robot check identifies; an assessment of the
        # robot, a floor above the controller, registered by it (register_sizing)
        if not _SIZING:
            raise ValueError(
                "torque.resistance_margin / learner.kd_deadband are sized to robot check's identification: import "
                "bioform_mj.run (or bioform_mj.assess.learner_sizing) first (bioform_mj.load and bioform do)"
            )
        sized = _SIZING[-1](sc, plant, np.asarray(c_true, dtype=float))
    band = sc.learner.projection_band  # opt-in (design §14.4): a band around the prior c_true, not c_bounds × ĉ(0)
    c_lo, c_hi = (band[0] * c_true, band[1] * c_true) if band else (lo * c_hat0, hi * c_hat0)
    return StackParams(
        offsets=np.array(sc.formation.offsets, dtype=float),
        kp=np.array(sc.estimator.kp),
        ka=np.array(sc.estimator.ka),
        kb=np.array(sc.estimator.kb),
        est_phi=np.array(sc.estimator.phi),
        k1=sc.kinematic.k1,
        k2=sc.kinematic.k2,
        k3=sc.kinematic.k3,
        A=sc.kinematic.A,
        B=sc.kinematic.B,
        D=sc.kinematic.D,
        law=law,
        learning=learning,
        c_gain=np.array(sized["c_gain"] if sized else sc.torque.c),
        torque_phi=sc.torque.phi,
        tau_max=np.full(n, sc.torque.tau_max) if tau_max is None else np.asarray(tau_max, dtype=float),
        steer_priority=sc.torque.saturation == "steer-priority",
        deriv_wn=sc.torque.deriv_wn,
        derivative=sc.torque.derivative,
        k4=_learner_k4(sc, c_hat0),
        k5=np.array(sc.learner.k5),
        kd=np.array(sized["kd"] if sized else sc.learner.kd),
        kk=np.array(sc.learner.drag_gain) if sc.learner.drag else np.zeros(2),
        k_max=float(sc.learner.drag_max) if sc.learner.drag else 0.0,
        c_hat0=c_hat0,
        c_min=c_lo,
        c_max=c_hi,
        dt=sc.sim.control_dt,
        leader_frame=sc.formation.frame == "leader",
        **_cbf_params(sc, plant),
        sizing=sized,
    )


def _cbf_params(sc: Any, plant: Any) -> dict[str, Any]:
    """The safety filter's part of :class:`StackParams` (design §19; empty when it is off)."""
    sf = sc.safety
    if sf.filter != "cbf":
        return {}
    from bioform_mj.formation.obstacles import to_rows

    radius = plant.footprint_radius if isinstance(plant, Footprints) else None
    obstacles = (plant.obstacles if isinstance(plant, Obstacles) else None) or []
    return dict(
        cbf=True,
        cbf_par=(sf.lookahead, sf.gain, sf.distance, sf.range, sf.pass_right),
        cbf_radius=None if radius is None else np.asarray(radius, dtype=float),
        cbf_obstacles=to_rows(obstacles) if obstacles else None,
    )


def _learner_k4(sc: Any, c_hat0: np.ndarray) -> np.ndarray:
    """``k4`` (2,) as configured, or (n, 2) per robot for ``gain_scaling = "c_hat0"``:
    ``k4 ⊙ (ĉ_i(0) / ĉ_paper(0))²`` with ``ĉ_paper(0) = c_hat0_scale ⊙ PAPER_C``, the initial
    estimate the paper's robot gets, so that robot keeps the paper's gains exactly."""
    k4 = np.array(sc.learner.k4, dtype=float)
    if sc.learner.gain_scaling == "c_hat0":
        ref = np.asarray(sc.learner.c_hat0_scale, dtype=float) * np.asarray(PAPER_C)
        return k4 * (np.asarray(c_hat0, dtype=float) / ref) ** 2
    return k4

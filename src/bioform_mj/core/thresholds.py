"""The one table of outcome thresholds (design §0, §9, §14): what makes a follower ``tipped``, ``slipping``,
``spinning``, ``lost``, ``c_hat_at_bound`` or ``c_hat_off``. The MuJoCo plant's in-loop watch
(``plants/mujoco``), a run's outcomes and summary (``assess/outcomes.py``), the fault table
(``run/faults.py: outcome``) and the batch engine (``batch/device.py``, ``batch/runner.py``: its device
constants and per-world columns are derived from these) all read them here; none types a number again."""

from __future__ import annotations

__all__ = [
    "TIP_ANGLE_DEG",
    "SLIP_RATIO",
    "SLIP_TIME",
    "SLIP_V_FLOOR",
    "SPIN_RAD_S",
    "LOST_FRACTION",
    "LOST_AFTER_S",
    "LOST_M",
    "C_HAT_BOUND_BAND",
    "C_HAT_OFF",
]

#: a chassis tilted further than this from upright (deg) has tipped over (outcome ``tipped``; the fault
#: table's ``tipped_over``)
TIP_ANGLE_DEG = 30.0
#: wheel slip ratio |r φ̇ − v_contact| / max(|r φ̇|, |v_contact|, SLIP_V_FLOOR) beyond which a wheel slips;
#: held for SLIP_TIME s: outcome ``slipping``; SLIP_V_FLOOR m/s keeps the ratio finite near standstill
SLIP_RATIO = 0.2
SLIP_TIME = 0.5
SLIP_V_FLOOR = 0.05
#: rad/s: |ω| beyond this over the last second of a run → ``spinning`` (the fault table: at its end)
SPIN_RAD_S = 6.0
#: final formation error beyond this fraction of the formation's extent → ``lost`` ...
LOST_FRACTION = 0.1
#: s: ... once the run has had this long to converge (or if the error grew over the run)
LOST_AFTER_S = 10.0
#: the ``lost`` threshold of the paper's formation (extent 10 m), kept for reference, m
LOST_M = 1.0
#: a learned parameter within this fraction of its projection bound counts as at the bound
C_HAT_BOUND_BAND = 0.01
#: a learned ĉ farther than this (relative, either component) from c_true at the end: ``c_hat_off``
C_HAT_OFF = 0.25

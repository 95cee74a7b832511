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
    "SLIP_V_FLOOR_OF_TOP",
    "slip_v_floor",
    "slip_floor_entry",
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
#: ... and at most this fraction of the slowest robot's top speed (issue 27: DiffBot's top speed 0.015 m/s is below
#: 0.05 m/s, where every ratio was taken against the floor and no slip could be seen; the paper robot, whose top
#: speed is not known, and any robot of 1 m/s or more keep 0.05 m/s: their outcomes are unchanged, bit for bit)
SLIP_V_FLOOR_OF_TOP = 0.05
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


def slip_v_floor(top_speeds: list[float | None]) -> float:
    """The slip ratio's speed floor (m/s) for robots of top speeds ``top_speeds`` (m/s at the tyre; None where not
    known): ``min(SLIP_V_FLOOR, SLIP_V_FLOOR_OF_TOP × the least known top speed)`` (design §21)."""
    known = [float(v) for v in top_speeds if v is not None and v > 0]
    return min([SLIP_V_FLOOR, *(SLIP_V_FLOOR_OF_TOP * v for v in known)])


def slip_floor_entry(top_speeds: list[float | None]) -> dict[str, object]:
    """summary.json's ``slip_floor``: the slip ratio's speed floor :func:`slip_v_floor` of robots of top speeds
    ``top_speeds`` (m/s; None where not known) with its unit, where it came from and the distinct known top speeds
    (``top_speeds_mps``, m/s) (design §21)."""
    known = sorted({float(v) for v in top_speeds if v is not None and v > 0})  # the distinct top speeds
    value = slip_v_floor(top_speeds)
    if not known:
        source = f"SLIP_V_FLOOR {SLIP_V_FLOOR:g} m/s: no robot's top speed is known"
    elif value < SLIP_V_FLOOR:
        source = f"{SLIP_V_FLOOR_OF_TOP:g} x the least top speed of the plant's robots, {known[0]:.6g} m/s"
    else:
        source = (
            f"SLIP_V_FLOOR {SLIP_V_FLOOR:g} m/s, not above {SLIP_V_FLOOR_OF_TOP:g} x the least top speed of the "
            f"plant's robots, {known[0]:.6g} m/s"
        )
    return {
        "value": value,
        "unit": "m/s",
        "source": source + " (core.thresholds.slip_v_floor, design §21)",
        "top_speeds_mps": known,
    }

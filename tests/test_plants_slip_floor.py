"""The slip ratio's speed floor scales with the robot (issue 27 gap 4, design §21).

``SLIP_V_FLOOR`` (0.05 m/s) was above DiffBot's top speed (0.015 m/s): every slip ratio of such a robot was taken
against the floor and no slip could be seen. The floor is now ``min(0.05, 0.05 × the least top speed)``; a robot
whose top speed is not known (the paper robot) keeps 0.05 m/s exactly. Ground truth by hand: a robot standing still
with one wheel spun to ``r φ̇ = 8 mm/s`` slips with ratio ``|r φ̇ − 0| / max(r φ̇, 0, floor)`` — 1 at a floor below
8 mm/s, 0.16 (under SLIP_RATIO 0.2: not seen) at 0.05 m/s.
"""

from __future__ import annotations

import numpy as np
import pytest

from bioform_mj.core.thresholds import SLIP_RATIO, SLIP_V_FLOOR, slip_v_floor
from bioform_mj.plants.mujoco.plant import MujocoPlant
from bioform_mj.robots.entries import resolve_robot
from bioform_mj.robots.refs import RobotRef


def _plant(**over) -> MujocoPlant:
    ref = resolve_robot(RobotRef("paper", **over))
    return MujocoPlant([ref], np.zeros((1, 3)), 0.001, 0.001, None, slots=False)


def _spun(plant: MujocoPlant, rim_speed: float) -> np.ndarray:
    """The slip ratios with the robot at rest and its right wheel turning at ``rim_speed`` m/s at the tyre."""
    plant.data.qvel[:] = 0.0
    dof, sign, r = plant._wheel_dof[0, 1], plant._wheel_sign[0, 1], plant._wheel_radius[0]
    plant.data.qvel[dof] = sign * rim_speed / r
    return plant.wheel_slip()[0]


def test_the_floor_is_a_share_of_the_slowest_top_speed_and_the_paper_robot_keeps_its_own():
    assert slip_v_floor([None]) == SLIP_V_FLOOR == 0.05
    assert slip_v_floor([2.0, None]) == SLIP_V_FLOOR  # 1 m/s or faster: unchanged
    assert slip_v_floor([0.22, 0.015]) == pytest.approx(0.05 * 0.015)  # DiffBot's 0.75 mm/s in a mixed team
    assert _plant().slip_floor == SLIP_V_FLOOR  # the paper robot: no top speed known, the floor of before


def test_a_scaled_down_robot_sees_a_slip_the_fixed_floor_hid():
    slow = _plant(top_speed=0.02)  # the paper robot said to drive at 2 cm/s at most: floor 1 mm/s
    assert slow.slip_floor == pytest.approx(0.001)
    assert _spun(slow, 0.008)[1] == pytest.approx(1.0, abs=1e-9) and _spun(slow, 0.008)[0] == 0.0
    paper = _plant()
    hidden = _spun(paper, 0.008)[1]
    assert hidden == pytest.approx(0.008 / 0.05, abs=1e-9) and hidden < SLIP_RATIO


def test_the_summary_says_the_floor_with_its_unit_and_source(monkeypatch):
    """summary.json's ``slip_floor``: the value the watch used (m/s) and what set it — 0.05 × the 0.02 m/s top speed
    given in the mapping (1 mm/s), or the fixed 0.05 m/s for the paper robot, whose top speed is not known."""
    from bioform_mj.core.thresholds import slip_floor_entry
    from bioform_mj.run.simulate import simulate
    from bioform_mj.scenario.loader import load

    monkeypatch.setenv("BIOFORM_NO_ROBOT_CHECK", "1")  # the watch's floor, not the robot check, is tested here
    ov = ["plant.kind=mujoco", "sim.duration=0.02", 'plant.robots=[{model="paper", top_speed=0.02}]']
    with pytest.warns(Warning):
        got = simulate(load("paper", overrides=ov), engine="stepwise").summary["slip_floor"]
    assert got["value"] == pytest.approx(0.05 * 0.02) and got["unit"] == "m/s"
    assert "0.05 x the least top speed" in got["source"] and "0.02 m/s" in got["source"]
    assert got["top_speeds_mps"] == [0.02]
    paper = slip_floor_entry([None])
    assert paper["value"] == SLIP_V_FLOOR and "no robot's top speed is known" in paper["source"]
    fast = slip_floor_entry([2.0, 1.5])
    assert fast["value"] == SLIP_V_FLOOR and "1.5 m/s" in fast["source"] and "not above" in fast["source"]

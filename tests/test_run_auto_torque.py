"""``formation.time_scale = "auto"`` counts the peak wheel torque (issue 27 refinement, design §21).

The wheel's own damping ``c`` and frictionloss ``f`` take their share of ``τ_max`` before the motion does. A robot
whose σ is set by its top speed (the tb3: XL430 no-load 0.197 m/s, σ 5.2) but whose wheels are damped so that at that
σ the damping alone, ``c · v_wheel / r`` with the peak wheel ground speed ``v_wheel = 0.8 v_top``, is above
``0.8 τ_max`` must get a larger σ, set by the wheel torque. A frictionloss at least ``0.8 τ_max`` does not fall
with σ: it is not counted, and the note says so.
"""

from __future__ import annotations

from pathlib import Path

import pytest

import bioform_mj.run  # noqa: F401 - registers the "auto" resolver
from bioform_mj.run.auto_scale import TORQUE_MARGIN, _torque_need
from bioform_mj.scenario.loader import load

TB3 = Path(__file__).resolve().parents[1] / "models" / "tb3_robot.xml"
TAU = 0.05  # N·m, the tb3 preset's torque limit
R = 0.033  # m, the tb3's wheel radius (models/tb3_robot.xml)


def test_the_torque_candidate_by_hand():
    """``(τ − f) / (0.8 τ_max − f)``: 1 exactly at the margin; None where f alone takes it."""
    p = type("P", (), {"wheel_frictionloss": 0.5})()
    pk = {"wheel_torque_nm": 3.0, "wheel_inertial_nm": 2.0, "wheel_resistance_nm": 1.0}
    need, why = _torque_need(pk, p, {"torque_nm": 5.0})
    assert need == pytest.approx((3.0 - 0.5) / (TORQUE_MARGIN * 5.0 - 0.5)) and "wheel torque 3 N·m" in why
    assert _torque_need({**pk, "wheel_torque_nm": 0.5 + (4.0 - 0.5)}, p, {"torque_nm": 5.0})[0] == pytest.approx(1.0)
    p.wheel_frictionloss = TORQUE_MARGIN * 5.0
    assert _torque_need(pk, p, {"torque_nm": 5.0}) is None


def _tb3(tmp_path: Path, damping: float, frictionloss: float) -> list[str]:
    text = TB3.read_text().replace(
        'damping="0" armature="0" frictionloss="0"', f'damping="{damping}" armature="0" frictionloss="{frictionloss}"'
    )
    assert f'damping="{damping}"' in text
    path = tmp_path / f"tb3_{damping}_{frictionloss}.xml"
    path.write_text(text)
    return [
        'formation.scale="auto"',
        'formation.time_scale="auto"',
        f'plant.robots=[{{model="{path}", tau_max={TAU}, motor="dc", driver="current"}}]',
    ]


@pytest.mark.slow  # ≈ 50 s at load 7 with an empty demand cache (the σ searches' twins), ≈ 8 s cached
def test_damped_wheels_slow_the_scenario_down_and_a_frictionloss_beyond_the_margin_is_said(tmp_path):
    import bioform_mj.run.simulate  # noqa: F401  (registers the loop the twin runs on)
    from bioform_mj.robots.entries import resolve_robot
    from bioform_mj.run.auto_scale import robot_limits
    from bioform_mj.run.demand import peaks

    free = load("tb3", _tb3(tmp_path, 0, 0))
    assert "wheel speed" in free.formation.scale_note and free.formation.time_scale > 1
    c = 0.01  # N·m·s/rad: at the free σ the damping alone needs c · 0.8 v_top / r = 0.048 N·m > 0.8 τ_max = 0.04
    p, lim = robot_limits(resolve_robot(free.plant.robots[0]))
    assert c * 0.8 * lim["top_speed_mps"] / R > TORQUE_MARGIN * TAU
    damped = load("tb3", _tb3(tmp_path, c, 0))
    assert damped.formation.time_scale > 1.1 * free.formation.time_scale
    assert "set by the 'tb3_0.01_0.xml' wheel torque" in damped.formation.scale_note
    pd, _ = robot_limits(resolve_robot(damped.plant.robots[0]))
    assert pd.wheel_damping == pytest.approx(c)
    pk = peaks(damped, (pd.a_eff, pd.b_eff), pd.half_track)
    # independently of the wheel model: the damping at the twin's peak wheel ground speed fits the margin now
    assert c * pk["wheel_speed_mps"] / R <= TORQUE_MARGIN * TAU
    stuck = load("tb3", _tb3(tmp_path, 0, 0.9 * TAU))  # f = 0.045 N·m ≥ 0.04: no σ makes room
    assert stuck.formation.time_scale == free.formation.time_scale
    assert "not counted in σ: its wheels' frictionloss 0.045 N·m" in stuck.formation.scale_note

"""table1 shows the paper's numbers only beside the paper's experiment."""

from __future__ import annotations

from bioform_mj.jobs.table1 import PAPER_TABLE1, markdown, paper_differences
from bioform_mj.scenario.loader import load


def _table(sc, j=1.0):
    from bioform_mj.jobs.table1 import paper_differences

    f = {"total_velocity_error": j, "final_formation_error_m": 0.01, "max_abs_v_cmd": 1.0, "saturation_fraction": 0.0}
    summ = {"followers": [dict(f, id=i + 1, outcome="ok") for i in range(3)], "diverged": None}
    differs = paper_differences(sc)
    return {
        "plant": sc.plant.kind,
        "scenario": sc.name,
        "paper_comparable": not differs,
        "differs_from_paper": differs,
        "methods": {m: summ for m in PAPER_TABLE1},
        "ordering_holds": True,
    }


def test_the_paper_scenario_and_its_unstated_conditions_are_comparable():
    assert paper_differences(load("paper")) == []
    assert paper_differences(load("paper", plant="mujoco")) == []
    unstated = ["torque.tau_max=200", "torque.derivative=difference", "learner.c_hat0_scale=[0.27,0.27]"]
    unstated += ["estimator.ka=[1,1]", "estimator.kb=[25,25]", "formation.initial_poses=[[0,0,0],[-1,-3,0],[-1,3,0]]"]
    assert paper_differences(load("paper", unstated)) == []
    md = markdown(_table(load("paper")))
    assert "paper's value in brackets" in md and "| 1 | 1.00 (20.6) | 1.00 (5.3) | 1.00 (8.9) | 1.00 (1.9) |" in md


def test_another_experiment_is_said_to_be_not_comparable():
    assert paper_differences(load("paper", ["leader.kind=circle"])) == ["leader.kind"]
    tb3 = paper_differences(load("tb3"))  # the paper's experiment at another size, on another robot
    assert {"formation.scale", "formation.offsets", "leader.speed", "plant.robots"} <= set(tb3)
    assert "faults" in paper_differences(load("fault_delay")) and "events" in paper_differences(load("payload"))
    md = markdown(_table(load("paper", ["leader.kind=figure8", "sim.duration=30"])))
    assert "not comparable" in md and "leader.kind, sim.duration" in md
    assert "(20.6)" not in md and "(1.9)" not in md and "| 1 | 1.00 | 1.00 | 1.00 | 1.00 |" in md

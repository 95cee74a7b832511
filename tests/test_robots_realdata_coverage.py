"""Do `bioform robot fit`'s 95 % intervals hold the truth as often as they say (issue 29; design §8.4)?

Recordings of the Kobuki URDF with a payload, wheel damping and dry friction (the truth), by the test recorder
(``tests/realdata_recorder.py``: a plain MuJoCo loop through MuJoCo's own URDF parser and ``rosbags``' writer;
none of the fit's code), 60 s each, three torque programs and sensor-noise draws. Measured on these three
(``scripts/fit_coverage.py --robots kobuki --programs 11-13``): with the plain cluster-robust sandwich (the
fit's interval before) 3 of the 18 intervals missed the truth and the RMS of (fitted − truth)/half-width was
0.72; with the leave-one-chunk-out jackknife 1 of 18 and 0.53 (0.51 for an exact interval of a normal error).
A parameter is identified where its interval is narrower than 30 % of its value (design §8.4): 17 of the 18 are;
program 13's left damping (±0.00024 N·m·s/rad, 30 % of the 0.0008 truth) is not, for its width alone (the clause
"or narrower than 5 % of the search range" that called it identified is gone).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent


@pytest.mark.slow  # three 60 s recordings made and fitted: ~1-2 min of CPU
def test_the_intervals_hold_the_truth_of_unseen_kobuki_recordings(tmp_path):
    pytest.importorskip("rosbags")
    pytest.importorskip("tabulate")
    sys.path.insert(0, str(HERE))
    import realdata_recorder as rr
    from bioform_mj.robots.realdata.fit import fit
    from bioform_mj.robots.realdata.recording import read_recording
    from bioform_mj.robots.realdata.simmodel import other_joints, sim_spec
    from bioform_mj.robots.refs import RobotRef

    urdf, truth = rr.KOBUKI_URDF, rr.KOBUKI_TRUTH
    ref = RobotRef(
        model=str(urdf),
        base="base_footprint",
        left_wheel="wheel_left_joint",
        right_wheel="wheel_right_joint",
        tau_max=1.0,
    )
    # the URDF's base_link: 2.4 kg, izz 0.03675 kg·m²; the payload adds 0.6 kg and 0.01 kg·m²
    want = {
        "mass": 3.0,
        "yaw_inertia": 0.04675,
        "damping_L": 0.0008,
        "damping_R": 0.001,
        "frictionloss_L": 0.008,
        "frictionloss_R": 0.006,
    }
    model = rr.true_model(urdf, truth)
    z, rel, ident = [], [], 0
    for program in (11, 12, 13):
        sim = rr.simulate(model, truth, 60.0, rr.KOBUKI_TAU, program)
        bag = tmp_path / f"kobuki{program}"
        rr.write_bag(bag, sim, truth, seed=program + 100)
        robot = sim_spec(ref)
        res, _ = fit(robot, read_recording(bag, truth.joints, None, other_joints(robot)), time_budget_s=600)
        for p in res.parameters:
            ident += p["status"] == "identified"
            if p["status"] != "identified":  # only for its width, and not far over the 30 % of its value
                assert p["why"].endswith("is wide"), (program, p["name"], p["why"])
                assert p["ci95_halfwidth"] <= 0.4 * want[p["name"]], (program, p["name"], p["why"])
            err = abs(p["fitted"] - want[p["name"]])
            z.append(err / p["ci95_halfwidth"])
            rel.append(p["ci95_halfwidth"] / want[p["name"]])
    z = np.array(z)
    assert z.size == 18 and ident >= 16, ident  # 17 measured
    assert np.sum(z > 1) <= 2, np.round(z, 2)  # 18 intervals at 95 %: 0.9 misses expected; 1 measured
    assert np.sqrt(np.mean(z**2)) <= 0.65, np.round(z, 2)  # 0.53 measured; 0.72 with the sandwich
    assert np.median(rel) <= 0.12  # honest, not useless: the median half-width 8.6 % of the value

"""``bioform calibrate table1`` (issue 14): a tiny calibration's report is complete, its best fit is
no worse than the scenario's own conditions, and bad input exits 2 with one error line."""

from __future__ import annotations

import json

import pytest

pytest.importorskip("scipy")

from bioform_mj.cli.main import main
from bioform_mj.jobs import calibrate as cal
from bioform_mj.jobs.table1 import PAPER_TABLE1
from bioform_mj.scenario.loader import load


def test_conditions_round_trip_and_the_scenario_is_inside_the_search_space():
    c = cal.scenario_conditions(load("paper"))
    assert c == {
        "initial_poses": [[0.0, 0.0, 0.0], [-1.0, -4.0, 0.0], [-1.0, 4.0, 0.0]],
        "c_hat0_scale": 0.5,
        "derivative": "filter",
        "deriv_wn": 50.0,
        "tau_max": 20.0,
        "saturation": "steer-priority",
        "estimator_gains": "eq13",
    }
    back = cal.to_conditions(cal.to_vector(c), 3)
    assert back == c
    for v, (lo, hi) in zip(cal.to_vector(c), cal._bounds([p for p in c["initial_poses"]])):
        assert lo <= v <= hi
    sc = cal.build_scenario("paper", "ideal", dict(c, estimator_gains="eq15", derivative="analytic"))
    assert sc.estimator.ka == (1.0, 1.0) and sc.estimator.kb == (25.0, 25.0) and sc.torque.derivative == "analytic"


def test_score_is_zero_on_the_paper_numbers():
    per = {m: list(v) for m, v in PAPER_TABLE1.items()}
    s = cal.score(per, 9.0, False, False)
    assert s["objective"] == 0.0 and s["rms_log_residual"] == 0.0
    assert cal.score(per, 4.0, False, False)["peak_log_residual"] == pytest.approx(-0.6931, abs=1e-4)
    assert cal.score(per, 9.0, True, False)["objective"] == cal.LOST_PENALTY


def test_tiny_calibration_writes_a_complete_report_no_worse_than_the_default(tmp_path, capsys):
    out = tmp_path / "cal"
    assert main(["calibrate", "table1", "--budget", "5", "--out", str(out), "--quiet"]) == 0
    r = json.loads((out / "calibration.json").read_text())
    md = (out / "calibration.md").read_text()
    assert {"best", "table", "rms_log_residual", "sensitivity", "default", "objective", "evaluations"} <= set(r)
    assert set(r["best"]) == {
        "initial_poses",
        "c_hat0_scale",
        "derivative",
        "deriv_wn",
        "tau_max",
        "saturation",
        "estimator_gains",
    }
    cells = [row for row in r["table"] if row["follower"] != "max"]
    assert len(cells) == 12 and all(row["paper"] == PAPER_TABLE1[row["method"]][row["follower"] - 1] for row in cells)
    assert all(row["ours"] > 0 for row in cells)
    assert r["evaluations"]["search"] == 5
    assert r["objective"] <= r["default"]["objective"]
    assert {"initial_poses", "c_hat0_scale", "derivative", "tau_max", "saturation", "estimator_gains"} <= set(
        r["sensitivity"]
    )
    for e in r["sensitivity"].values():
        assert e["alternatives"] and "max_objective_change" in e
    assert "Sensitivity" in md and "Best conditions" in md


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["calibrate", "table9"], "unknown calibration target"),
        (["calibrate", "table1", "--budget", "0"], "--budget"),
        (["calibrate", "table1", "--budget", "-3"], "--budget"),
        (["calibrate", "table1", "--plant", "mars"], "--plant"),
    ],
)
def test_bad_calibration_input_exits_2_with_one_error_line(tmp_path, capsys, argv, needle):
    out = tmp_path / "c"
    assert main(argv + ["--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and needle in err[0]
    assert not out.exists()

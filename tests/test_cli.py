"""The ``bioform`` command: outputs, schema, exit codes (design §10)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from bioform_mj.cli.main import main
from bioform_mj.scenario.config import Scenario
from bioform_mj.scenario.loader import load

SUMMARY_KEYS = {
    "id",
    "total_velocity_error",
    "final_formation_error_m",
    "rms_formation_error_m",
    "final_estimation_error_m",
    "max_abs_v_cmd",
    "peak_abs_torque",
    "saturation_fraction",
    "c_hat",
    "c_true",
}


def test_paper_toml_equals_dataclass_defaults():
    assert load("paper") == Scenario()


def test_run_writes_summary_and_log(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(
        [
            "run",
            "paper",
            "--plant",
            "ideal",
            "--method",
            "bioinspired",
            "--duration",
            "2",
            "--seed",
            "3",
            "--set",
            "kinematic.k1=2.5",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    s = json.loads((out / "summary.json").read_text())
    assert {"scenario", "plant", "method", "sim_time_s", "wall_time_s", "config", "followers"} <= set(s)
    assert s["plant"] == "ideal" and s["method"] == "bioinspired" and s["seed"] == 3
    assert s["sim_time_s"] == pytest.approx(2.0)
    assert s["config"]["kinematic"]["k1"] == 2.5
    assert s["versions"]["bioform_mj"] and s["versions"]["mujoco"]
    assert len(s["followers"]) == 3 and all(SUMMARY_KEYS <= set(f) for f in s["followers"])
    with np.load(out / "log.npz") as log:
        assert log["pose"].shape == (200, 3, 3)
        assert np.all(np.isfinite(log["pose"]))
    assert not list(out.glob(".*tmp"))  # no temporary files left behind
    assert "outputs in" in capsys.readouterr().out


def test_table1_outputs(table1_ideal):
    out, table = table1_ideal
    assert table["plant"] == "ideal"
    assert set(table["methods"]) == {"backstepping", "bioinspired", "backstepping-learning", "bioinspired-learning"}
    md = (out / "table1.md").read_text()
    assert "(1.9)" in md and "bioinspired-learning" in md  # paper's number beside ours
    assert "holds" in md


def test_presets_lists_paper(capsys):
    assert main(["presets"]) == 0
    assert "paper" in capsys.readouterr().out.split()


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["run", "nosuchpreset"], "unknown preset 'nosuchpreset'"),
        (["run", "--method", "pid"], "unknown method 'pid' (expected one of: backstepping,"),
        (["run", "--plant", "gazebo"], "unknown plant 'gazebo' (expected one of: ideal, mujoco"),
        (["run", "--set", "kinematic.k1=-1"], "kinematic.k1"),
        (["run", "--set", "kinematic.k9=1"], "kinematic.k9"),
        (["run", "--set", "graph.edges=[[1,2]]"], "follower(s) 3 cannot reach the leader"),
        (["run", "--set", "graph.leader_access=[]"], "no follower has leader access"),
        (["run", "--set", "sim.duration=0"], "sim.duration"),
        (["run", "--set", "sim.physics_dt=0.0007"], "sim.physics_dt"),
        (["run", "--set", "torque.c=[3, nan]"], "torque.c"),
        (["run", "--set", "formation.offsets=[[3,0],[3,0],[4,-5]]"], "same formation slot"),
        (["run", "missing.toml"], "missing.toml"),
        (["run", "--set", "nokey"], "KEY=VALUE"),
        (["run", "--duration", "-1"], "sim.duration"),
    ],
)
def test_bad_input_exit_2_one_line(argv, needle, tmp_path, capsys):
    out = tmp_path / "never"
    code = main(argv + ["--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and needle in lines[0], err
    assert not out.exists()


def test_bad_toml_file(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[sim\nduration = 1")
    assert main(["run", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "not valid TOML" in capsys.readouterr().err


def test_unwritable_output_dir(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["run", "--duration", "0.1", "--out", str(blocker / "sub")]) == 2
    assert "output directory" in capsys.readouterr().err


def test_divergence_exit_3_keeps_log(tmp_path, capsys):
    out = tmp_path / "div"
    code = main(["run", "--set", "limits.speed=0.5", "--duration", "3", "--out", str(out), "--quiet"])
    assert code == 3
    err = capsys.readouterr().err
    assert "diverged" in err and "follower" in err and "Traceback" not in err
    s = json.loads((out / "summary.json").read_text())
    assert s["diverged"]["time_s"] < 3
    assert (out / "log.npz").exists()


def test_console_script_entry_point(tmp_path):
    """The installed ``bioform`` script (through ``python -m``) gives the same exit code and one line."""
    r = subprocess.run(
        [sys.executable, "-m", "bioform_mj.cli", "run", "--set", "kinematic.k2=0"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and "kinematic.k2" in r.stderr and "Traceback" not in r.stderr


def test_run_engines_give_identical_logs_on_the_ideal_plant(tmp_path):
    """`--engine stepwise` and `--engine compiled`: the same compiled equations, the same bits."""
    logs = {}
    for eng in ("stepwise", "compiled"):
        out = tmp_path / eng
        assert main(["run", "paper", "--duration", "1", "--engine", eng, "--quiet", "--out", str(out)]) == 0
        with np.load(out / "log.npz") as z:
            logs[eng] = {k: z[k] for k in z.files}
        logs[eng]["_tve"] = [
            f["total_velocity_error"] for f in json.loads((out / "summary.json").read_text())["followers"]
        ]
    for k in ("pose", "vel", "est_pose", "cmd", "tau", "c_hat", "_tve"):
        assert np.array_equal(logs["stepwise"][k], logs["compiled"][k]), k

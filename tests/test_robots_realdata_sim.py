"""Sim and real, the loop closed (issue 29): this project's own bags read back by ``robot fit`` without topic
flags, what a bag's effort is (the torque on the joint, or the command to a ``<dcmotor>`` drive), caster
friction found and fitted, and confidence intervals that hold the truth.

The recordings of a "real" robot come from ``tests/realdata_recorder.py`` (no project code); the round trips
of the project's own bags run ``bioform run --rosbag``. Fast tests read recordings only; the fits are
``slow``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")

sys.path.insert(0, str(Path(__file__).parent))
import realdata_recorder as rr  # noqa: E402
from bioform_mj.cli import main as cli  # noqa: E402

TRUTH = rr.Truth(payload_kg=0.3, payload_yaw_kgm2=0.001, damping=(0.002, 0.0025), frictionloss=(0.004, 0.003))
#: the tb3 preset's run without its disturbance forces (no robot model holds them)
CALM = ["--set", "disturbance.bias=[0,0]", "--set", "disturbance.amp=[0,0]"]


def test_a_single_robot_namespace_is_found_and_said(tmp_path):
    from bioform_mj.robots.realdata.recording import Topics, read_recording

    model = rr.true_model(rr.MODELS / "tb3_robot.xml", TRUTH)
    sim = rr.simulate(model, TRUTH, 1.0, 0.025)
    rr.write_bag(tmp_path / "b", sim, TRUTH, topics=("/robot1/joint_states", "/robot1/odom", "/robot1/imu"))
    found = read_recording(tmp_path / "b", TRUTH.joints)
    named = read_recording(tmp_path / "b", TRUTH.joints, Topics(namespace="/robot1/"))
    flags = read_recording(tmp_path / "b", TRUTH.joints, Topics("/robot1/joint_states", "/robot1/odom", "/robot1/imu"))
    assert any(n.startswith("robot namespace '/robot1' taken") for n in found.notes)
    assert len(found.t) == 101 and len(found.odom_t) == len(found.imu_t) == 101
    for rec in (named, flags):
        for k in ("t", "velocity", "effort", "odom_twist", "imu_gyro"):
            assert np.array_equal(getattr(rec, k), getattr(found, k)), k


def _stand_in_bag(path: Path, n: int) -> None:
    """This project's exporter on a 3-row stand-in log of ``n`` followers (no simulation: a bag's layout)."""
    from types import SimpleNamespace

    from bioform_mj.outputs.rosbag import write_bag

    z, K = np.zeros, 3
    log = {
        "t": np.arange(K) * 0.01,
        "t_state": np.arange(K + 1) * 0.01,
        "pose_3d": z((K + 1, n, 6)),
        "twist_3d": z((K + 1, n, 6)),
        "wheel_angle": z((K + 1, n, 2)),
        "wheel_speed": z((K + 1, n, 2)),
        "leader_state": z((K + 1, 5)),
        "wheel_sign": np.ones((n, 2)),
        "wheel_joints": np.array([["left_wheel", "right_wheel"]] * n),
        "cmd": z((K, n, 2)),
        "tau": z((K, n, 2)),
        "est_pose": z((K, n, 3)),
        "est_vel": z((K, n, 2)),
    }
    write_bag(SimpleNamespace(log=log, summary={}), path)


def test_several_robots_in_a_bag_one_error_line_naming_them(tmp_path, capsys):
    _stand_in_bag(tmp_path / "bag", 3)
    out = tmp_path / "fit"
    assert cli.main(["robot", "fit", "paper", "--bag", str(tmp_path / "bag"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:"), err
    assert "/f1/joint_states, /f2/joint_states, /f3/joint_states" in err[0] and "--robot-ns" in err[0]
    assert not out.exists()
    assert (
        cli.main(["robot", "fit", "paper", "--bag", str(tmp_path / "bag"), "--robot-ns", "f4", "--out", str(out)]) == 2
    )
    assert "'/f4/joint_states'" in capsys.readouterr().err and not out.exists()


@pytest.mark.slow
def test_dc_motor_robots_own_bag_fits_without_flags(tmp_path):
    """The tb3 preset (XL430 ``<dcmotor>`` drives behind a current driver, 3 followers), 10 s without its
    disturbance forces, exported with ``--rosbag``: its efforts are the commanded torques, and the bag says so.
    ``robot fit tb3 --robot-ns f1`` (no topic or motor flags) simulates the motors and finds the published
    robot: masses within 2 %, ``a``/``b`` within 2 %, no damping or friction to speak of (measured: mass
    0.9386 kg, a 29.32 against 29.19). Taking the same efforts as applied torques (``--motor ideal``, what the
    fit did before the bag said what its effort is) leaves a residual thousands of times larger and the mass
    40 % off (1.325 kg; 3.77 kg on a 12 s run with the preset's disturbance forces on)."""
    run = tmp_path / "run"
    assert cli.main(["run", "tb3", "--duration", "10", *CALM, "--rosbag", "--out", str(run), "--quiet"]) == 0
    out = tmp_path / "fit"
    base = ["robot", "fit", "tb3", "--bag", str(run / "rosbag"), "--robot-ns", "f1", "--time-budget", "600"]
    assert cli.main([*base, "--out", str(out)]) == 0
    rep = json.loads((out / "fit.json").read_text())
    got = {p["name"]: p for p in rep["parameters"]}
    assert rep["effort"] == {"motor": "dc", "driver": "current"}
    assert any("<dcmotor>" in n and "metadata" in n for n in rep["notes"])
    assert any("namespace" not in n and "/f1/ground_truth/odom" in n for n in rep["notes"])
    assert got["mass"]["fitted"] == pytest.approx(0.943, rel=0.02)
    assert got["yaw_inertia"]["fitted"] == pytest.approx(0.0020064, rel=0.03)
    assert rep["a"] == pytest.approx(rep["published"]["a"], rel=0.02)
    assert rep["b"] == pytest.approx(rep["published"]["b"], rel=0.02)
    for side in "LR":
        assert got[f"damping_{side}"]["fitted"] < 1e-4  # N·m·s/rad, against 0.05 N·m at 6 rad/s
        assert got[f"frictionloss_{side}"]["fitted"] < 1e-3  # N·m, 2 % of the torque limit
    out2 = tmp_path / "fit_ideal"
    assert cli.main([*base, "--motor", "ideal", "--out", str(out2)]) == 0
    rep2 = json.loads((out2 / "fit.json").read_text())
    wrong = {p["name"]: p for p in rep2["parameters"]}
    assert wrong["mass"]["fitted"] > 1.2 * 0.943
    assert rep2["residual"]["calibrated"]["cost"] > 100 * rep["residual"]["calibrated"]["cost"]


@pytest.mark.slow
def test_intervals_hold_the_truth_on_most_recordings(tmp_path):
    """Three 24 s tb3 recordings of the changed robot (torque programs 1, 2, 3, sensor noise seeds 101–103):
    the truth lies inside the 95 % interval for 16 of the 18 parameter fits measured (89 %; the misses: a
    mass 1.3 % low with ±1.0 %, a damping 1.8 % high with ±1.7 %); required here: at least 14 (78 %). The
    independent-residual intervals alone held it far less often (tb3 mass ±0.006 kg against an error of
    0.011 kg); the cluster-robust ones are about twice as wide (mass ±0.012–0.015 kg)."""
    truth = TRUTH.values(0.943, 0.0020064)  # tb3_robot.xml's chassis body
    inside, total, mass_hw = 0, 0, []
    for s in (1, 2, 3):
        model = rr.true_model(rr.MODELS / "tb3_robot.xml", TRUTH)
        sim = rr.simulate(model, TRUTH, 24.0, 0.025, s)
        rr.write_bag(tmp_path / f"bag{s}", sim, TRUTH, seed=s + 100)
        out = tmp_path / f"fit{s}"
        argv = ["robot", "fit", "tb3", "--bag", str(tmp_path / f"bag{s}"), "--out", str(out), "--time-budget", "600"]
        assert cli.main(argv) == 0
        for p in json.loads((out / "fit.json").read_text())["parameters"]:
            total += 1
            inside += p["ci95"] is not None and p["ci95"][0] <= truth[p["name"]] <= p["ci95"][1]
            if p["name"] == "mass":
                mass_hw.append(p["ci95_halfwidth"])
    assert total == 18 and inside >= 14, (inside, total)
    assert min(mass_hw) > 0.008  # kg: wider than the 0.006 kg the independent-residual interval gave


@pytest.mark.slow
def test_a_dragging_caster_is_named_and_nothing_is_reported_found(tmp_path):
    """tb3 whose ball caster drags (sliding friction 0.3, the file's is frictionless), 24 s (program 5, noise
    seed 105) at 0.025 N·m: the caster's drag (0.3 × 4.8 N × 0.033 m = 0.048 N·m of wheel torque) all but holds
    the robot (wheels at most 0.38 rad/s, above 0.1 rad/s 1 % of the time; without the drag 10.7 rad/s). The
    report says so ("the wheels hardly turned"),
    names the caster robot check finds, says the model misses the recording and reports no parameter
    identified, rather than a mass of 3.8 kg ± 0.1 %."""
    truth = rr.Truth(**{**TRUTH.__dict__, "caster_friction": 0.3})
    model = rr.true_model(rr.MODELS / "tb3_robot.xml", truth)
    rr.write_bag(tmp_path / "bag", rr.simulate(model, truth, 24.0, 0.025, 5), truth, seed=105)
    out = tmp_path / "fit"
    assert cli.main(["robot", "fit", "tb3", "--bag", str(tmp_path / "bag"), "--out", str(out)]) == 0
    rep = json.loads((out / "fit.json").read_text())
    assert any("back_caster" in n and "not fitted unless asked" in n for n in rep["notes"])
    assert any("misses the recording" in n for n in rep["notes"])
    assert any(n.startswith("the wheels hardly turned") for n in rep["notes"])
    assert rep["unidentified"] == [p["name"] for p in rep["parameters"]]


def _caster_fit(tmp_path: Path, truth: rr.Truth, seed: int) -> dict:
    """``robot fit tb3 --fit ...,caster_friction`` of a 24 s recording at 0.08 N·m (pulses of 0.024-0.08 N·m)
    of ``truth`` (program ``seed``); the optimiser's time budget lifted (a loaded machine must not change it)."""
    rr.record(tmp_path / "bag", "tb3", truth, duration=24.0, tau=0.08, seed=seed)
    out = tmp_path / "fit"
    fit = "mass,yaw_inertia,damping,frictionloss,caster_friction"
    argv = ["robot", "fit", "tb3", "--bag", str(tmp_path / "bag"), "--out", str(out), "--fit", fit]
    assert cli.main([*argv, "--time-budget", "600"]) == 0
    return json.loads((out / "fit.json").read_text())


def _check_caster_fit(rep: dict, truth: rr.Truth) -> dict:
    """Caster friction recovered within 10 % and its interval holding the truth; the mass within 5 %; every
    parameter reported identified within its tolerance (yaw inertia and wheels 10 %: the chatter leaves the
    yaw inertia's profile interval at ±22 %) and its 95 % interval holding the truth."""
    assert any("back_caster" in n and "condim 3" in n for n in rep["notes"])
    assert any(n.startswith("caster friction searched first on a grid") for n in rep["notes"])
    true = {
        "mass": (0.943 + truth.payload_kg, 0.05),
        "yaw_inertia": (0.0020064 + truth.payload_yaw_kgm2, 0.10),
        "damping_L": (truth.damping[0], 0.10),
        "damping_R": (truth.damping[1], 0.10),
        "frictionloss_L": (truth.frictionloss[0], 0.10),
        "frictionloss_R": (truth.frictionloss[1], 0.10),
        "caster_friction": (truth.caster_friction, 0.10),
    }
    got = {p["name"]: p for p in rep["parameters"]}
    assert set(got) == set(true)
    for name, (value, tol) in true.items():
        p = got[name]
        assert p["status"] == "not identified" or abs(p["fitted"] - value) <= tol * value, (name, p)
        assert p["status"] == "not identified" or p["ci95"][0] <= value <= p["ci95"][1], (name, p)
        assert p["status"] == "identified" or p["why"], p
        assert p["ci95_method"].startswith("profile"), p
    caster = got["caster_friction"]
    assert caster["status"] == "identified", caster
    assert abs(caster["fitted"] - truth.caster_friction) <= 0.10 * truth.caster_friction, caster
    assert caster["ci95"][0] <= truth.caster_friction <= caster["ci95"][1], caster
    assert abs(got["mass"]["fitted"] - true["mass"][0]) <= 0.05 * true["mass"][0], got["mass"]
    return got


@pytest.mark.slow  # ~70 s CPU
def test_a_dragging_caster_is_recovered(tmp_path):
    """tb3 whose ball caster drags (sliding friction 0.3; the file's is frictionless, condim 1: the notes say it
    is given condim 3), payload 0.3 kg. The sliding caster chatters (its contact opens 20-45 % of the time at
    ~50 Hz), so samples of the wheel speeds are chaotic: before, the fit compared them, stalled at caster 0.2
    and reported nothing found. Now it compares 0.1 s means and searches the caster's friction on a grid first:
    measured caster 0.3048 (profile interval 0.280-0.324), mass 1.222 kg (1.147-1.293; truth 1.243), yaw
    inertia +5.2 % (interval ±22 %), wheel damping within 6 %; the wheels' dry friction (traded against the
    caster's, ±32 %) not identified."""
    truth = rr.Truth(**{**TRUTH.__dict__, "caster_friction": 0.3})
    _check_caster_fit(_caster_fit(tmp_path, truth, 0), truth)


@pytest.mark.slow  # ~70 s CPU
def test_a_dragging_caster_of_another_friction_and_mass_is_recovered(tmp_path):
    """Caster friction 0.15, payload 0.5 kg and 0.0015 kg·m², other wheel damping and dry friction, another
    program. Measured: caster 0.1509 (0.129-0.177; the grid's start was 0.05), mass 1.463 kg (1.338-1.597;
    truth 1.443); frictionloss_R 0.0052 (0.0020-0.0084) not identified."""
    truth = rr.Truth(
        payload_kg=0.5,
        payload_yaw_kgm2=0.0015,
        damping=(0.003, 0.002),
        frictionloss=(0.003, 0.005),
        caster_friction=0.15,
    )
    _check_caster_fit(_caster_fit(tmp_path, truth, 3), truth)

"""The whole stack closed-loop on the MuJoCo plant (issue 3): numbers against the physics.

The learner's target is the ground truth read from the compiled model (``a_eff``, ``b_eff``,
design §8), which ``test_plants_mujoco_models.py`` checks by system identification. The runs are
shared through module-scoped fixtures: Table I in MuJoCo (4 × 20 s, whose
bioinspired-learning run also serves the learner and formation checks), the payload preset
(120 s) and the heterogeneous preset (2 × 20 s). Measured values are quoted at each bound.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

from bioform_mj.cli.main import main
from bioform_mj.control.params import stack_params
from bioform_mj.jobs.table1 import ordering_holds, run_table1
from bioform_mj.robots.params import ground_truth
from bioform_mj.robots.refs import models_dir
from bioform_mj.run.simulate import simulate
from bioform_mj.scenario.config import EventCfg
from bioform_mj.scenario.loader import load

PAPER_C = np.array([0.4, 10.0])  # the paper robot's a_eff, b_eff (models/paper_robot.xml)


def _rel(c_hat, c_true) -> np.ndarray:
    return np.asarray(c_hat) / np.asarray(c_true) - 1.0


# ---------------------------------------------------------------------------------------
# The paper scenario in MuJoCo: Table I and the learner
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def table1_mujoco():
    """``run_table1`` on the paper scenario with ``--plant mujoco``; (table, {method: RunResult})."""
    results = {}
    table = run_table1(load("paper", plant="mujoco"), on_result=results.__setitem__)
    return table, results


@pytest.mark.slow
def test_bioinspired_learning_learns_c_and_holds_formation(table1_mujoco):
    """ĉ within 10 % of the model's a_eff, b_eff for every follower; formation error < 0.1 m.

    Measured (20 s): â −6.5..−6.8 % (the constant d1 = 0.1 biases it, design §8), b̂ −0.8..+3.3 %;
    final formation errors 2.5, 3.05, 3.0 cm (the paper-literal sgn chatters), estimation
    errors 4.1–5.5 mm.
    """
    _, results = table1_mujoco
    res = results["bioinspired-learning"]
    assert res.diverged is None
    assert res.summary["plant"] == "mujoco" and res.summary["sim_time_s"] == pytest.approx(20.0)
    for f in res.summary["followers"]:
        np.testing.assert_allclose(f["c_true"], PAPER_C, rtol=1e-6)  # the calibrated robot
        err = _rel(f["c_hat"], f["c_true"])
        assert np.all(np.abs(err) < 0.10), (f["id"], err)
        assert f["final_formation_error_m"] < 0.1
        assert f["final_estimation_error_m"] < 0.02
    # the learner moved ĉ from ĉ(0) = 0.5 c_true and stayed there: the last 5 s within 10 % too
    log = res.log
    late = log["t"] >= 15.0
    assert np.all(np.abs(_rel(log["c_hat"][late], log["c_true"][late])) < 0.10)
    np.testing.assert_allclose(log["c_hat"][0], 0.5 * log["c_true"][0], rtol=1e-3)


@pytest.mark.slow
def test_table1_ordering_holds_in_mujoco(table1_mujoco):
    """Bioinspired-learning has the lowest total velocity error for every follower.

    Measured (20 s): BIO-L 1.92/2.00/2.16, BIO 2.61/2.81/3.00, BS-L 8.11/6.37/11.69,
    BS 10.23/7.92/14.64 — the paper's ordering, with BIO-L's margin over BIO ~25 %.
    """
    table, results = table1_mujoco
    assert table["plant"] == "mujoco"
    assert all(r.diverged is None for r in results.values())
    assert ordering_holds(table) and table["ordering_holds"]
    per = {m: np.array([f["total_velocity_error"] for f in s["followers"]]) for m, s in table["methods"].items()}
    best = per["bioinspired-learning"]
    for m in ("bioinspired", "backstepping-learning", "backstepping"):
        assert np.all(best < 0.9 * per[m]), (m, best, per[m])  # strictly, with a margin
    # learning helps both laws; the bioinspired law beats backstepping with or without it
    assert np.all(per["backstepping-learning"] < per["backstepping"])
    assert np.all(per["bioinspired"] < per["backstepping-learning"])
    # every method holds the formation in MuJoCo (final errors 2.4–3.2 cm)
    for s in table["methods"].values():
        assert max(f["final_formation_error_m"] for f in s["followers"]) < 0.1


def test_same_seed_identical_logs_in_mujoco():
    """Same seed: bit-identical logs and summaries (but the wall time); another seed differs.

    With jittered initial poses and a payload event, so that both seeded and event paths run.
    """

    def run(seed: int):
        sc = load(
            "paper", plant="mujoco", overrides=["sim.duration=1.5", "formation.init_jitter=0.2", f"sim.seed={seed}"]
        )
        sc = dataclasses.replace(sc, events=(EventCfg(time=0.5, follower=2, mass=12.0, inertia=0.3),))
        return simulate(sc)

    a, b, c = run(4), run(4), run(5)
    assert a.diverged is None and c.diverged is None
    assert set(a.log) == set(b.log)
    for key in a.log:
        np.testing.assert_array_equal(a.log[key], b.log[key], err_msg=key)
    assert a.summary["followers"] == b.summary["followers"]
    strip = lambda s: {k: v for k, v in s.items() if k not in ("wall_time_s", "setup_time_s")}  # noqa: E731
    assert strip(a.summary) == strip(b.summary)
    assert not np.array_equal(a.log["pose"][0], c.log["pose"][0])
    assert not np.array_equal(a.log["tau"], c.log["tau"])
    assert a.log["c_true"][-1, 1, 0] < a.log["c_true"][0, 1, 0]  # the payload arrived


# ---------------------------------------------------------------------------------------
# Payload preset: follower 2 picks up 12 kg + 0.3 kg·m² at t = 10 s
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def payload_run():
    sc = load("payload")
    return sc, simulate(sc)


def test_payload_preset_truth_inside_projection_set():
    """The new (a, b) = (0.270, 4.00) lies inside [0.1, 10] × ĉ(0): the bounds cannot stop the learner."""
    sc = load("payload")
    ev = sc.events[0]
    assert (ev.follower, ev.time, ev.mass, ev.inertia) == (2, 10.0, 12.0, 0.3)
    # paper robot: m = 24.5 kg, I = 0.18 kg·m², r = 0.1 m, l = 0.2 m, I_w = 0.0025 kg·m²
    m, i_yaw, r, l, iw = 24.5 + ev.mass, 0.18 + ev.inertia, 0.1, 0.2, 0.0025
    c_new = np.array([1 / (m * r + 2 * iw / r), l / (i_yaw * r + 2 * iw * l**2 / r)])
    np.testing.assert_allclose(c_new, [0.27027, 4.0], rtol=1e-4)
    p = stack_params(sc, np.tile(PAPER_C, (sc.n, 1)))  # bounds around ĉ(0) = 0.5 c_true(0)
    assert np.all(p.c_min[1] < c_new) and np.all(c_new < p.c_max[1])
    np.testing.assert_allclose(p.c_min[1], [0.02, 0.5])
    np.testing.assert_allclose(p.c_max[1], [2.0, 50.0])


@pytest.mark.slow
def test_payload_c_hat_tracks_new_values(payload_run):
    """By the end (120 s) follower 2's ĉ is within 15 % of the loaded robot's a_eff, b_eff.

    Measured: â 0.242 vs 0.270 (−10.3 %: re-converged within ~5 s, biased by d1), b̂ 3.96 vs 4.00
    (−1.0 %). b̂ is slow: 10.4 at the pick-up, 6.8 at 40 s, 5.3 at 60 s (+32 %), 4.1 at 100 s;
    its time constant is 23–37 s on the paper's gently weaving leader (payload.toml says why).
    """
    sc, res = payload_run
    assert res.diverged is None and res.summary["sim_time_s"] == pytest.approx(sc.sim.duration)
    log, t = res.log, res.log["t"]
    before, after = t < 10.0, t >= 10.0 + 1e-9
    # the plant's truth switches at the event, for follower 2 only
    np.testing.assert_allclose(log["c_true"][before][:, 1], np.tile(PAPER_C, (before.sum(), 1)), rtol=1e-6)
    np.testing.assert_allclose(log["c_true"][after][:, 1], np.tile([1 / 3.7, 4.0], (after.sum(), 1)), rtol=1e-6)
    np.testing.assert_allclose(log["c_true"][:, [0, 2]], np.broadcast_to(PAPER_C, (len(t), 2, 2)), rtol=1e-6)
    # just before the pick-up follower 2 had learnt the unloaded robot (â −4 %, b̂ +4 %)
    k_pick = np.flatnonzero(before)[-1]
    assert np.all(np.abs(_rel(log["c_hat"][k_pick, 1], PAPER_C)) < 0.10)
    # by the end: the new values, within 15 %
    f2 = res.summary["followers"][1]
    np.testing.assert_allclose(f2["c_true"], [1 / 3.7, 4.0], rtol=1e-6)
    err = _rel(f2["c_hat"], f2["c_true"])
    assert np.all(np.abs(err) < 0.15), err

    # â re-converges fast (measured −7 % at 20 s), b̂'s error shrinks all the way (+123 %, +32 %, −1 %)
    def err_at(time: float) -> np.ndarray:
        k = np.searchsorted(t, time)
        return np.abs(_rel(log["c_hat"][k, 1], log["c_true"][k, 1]))

    assert err_at(20.0)[0] < 0.15
    assert err_at(20.0)[1] > err_at(60.0)[1] > err_at(119.0)[1]
    # the unloaded followers are undisturbed: ĉ within 10 % (â −6.8 %, b̂ −2.5 %), formation held
    for f in (res.summary["followers"][0], res.summary["followers"][2]):
        assert np.all(np.abs(_rel(f["c_hat"], f["c_true"])) < 0.10)
    for f in res.summary["followers"]:
        assert f["final_formation_error_m"] < 0.1  # measured 2.2, 2.9, 2.9 cm
    assert log["formation_error"][after].max() < 0.1  # the pick-up does not break the formation


# ---------------------------------------------------------------------------------------
# Heterogeneous preset: paper robot, lab robot, paper robot
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def hetero_runs():
    """The preset (the paper's learner gains), and the same with k4 scaled ×1000 for the lab robot."""
    return {
        "paper gains": simulate(load("hetero")),
        "k4 x1000": simulate(load("hetero", overrides=["learner.k4=[6000.0, 50000.0]"])),
        "gain scaling": simulate(load("hetero", overrides=['learner.gain_scaling="c_hat0"'])),
    }


@pytest.mark.slow
def test_hetero_formation_holds(hetero_runs):
    """Final formation error < 0.1 m for every follower (measured 2.5, 2.9, 3.0 cm)."""
    for res in hetero_runs.values():
        assert res.diverged is None
        for f in res.summary["followers"]:
            assert f["final_formation_error_m"] < 0.1
            assert f["rms_formation_error_last_half_m"] < 0.1


@pytest.mark.slow
def test_hetero_lab_robot_c_hat_does_not_learn_with_paper_gains(hetero_runs):
    """Recorded honestly: with the paper's gains the lab robot's ĉ stays at ĉ(0) = 0.5 c_true.

    The learner's rate is ~k4·E[τ²]/k5 (+ a chatter term), and the lab robot (c ≈ (14.4, 327),
    ~35× the paper robot's) needs ~35× smaller torques: measured time constants ~1 h (a) and
    ~20 h (b). In 20 s ĉ moves +2.1 % (a) and +1.6 % (b) from ĉ(0), i.e. ends −49 % off. The
    paper robots of the same team learn as in the paper scenario (within 7 %).
    """
    res = hetero_runs["paper gains"]
    lab = res.summary["followers"][1]
    np.testing.assert_allclose(lab["c_true"], [14.43, 326.6], rtol=1e-3)
    moved = np.asarray(lab["c_hat"]) / (0.5 * np.asarray(lab["c_true"]))
    assert np.all(moved > 1.0) and np.all(moved < 1.05), moved  # learning in the right direction, barely
    assert np.all(_rel(lab["c_hat"], lab["c_true"]) < -0.45)
    for f in (res.summary["followers"][0], res.summary["followers"][2]):
        assert np.all(np.abs(_rel(f["c_hat"], f["c_true"])) < 0.10)


@pytest.mark.slow
def test_hetero_scaled_learner_gain_learns_every_robot(hetero_runs):
    """k4 ×1000 (adaptation speed ∝ k4/c²): every ĉ within 10 % (measured lab −6.3 %, −0.1 %;
    paper robots −2.8..+2.0 %) — the explanation above, checked."""
    for f in hetero_runs["k4 x1000"].summary["followers"]:
        assert np.all(np.abs(_rel(f["c_hat"], f["c_true"])) < 0.10), f


@pytest.mark.slow
def test_hetero_gain_scaling_learns_every_robot_and_keeps_the_paper_robots(hetero_runs):
    """learner.gain_scaling = "c_hat0" (k4 ∝ ĉ(0)², the explanation above turned into a setting):
    the lab robot learns within 10 % (measured −6.5 %, −0.1 %); the paper robots keep the paper's
    gains (to the 1e-9 by which the compiled model's a_eff differs from 0.4), so their ĉ is that
    of the unscaled run."""
    scaled, plain = hetero_runs["gain scaling"].summary["followers"], hetero_runs["paper gains"].summary["followers"]
    for f in scaled:
        assert np.all(np.abs(_rel(f["c_hat"], f["c_true"])) < 0.10), f
    for i in (0, 2):
        np.testing.assert_allclose(scaled[i]["c_hat"], plain[i]["c_hat"], rtol=1e-6)


# ---------------------------------------------------------------------------------------
# CLI: run --plant mujoco writes scene.xml; identify
# ---------------------------------------------------------------------------------------


def test_run_mujoco_writes_scene_xml_that_compiles(tmp_path):
    out = tmp_path / "run"
    code = main(["run", "paper", "--plant", "mujoco", "--set", "sim.duration=1", "--out", str(out), "--quiet"])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["plant"] == "mujoco" and summary["sim_time_s"] == pytest.approx(1.0)
    scene = out / "scene.xml"
    assert scene.is_file() and (out / "log.npz").is_file()
    model = mujoco.MjModel.from_xml_path(str(scene))
    assert model.nu == 6  # two wheel motors per follower
    for i in (1, 2, 3):
        model.body(f"f{i}/base")  # raises KeyError if missing
    assert model.body_mocapid[model.body("leader").id] >= 0
    assert model.opt.timestep == pytest.approx(0.001)
    # the robots stand at the scenario's initial poses, and the truth matches the summary's c_true
    sc = load("paper")
    for i, pose in enumerate(sc.initial_poses()):
        adr = model.jnt_qposadr[model.body_jntadr[model.body(f"f{i + 1}/base").id]]
        np.testing.assert_allclose(model.qpos0[adr : adr + 2], pose[:2], atol=1e-6)
    for i, f in enumerate(summary["followers"]):
        np.testing.assert_allclose(ground_truth(model, f"f{i + 1}/"), f["c_true"], rtol=1e-5)  # to_xml: ~7 digits


@pytest.mark.parametrize("name,expected", [("paper", (0.4, 10.0)), ("lab", (14.43, 326.61))])
def test_identify_cli_on_model_file(tmp_path, name, expected):
    """``bioform identify MODEL.xml``: exit 0, JSON on stdout, identified a, b within 3 % of the formula
    (measured 1e-5), and the formula equals the calibration in the model's header."""
    model = tmp_path / "MODEL.xml"
    model.write_text((models_dir() / f"{name}_robot.xml").read_text())
    out_json = tmp_path / "ident.json"
    exe = Path(sys.executable).with_name("bioform")
    cmd = [str(exe)] if exe.is_file() else [sys.executable, "-m", "bioform_mj.cli"]
    r = subprocess.run(
        cmd + ["identify", str(model), "--out", str(out_json)],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert rep == json.loads(out_json.read_text())
    np.testing.assert_allclose([rep["formula"]["a"], rep["formula"]["b"]], expected, rtol=1e-3)
    for k in ("a", "b"):
        assert rep["identified"][k] == pytest.approx(rep["formula"][k], rel=0.03)
        assert abs(rep["relative_error"][k]) < 0.03
    assert rep["test"]["mujoco_warnings"] == 0


NO_WHEELS = """<mujoco model="no_wheels">
  <worldbody>
    <body name="base" pos="0 0 0.1">
      <freejoint name="root"/>
      <geom name="chassis" type="box" size="0.1 0.1 0.05" mass="5"/>
    </body>
  </worldbody>
</mujoco>
"""


@pytest.mark.parametrize(
    "case,needle",
    [
        ("missing", "does not exist"),
        ("no wheels", "left_wheel"),
        ("not xml", "MODEL.xml"),
    ],
)
def test_identify_cli_bad_model_exit_2_one_line(tmp_path, capsys, case, needle):
    model = tmp_path / "MODEL.xml"
    if case == "no wheels":
        model.write_text(NO_WHEELS)
    elif case == "not xml":
        model.write_text("<mujoco><worldbody>")
    out_json = tmp_path / "ident.json"
    code = main(["identify", str(model), "--out", str(out_json)])
    cap = capsys.readouterr()
    assert code == 2
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and needle in lines[0], cap.err
    assert "Traceback" not in cap.err and cap.out == ""
    assert not out_json.exists()

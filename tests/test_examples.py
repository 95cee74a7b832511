"""The user-written controller of examples/ plugs into simulate() without copying the loop."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from bioform_mj.control.base import Controller

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "kanayama.py"


@pytest.fixture(scope="module")
def kanayama():
    spec = importlib.util.spec_from_file_location("kanayama_example", EXAMPLE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_user_controller_holds_the_formation_and_is_compared_with_the_four_methods(kanayama):
    summ = kanayama.compare("ideal", duration=10.0)
    user = summ["kanayama (examples/)"]
    assert user["controller"] == "Kanayama" and user["engine"] == "stepwise"
    fe = [f["final_formation_error_m"] for f in user["followers"]]
    assert max(fe) < 0.1  # measured 0.02-0.03 m after 10 s
    assert all(f["outcome"] == "ok" for f in user["followers"])
    j_user = np.array([f["total_velocity_error"] for f in user["followers"]])
    j_bio = np.array([f["total_velocity_error"] for f in summ["bioinspired-learning"]["followers"]])
    assert np.all(np.isfinite(j_user)) and np.all(j_bio < j_user)  # measured 1.3 vs 4.6-7.0 over 20 s
    # signals the controller does not provide are NaN, not zeros
    assert all(np.isnan(f["c_hat"][0]) for f in user["followers"])
    md = kanayama.table(summ)
    assert md.count("\n") == 2 + 5 and "kanayama" in md


def test_user_controller_satisfies_the_protocol(kanayama):
    from bioform_mj.run.simulate import make_plant
    from bioform_mj.scenario.loader import load

    sc = load("paper")
    pl = make_plant(sc)
    assert isinstance(kanayama.Kanayama(sc, pl.c_true(), np.full(3, 20.0)), Controller)


def test_user_controller_honours_offsets_in_the_leaders_frame(kanayama):
    """formation.frame = "leader" on an 8 m circle: the example used to track world-frame slots and lose
    the formation (0.6-2.2 m); it now tracks the slot's own pose and velocity (measured 6-29 mm)."""
    from bioform_mj.run.simulate import make_plant, simulate
    from bioform_mj.scenario.loader import load

    ov = ["sim.duration=10", "formation.frame=leader", "leader.kind=circle", "leader.radius=8", "leader.y0=8"]
    sc = load("paper", ov, plant="ideal")
    pl = make_plant(sc)
    res = simulate(sc, plant=pl, controller=kanayama.Kanayama(sc, pl.c_true(), np.full(sc.n, sc.torque.tau_max)))
    fe = [f["final_formation_error_m"] for f in res.summary["followers"]]
    assert max(fe) < 0.1, fe  # measured 0.006, 0.027, 0.029 m
    # the slots it was judged on are the leader-frame ones (design §4): p_r - R(θ_r) Δ
    lp = res.log["leader_pose"][-1]
    c, s = np.cos(lp[2]), np.sin(lp[2])
    off = np.array(sc.formation.offsets)
    slots = lp[:2] - np.column_stack([c * off[:, 0] - s * off[:, 1], s * off[:, 0] + c * off[:, 1]])
    assert np.allclose(res.log["slots"][-1], slots, atol=1e-9)


def test_user_controller_honours_the_saturation_mode(kanayama):
    from bioform_mj.core.equations import saturate
    from bioform_mj.scenario.loader import load

    got = {}
    for mode, steer in (("steer-priority", True), ("wheel", False)):
        sc = load("paper", [f"torque.saturation={mode}"])
        k = kanayama.Kanayama(sc, np.tile([0.4, 10.0], (3, 1)), np.full(3, 1.0))
        assert k.steer is steer
        k.reset(np.zeros((3, 3)), np.zeros((3, 2)))
        k.state.est_vel[:] = (1.0, 0.0)  # a moving leader estimate: the command turns
        poses = np.array([[-3.0, -1.0, 0.5], [-4.0, 5.0, -0.5], [-4.0, -5.0, 0.3]])  # off their slots: saturates
        tau = k.step(np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0]), poses, np.zeros((3, 2))).copy()
        assert np.all(np.abs(tau) <= 1.0 + 1e-12)  # each wheel within its 1 N·m limit
        for i in range(3):
            assert tuple(tau[i]) == saturate(k.tau_raw[i, 0], k.tau_raw[i, 1], 1.0, steer)
        got[mode] = tau
    assert not np.array_equal(got["steer-priority"], got["wheel"])  # the mode is the scenario's, not fixed


def test_example_on_a_bad_scenario_says_one_error_line_and_exits_2(tmp_path):
    import os
    import subprocess
    import sys

    env = dict(
        os.environ, PYTHONPATH=str(EXAMPLE.parent.parent / "src") + os.pathsep + os.environ.get("PYTHONPATH", "")
    )
    out = subprocess.run(
        [sys.executable, str(EXAMPLE), "paper", "--set", "formation.frame=sideways", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert out.returncode == 2
    err = out.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "formation.frame" in err[0]

"""``bioform sweep/bench --backend warp`` through the CLI: rows agree with the local backend
(Warp's CPU device, a few worlds), and the exit-2 paths. The tests that need no Warp (the
missing extra, monkeypatched away) run in every venv."""

import csv
import sys

import numpy as np
import pytest

from bioform_mj.cli.main import main

SWEEP = [
    "sweep",
    "paper",
    "--plant",
    "mujoco",
    "--duration",
    "0.3",
    "--seeds",
    "2",
    "--set",
    "formation.init_jitter=0.05",
    "--quiet",
]


def _rows(out):
    with open(out / "runs.csv") as fh:
        return {r["seed"]: r for r in csv.DictReader(fh)}


def _no_warp(monkeypatch):
    for mod in ("warp", "mujoco_warp"):
        monkeypatch.setitem(sys.modules, mod, None)  # import raises ImportError


@pytest.mark.parametrize(
    "cmd", [SWEEP + ["--backend", "warp"], ["bench", "--backend", "warp", "--worlds", "2"]], ids=["sweep", "bench"]
)
def test_without_the_extra_exit_2(cmd, monkeypatch, tmp_path, capsys):
    _no_warp(monkeypatch)
    out = tmp_path / "sw"
    args = cmd + (["--out", str(out)] if cmd[0] == "sweep" else ["--json", str(tmp_path / "b.json")])
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "pip install 'bioform-mj[gpu]'" in err[0]
    assert not out.exists() and not (tmp_path / "b.json").exists()


# ---- below: Warp's CPU device
def _need_warp():
    pytest.importorskip("warp")
    pytest.importorskip("mujoco_warp")
    import warp as wp

    wp.config.quiet = True


@pytest.mark.parametrize(
    "extra,what",
    [
        (["--plant", "ideal"], "plant.kind = 'ideal'"),
        (["--set", "faults.friction_patch=[-5.0,-5.0,5.0,5.0,0.3]"], "faults.friction_patch"),
    ],
)
def test_unsupported_feature_exit_2(extra, what, tmp_path, capsys):
    _need_warp()
    out = tmp_path / "sw"
    assert main(SWEEP + extra + ["--backend", "warp", "--device", "cpu", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and what in err[0], err
    assert not out.exists()


def test_too_many_worlds_exit_2(monkeypatch, tmp_path, capsys):
    _need_warp()
    from bioform_mj.batch import backend

    monkeypatch.setattr(backend, "free_memory", lambda device: 400_000)  # bytes: one world of 3 robots fits
    out = tmp_path / "sw"
    assert main(SWEEP + ["--backend", "warp", "--device", "cpu", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "2 worlds of 3 robots need about" in err[0], err
    assert "at most 1 worlds fit" in err[0]
    assert not out.exists()


def test_bad_device_exit_2(tmp_path, capsys):
    _need_warp()
    assert main(SWEEP + ["--backend", "warp", "--device", "tpu", "--out", str(tmp_path / "sw")]) == 2
    assert capsys.readouterr().err.startswith("error: --device 'tpu'")


@pytest.mark.parametrize(
    "extra",
    [
        [],
        [
            "--set",
            "faults.packet_loss=0.2",
            "--set",
            "faults.delay=0.005",
            "--set",
            "faults.push=[[1,0.1,0.1,40.0,0.0,0.0]]",
            "--set",
            "faults.actuator=[[3,0.05,0.2,0.5]]",
        ],
    ],
    ids=["paper", "faults"],
)
def test_warp_sweep_rows_agree_with_local(extra, tmp_path):
    """2 worlds (seeds) of the paper scenario, 0.3 s, without and with per-step faults (the sweep
    path hands them to the device): issue 13's tolerances, formation error 1 mm, ĉ 0.5 %, total
    velocity error 1 % (measured: < 1e-5 m at 0.3 s)."""
    _need_warp()
    wa, lo = tmp_path / "warp", tmp_path / "local"
    assert main(SWEEP + extra + ["--backend", "warp", "--device", "cpu", "--out", str(wa)]) == 0
    assert main(SWEEP + extra + ["--workers", "1", "--out", str(lo)]) == 0
    rw, rl = _rows(wa), _rows(lo)
    assert set(rw) == set(rl) == {"0", "1"}
    for seed in rw:
        a, b = rw[seed], rl[seed]
        assert a["key"] == b["key"]  # the same run (content key): a resume across backends skips it
        assert a["status"] == b["status"] == "ok"
        assert a["outcome"] == b["outcome"] and a["follower_outcomes"] == b["follower_outcomes"]
        assert a["backend"] == "warp" and a["device"] == "cpu" and a["batch_worlds"] == "2"
        f = lambda r, c: float(r[c])  # noqa: E731
        for c in (
            "final_formation_error_m_mean",
            "final_formation_error_m_max",
            "rms_formation_error_m_max",
            "final_estimation_error_m_max",
        ):
            assert abs(f(a, c) - f(b, c)) < 1e-3, c
        for c in ("total_velocity_error_mean", "total_velocity_error_max", "max_abs_v_cmd_max"):
            assert f(a, c) == pytest.approx(f(b, c), rel=1e-2), c
        assert f(a, "c_hat_abs_rel_error_max") == pytest.approx(f(b, "c_hat_abs_rel_error_max"), abs=5e-3)
    assert (wa / "stats.md").read_text().count("bioinspired-learning") == 1
    # a resume runs nothing
    assert main(SWEEP + extra + ["--backend", "warp", "--device", "cpu", "--out", str(wa)]) == 0
    import json

    assert json.loads((wa / "sweep.json").read_text())["ran"] == 0


def test_warp_sweep_groups_per_scene(tmp_path):
    """Two durations: two scenes (time axes), two batches; both land in one table."""
    _need_warp()
    out = tmp_path / "sw"
    args = [
        "sweep",
        "paper",
        "--plant",
        "mujoco",
        "--vary",
        "sim.duration=0.05,0.1",
        "--quiet",
        "--backend",
        "warp",
        "--device",
        "cpu",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    with open(out / "runs.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert sorted(float(r["sim_time_s"]) for r in rows) == [0.05, 0.1]
    assert all(r["batch_worlds"] == "1" and r["status"] == "ok" for r in rows)


def test_replay_reproduces_the_closed_loop():
    """The physics-alone benchmark replays the closed loop's own inputs: same final state."""
    _need_warp()
    from bioform_mj.batch.runner import BatchRun
    from bioform_mj.scenario.loader import load

    ov = ["plant.kind=mujoco", "sim.duration=0.05", "formation.init_jitter=0.05"]
    b = BatchRun([load("paper", overrides=[*ov, f"sim.seed={s}"]) for s in range(2)], "cpu")
    b.run()
    q_loop = b.d.qpos.numpy().copy()
    b.record()
    b.run_replay()
    np.testing.assert_allclose(b.d.qpos.numpy(), q_loop, atol=1e-5)

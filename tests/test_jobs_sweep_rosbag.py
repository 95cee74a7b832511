"""``bioform sweep … --rosbag`` (issue 29): one ROS 2 bag per row, complete or absent, resumable.

Each row's bag is read back with rosbags' own reader and compared with a run of the same scenario and
seed made here with ``simulate(full_state=True)`` (same engine, same seed: bit-identical numbers); a
resume redoes a row whose bag is gone and removes what an interrupted run left half-written; bad input
is one ``error:`` line and exit 2 before any work.
"""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from bioform_mj.cli.main import main

pytestmark = pytest.mark.skipif(importlib.util.find_spec("rosbags") is None, reason="the ros extra is not installed")

ARGS = ["--plant", "ideal", "--duration", "0.4", "--seeds", "2", "--set", "formation.init_jitter=0.2", "--quiet"]


def _odom_x(bag) -> tuple[np.ndarray, np.ndarray]:
    """``/f1/ground_truth/odom``: log times (ns) and position x (m), with rosbags' reader."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    t, x = [], []
    with Reader(bag) as rd:
        conns = [c for c in rd.connections if c.topic == "/f1/ground_truth/odom"]
        for c, ns, raw in rd.messages(connections=conns):
            t.append(ns)
            x.append(store.deserialize_cdr(raw, c.msgtype).pose.pose.position.x)
    return np.array(t), np.array(x)


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep_bags") / "s"
    assert main(["sweep", "paper", *ARGS, "--workers", "1", "--rosbag", "--out", str(out)]) == 0
    return out


def test_each_row_has_its_bag_equal_to_its_run(swept):
    from bioform_mj.run.simulate import simulate
    from bioform_mj.scenario.loader import load

    rows = [json.loads(p.read_text()) for p in sorted((swept / "runs").glob("*.json"))]
    assert len(rows) == 2 and {r["seed"] for r in rows} == {0, 1}
    assert json.loads((swept / "sweep.json").read_text())["rosbag"] == "jazzy"
    xs = []
    for r in rows:
        assert r["status"] == "ok" and r["rosbag"] == f"bags/{r['key']}" and r["rosbag_write_s"] > 0
        bag = swept / r["rosbag"]
        assert sorted(p.name for p in bag.iterdir()) == sorted(["metadata.yaml", f"{r['key']}.mcap"])
        t, x = _odom_x(bag)
        sc = load(
            "paper",
            ["formation.init_jitter=0.2", "sim.duration=0.4", f"sim.seed={r['seed']}"],
            plant="ideal",
            method="bioinspired-learning",
        )
        log = simulate(sc, full_state=True).log
        assert np.array_equal(t, np.rint(log["t_state"] * 1e9).astype(np.int64))  # K + 1 samples, 0 … T
        assert np.array_equal(x, log["pose_3d"][:, 0, 0])  # bit for bit
        xs.append(x)
    assert not np.array_equal(xs[0], xs[1])  # two seeds, two runs
    assert not [p for p in (swept / "bags").iterdir() if p.name.startswith(".")]


def test_resume_redoes_a_row_without_its_bag_and_removes_half_written_ones(swept, tmp_path, capsys):
    import shutil

    out = tmp_path / "s"
    shutil.copytree(swept, out)
    keys = sorted(p.stem for p in (out / "runs").glob("*.json"))
    gone = out / "bags" / keys[0]
    shutil.rmtree(gone)
    half = out / "bags" / f".{keys[1]}.abcd.tmp"  # what a run killed while writing leaves
    (half / keys[1]).mkdir(parents=True)
    (half / keys[1] / f"{keys[1]}.mcap").write_bytes(b"\x89MCAP0\r\n")
    kept = (out / "runs" / f"{keys[1]}.json").read_text()
    capsys.readouterr()
    assert main(["sweep", "paper", *ARGS, "--workers", "1", "--rosbag", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "resume: 1 half-written bag(s) of an interrupted run removed" in err
    assert "resume: 1 row(s) redone (its bag is missing (--rosbag))" in err
    assert not half.exists() and (gone / "metadata.yaml").is_file()
    assert (out / "runs" / f"{keys[1]}.json").read_text() == kept  # the other row was not run again
    assert json.loads((out / "sweep.json").read_text())["ran"] == 1
    assert np.array_equal(_odom_x(gone)[1], _odom_x(swept / "bags" / keys[0])[1])  # the same run again


def test_sweep_rosbag_bad_input_exit_2(tmp_path, capsys):
    out = tmp_path / "w"
    assert main(["sweep", "paper", *ARGS, "--ros-distro", "humble", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: --ros-distro only applies to --rosbag"]
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork")
def test_sigterm_mid_sweep_leaves_only_complete_bags_and_resumes(tmp_path):
    """SIGTERM while two workers run and write bags (paper, ideal plant, 20 s runs): every folder left in
    ``bags/`` is a complete bag rosbags reads (no temporary folder stays), every finished row has its bag, and
    the printed command resumes the sweep to a bag per row."""
    import os
    import signal
    import subprocess
    import time

    from rosbags.rosbag2 import Reader

    out = tmp_path / "s"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1] / "src")}
    args = ["--plant", "ideal", "--duration", "20", "--seeds", "12", "--set", "formation.init_jitter=0.2", "--quiet"]
    cmd = [sys.executable, "-m", "bioform_mj.cli", "sweep", "paper", *args, "--workers", "2", "--rosbag"]
    proc = subprocess.Popen([*cmd, "--out", str(out)], stderr=subprocess.PIPE, text=True, env=env)
    deadline = time.time() + 120
    while time.time() < deadline and len(list((out / "runs").glob("*.json")) if (out / "runs").exists() else []) < 3:
        time.sleep(0.02)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM, err
    rows = {p.stem for p in (out / "runs").glob("*.json")}
    bags = {p.name for p in (out / "bags").iterdir()}
    assert 3 <= len(rows) < 12 and not [b for b in bags if b.startswith(".")]
    assert rows <= bags  # a row is written after its bag
    for b in bags:  # complete: its metadata and every message read back
        with Reader(out / "bags" / b) as rd:
            assert rd.message_count == sum(1 for _ in rd.messages()) > 0
    resume = err.split("Resume with:")[1].strip().splitlines()[0].split()
    assert "--rosbag" in resume
    res = subprocess.run([sys.executable, "-m", "bioform_mj.cli", *resume[1:]], capture_output=True, text=True, env=env)
    assert res.returncode == 0, res.stderr
    keys = {p.stem for p in (out / "runs").glob("*.json")}
    assert len(keys) == 12 and keys == {p.name for p in (out / "bags").iterdir()}

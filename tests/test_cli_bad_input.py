"""Robustness: a battery of bad inputs (exit 2, one line, nothing written), fuzzed scenarios, SIGKILL."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
import tomllib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bioform_mj.cli.main import main

# (description, scenario-file text or None, extra argv, substring the error line must contain)
BAD = [
    ("malformed toml", "[sim\nduration=1", [], "not valid TOML"),
    ("unknown top-level key", "colour = 'red'", [], "'colour'"),
    ("unknown nested key", "[kinematic]\nk7 = 1.0", [], "kinematic.k7"),
    ("wrong type string for float", "[kinematic]\nk1 = 'two'", [], "kinematic.k1"),
    ("wrong type table for array", "[estimator]\nkp = 3.0", [], "estimator.kp"),
    ("nan gain", "[kinematic]\nk2 = nan", [], "kinematic.k2"),
    ("inf gain", "[torque]\nc = [inf, 3.0]", [], "torque.c"),
    ("zero gain", "[kinematic]\nk3 = 0.0", [], "kinematic.k3"),
    ("negative estimator gain", "[estimator]\nkp = [15.0, -1.0, 15.0]", [], "estimator.kp"),
    ("negative learner gain", "[learner]\nk4 = [6.0, -50.0]", [], "learner.k4"),
    ("negative neuron A", "[kinematic]\nA = -2.0", [], "kinematic.A"),
    ("zero duration", "[sim]\nduration = 0.0", [], "sim.duration"),
    ("negative duration", "[sim]\nduration = -5.0", [], "sim.duration"),
    ("physics step larger than control", "[sim]\nphysics_dt = 0.002", [], "sim.physics_dt"),
    ("physics step not dividing control", "[sim]\ncontrol_dt = 0.001\nphysics_dt = 0.0003", [], "sim.physics_dt"),
    ("duplicate edge", "[graph]\nedges = [[1, 2], [2, 1], [1, 3]]", [], "more than once"),
    ("out-of-range follower in edge", "[graph]\nedges = [[1, 2], [1, 7]]", [], "outside 1..3"),
    ("self-loop", "[graph]\nedges = [[1, 1], [1, 2], [1, 3]]", [], "self-loop"),
    ("disconnected graph", "[graph]\nedges = [[1, 2]]", [], "follower(s) 3 cannot reach"),
    ("no leader access", "[graph]\nleader_access = []", [], "no follower has leader access"),
    ("duplicate leader access id", "[graph]\nleader_access = [1, 1]", [], "more than once"),
    ("same formation slot", "[formation]\noffsets = [[3.0, 0.0], [4.0, 5.0], [3.0, 0.0]]", [], "same formation slot"),
    ("initial poses count mismatch", "[formation]\ninitial_poses = [[0.0, 0.0, 0.0]]", [], "formation.initial_poses"),
    (
        "offset with three numbers",
        "[formation]\noffsets = [[3.0, 0.0, 1.0], [4.0, 5.0], [4.0, -5.0]]",
        [],
        "formation.offsets[0]",
    ),
    ("unknown method in file", "method = 'pid'", [], "unknown method 'pid'"),
    ("unknown plant in file", "[plant]\nkind = 'gazebo'", [], "unknown plant 'gazebo'"),
    ("unknown trajectory", "[leader]\nkind = 'spiral'", [], "leader.kind"),
    ("leader that stops", "[leader]\nkind = 'harmonic'\nvx = 0.0", [], "leader"),
    ("unknown estimator init", "[estimator]\ninit = 'random'", [], "estimator.init"),
    ("event for a missing follower", "[[events]]\ntime = 1.0\nfollower = 9\nmass = 1.0", [], "events[0].follower"),
    ("event after the end", "[[events]]\ntime = 99.0\nfollower = 1\nmass = 1.0", [], "events[0].time"),
    ("unknown robot model", "[plant]\nrobots = ['tank']", ["--plant", "mujoco"], "unknown robot 'tank'"),
    (
        "missing model file",
        "[plant]\nrobots = ['/nonexistent/robot.xml']",
        ["--plant", "mujoco"],
        "/nonexistent/robot.xml",
    ),
    ("negative seed", "[sim]\nseed = -1", [], "sim.seed"),
    ("bool for float", "[torque]\ntau_max = true", [], "torque.tau_max"),
]
BAD += [  # faults (issue 6)
    ("failing link not in the graph", "[faults]\nlink_fail = [[2, 3, 1.0, 2.0]]", [], "faults.link_fail[0]"),
    ("link recovers before it fails", "[faults]\nlink_fail = [[1, 2, 2.0, 1.0]]", [], "t_fail < t_recover"),
    ("packet loss of one", "[faults]\npacket_loss = 1.0", [], "faults.packet_loss"),
    ("negative delay", "[faults]\ndelay = -0.1", [], "faults.delay"),
    ("pose noise with two numbers", "[faults]\nnoise_pose = [0.1, 0.1]", [], "faults.noise_pose"),
    ("actuator fault for a missing follower", "[faults]\nactuator = [[5, 1.0, 2.0, 0.5]]", [], "faults.actuator[0]"),
    ("push without duration", "[faults]\npush = [[1, 1.0, 0.0, 10.0, 0.0, 0.0]]", [], "faults.push[0]"),
    (
        "friction patch on the ideal plant",
        "[faults]\nfriction_patch = [0.0, 0.0, 1.0, 1.0, 0.1]",
        [],
        "faults.friction_patch",
    ),
    ("unknown fault key", "[faults]\nmeteor = 1.0", [], "faults.meteor"),
]

BAD += [  # issue 11: types anywhere, names, sizes beyond reason
    ("table given a number, then --duration", "sim = 3", ["--duration", "1"], "'sim': expected a table"),
    (
        "table given a string, then --set",
        "kinematic = 'x'",
        ["--set", "kinematic.k1=3"],
        "'kinematic': expected a table",
    ),
    ("array of tables given a number", "events = 3", [], "events"),
    ("array of tables given numbers", "events = [3]", [], "events[0]"),
    ("name not a string", "name = 3", [], "'name'"),
    ("description not a string", "description = [1]", [], "'description'"),
    ("method not a string", "method = 1.5", [], "'method'"),
    ("integer too large", "[sim]\nseed = 1e30", [], "sim.seed"),
    ("follower id too large", "[graph]\nleader_access = [99999999999999999999]", [], "graph.leader_access"),
    ("name with a path", "name = '../../x'", [], "plain file name"),
    ("absolute name", "name = '/tmp/x'", [], "plain file name"),
    ("name with a NUL", 'name = "a\\u0000b"', [], "'name'"),
    ("empty name", "name = ''", [], "is empty"),
    ("physics step 1e-300", "[sim]\nphysics_dt = 1e-300", [], "sim.physics_dt"),
    ("physics step 1e-12", "[sim]\nphysics_dt = 1e-12\ncontrol_dt = 1e-12", [], "sim.physics_dt"),
    ("duration beyond reason", "[sim]\nduration = 1e9", [], "1e+12 steps"),
    ("log beyond reason", "[sim]\nduration = 3e4\nlog_dt = 0.001", [], "GB of log"),
    (
        "physics steps beyond reason",
        "[sim]\nduration = 5e4\nphysics_dt = 1e-5\ncontrol_dt = 1e-3\nlog_dt = 1.0",
        [],
        "physics steps",
    ),
]


@pytest.mark.parametrize("desc,text,argv,needle", BAD, ids=[b[0] for b in BAD])
def test_bad_scenario_file(desc, text, argv, needle, tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    out = tmp_path / "out"
    dur = [] if "duration" in text else ["--duration", "0.05"]
    code = main(["run", str(path), *dur, "--out", str(out), *argv])
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("error:") and needle in lines[0], err
    assert "Traceback" not in err
    assert not out.exists()


def test_unreadable_scenario_file(tmp_path, capsys, monkeypatch):
    """PermissionError (root reads everything, so the refusal is simulated) is bad input, not a crash."""
    from pathlib import Path

    path = tmp_path / "locked.toml"
    path.write_text("[sim]\nduration = 1.0\n")
    real = Path.read_bytes

    def refuse(self):
        if self.name == "locked.toml":
            raise PermissionError(13, "Permission denied", str(self))
        return real(self)

    monkeypatch.setattr(Path, "read_bytes", refuse)
    out = tmp_path / "o"
    code = main(["run", str(path), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error:") and "cannot be read: Permission denied" in err
    assert err.count("\n") == 1 and not out.exists()


def test_scenario_that_is_a_directory(tmp_path, capsys):
    d = tmp_path / "dir.toml"
    d.mkdir()
    assert main(["run", str(d), "--out", str(tmp_path / "o")]) == 2
    assert "is a directory" in capsys.readouterr().err


def _leaf_keys(cls=None, prefix=""):
    import dataclasses
    import typing

    from bioform_mj.scenario.config import Scenario

    cls = cls or Scenario
    for name, tp in typing.get_type_hints(cls).items():
        if dataclasses.is_dataclass(tp):
            yield prefix + name, True
            yield from _leaf_keys(tp, prefix + name + ".")
        else:
            yield prefix + name, False


WRONG = ["x", 3, -1, 2.5, True, [1, 2], [[1, 2], [3, 4]], {"a": 1}, [], 1e300, 10**30, [{"a": 1}]]


@pytest.mark.parametrize("key,is_table", list(_leaf_keys()), ids=[k for k, _ in _leaf_keys()])
def test_any_type_anywhere_loads_or_is_refused(key, is_table):
    """Every key of a scenario, given values of every type: a Scenario or an InputError, never another
    exception (a TypeError would be exit 1). Tables also get a scalar then a key below them."""
    from bioform_mj.core.errors import InputError
    from bioform_mj.scenario.loader import load

    for value in WRONG:
        overrides = {key: value}
        if is_table:
            overrides = {key: value, f"{key}.x": 1}
        try:
            load("paper", overrides)
        except InputError:
            pass
        if is_table:
            try:
                load("paper", {key: value})
            except InputError:
                pass


# ---- fuzz: any generated scenario runs or exits 2 cleanly ------------------------------------
_num = st.one_of(st.floats(-50, 50), st.just(0.0), st.just(float("nan")), st.integers(-3, 30))
_vec = lambda k: st.lists(_num, min_size=k - 1, max_size=k + 1)  # noqa: E731

FUZZ = st.fixed_dictionaries(
    {},
    optional={
        "kinematic": st.fixed_dictionaries({}, optional={"k1": _num, "k2": _num, "A": _num, "B": _num}),
        "estimator": st.fixed_dictionaries(
            {},
            optional={
                "kp": _vec(3),
                "ka": _vec(2),
                "phi": _vec(2),
                "init": st.sampled_from(["zero", "self", "leader", "x"]),
            },
        ),
        "torque": st.fixed_dictionaries({}, optional={"c": _vec(2), "phi": _num, "tau_max": _num}),
        "learner": st.fixed_dictionaries({}, optional={"k4": _vec(2), "k5": _vec(2), "c_hat0_scale": _vec(2)}),
        "graph": st.fixed_dictionaries(
            {},
            optional={
                "kind": st.sampled_from(["explicit", "chain", "ring", "star", "complete", "mesh"]),
                "edges": st.lists(st.lists(st.integers(0, 4), min_size=2, max_size=2), max_size=4),
                "leader_access": st.lists(st.integers(0, 4), max_size=3),
            },
        ),
        "sim": st.fixed_dictionaries(
            {},
            optional={
                "control_dt": st.sampled_from([0.001, 0.002, -0.001, 0.0]),
                "physics_dt": st.sampled_from([0.001, 0.0005, 0.003]),
            },
        ),
        "leader": st.fixed_dictionaries(
            {},
            optional={
                "kind": st.sampled_from(["paper", "line", "circle", "figure8", "x"]),
                "speed": _num,
                "radius": _num,
            },
        ),
    },
)


def _toml(d, prefix=""):
    out = []
    for k, v in d.items():
        if isinstance(v, dict):
            out.append(f"[{k}]")
            for kk, vv in v.items():
                out.append(f"{kk} = {_val(vv)}")
    return "\n".join(out) + "\n"


def _val(v):
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, float) and np.isnan(v):
        return "nan"
    if isinstance(v, list):
        return "[" + ", ".join(_val(x) for x in v) + "]"
    return repr(v)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(FUZZ)
def test_fuzzed_scenarios_run_or_fail_cleanly(tmp_path, capsys, data):
    text = _toml(data)
    tomllib.loads(text)  # the generator itself writes valid TOML
    path = tmp_path / "fuzz.toml"
    path.write_text(text)
    out = tmp_path / "o"
    code = main(["run", str(path), "--duration", "0.02", "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code in (0, 2, 3), err
    assert "Traceback" not in err
    if code == 2:
        assert err.startswith("error:") and err.count("\n") == 1
    else:
        assert json.loads((out / "summary.json").read_text())["steps"] > 0


def test_sigkill_mid_write_leaves_the_old_file_or_the_new_one_never_a_partial_one(tmp_path):
    """A process rewrites a large log.npz again and again (each version a different size) and is
    SIGKILLed at several moments: the real name always holds one complete version, and the
    kills must land mid-write at least once (a temporary file left behind), or the test proves
    nothing."""
    out = tmp_path / "log.npz"
    code = (
        "import sys, numpy as np\n"
        "from bioform_mj.outputs.files import write_npz\n"
        "k = 0\n"
        "while True:\n"
        "    k += 1\n"
        "    write_npz(sys.argv[1], {'pose': np.full(2_000_000 + 1000 * k, float(k))})\n"
        "    print(k, flush=True)\n"
    )
    mid_write = 0
    for delay in (0.5, 0.9, 1.3, 1.7, 2.1, 2.5):
        proc = subprocess.Popen(
            [sys.executable, "-c", code, str(out)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True
        )
        proc.stdout.readline()  # one version is complete: the kill lands in a later write
        time.sleep(delay % 0.4)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        with np.load(out) as z:  # complete: loads, and its content is one version, whole
            x = z["pose"]
            k = int(x[0])
            assert k >= 1 and x.shape == (2_000_000 + 1000 * k,) and np.all(x == k)
        tmp = [f for f in tmp_path.iterdir() if f.name.startswith(".")]
        mid_write += bool(tmp)
        for f in tmp:
            f.unlink()
    assert mid_write >= 1, "no kill landed mid-write"


def test_sigkill_mid_sweep_then_resume(tmp_path):
    """Kill a sweep after some runs finished; rerunning keeps their rows and runs only the rest."""
    out = tmp_path / "sw"
    cmd = [
        sys.executable,
        "-m",
        "bioform_mj.cli",
        "sweep",
        "paper",
        "--seeds",
        "6",
        "--workers",
        "1",
        "--quiet",
        "--set",
        "sim.duration=40",
        "--out",
        str(out),
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    runs = out / "runs"
    deadline = time.time() + 120
    while time.time() < deadline and len(list(runs.glob("*.json")) if runs.exists() else []) < 2:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    finished = {f.name: f.stat().st_mtime_ns for f in runs.glob("*.json")}
    assert 2 <= len(finished) < 6, "the kill should land mid-sweep"
    for f in runs.glob("*.json"):
        assert json.loads(f.read_text())["status"] == "ok"  # complete rows only
    assert not (out / "runs.csv").exists()
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert {f.name: f.stat().st_mtime_ns for f in runs.glob("*.json") if f.name in finished} == finished
    import csv

    rows = list(csv.DictReader((out / "runs.csv").open()))
    assert len(rows) == 6 and {r["seed"] for r in rows} == {str(i) for i in range(6)}
    timing = json.loads((out / "sweep.json").read_text())
    assert timing["ran"] == 6 - len(finished) and timing["skipped"] == len(finished)

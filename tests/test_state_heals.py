"""State that heals (issue 28 item 3): a robot-check cache entry of the wrong shape is ignored and
rewritten with one warning naming the file, never an internal error."""

from __future__ import annotations

import json
import os
import warnings

import pytest

from bioform_mj.assess import prerun
from bioform_mj.assess.cache_schema import entry_problem
from bioform_mj.core.errors import RobotWarning

GOOD = {
    "format": prerun.CACHE_FORMAT,
    "verdict": "pass",
    "fail_reasons": [],
    "cause": None,
    "formula": {"a": 1.0, "b": 2.0},
    "identified": {"a": 1.0, "b": None},
    "relative_error": {"a": 0.0, "b": None},
    "resistances": [],
    "seconds": 0.5,
}


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """An empty cache and memo; the check itself a stand-in that counts its calls."""
    monkeypatch.setenv(prerun.CACHE_ENV, str(tmp_path / "cache"))
    monkeypatch.setattr(prerun, "_MEMO", {})
    calls = []
    monkeypatch.setattr(prerun, "_check", lambda ref, *_a, **_k: calls.append(ref) or dict(GOOD))
    (tmp_path / "cache" / "robot-check").mkdir(parents=True)
    return tmp_path / "cache" / "robot-check", calls


BAD = [
    ("missing keys", {"format": prerun.CACHE_FORMAT, "verdict": "pass"}),
    ("wrong verdict", {**GOOD, "verdict": "great"}),
    ("reasons not a list", {**GOOD, "fail_reasons": "x"}),
    ("formula of strings", {**GOOD, "formula": {"a": "1", "b": 2}}),
    ("a list", [1, 2]),
    ("cause of the wrong shape", {**GOOD, "cause": {"kind": 1}}),
]


@pytest.mark.parametrize("desc,entry", BAD, ids=[b[0] for b in BAD])
def test_wrong_shape_ignored_rewritten_and_said_once(desc, entry, cache):
    folder, calls = cache
    path = folder / "k.json"
    path.write_text(json.dumps(entry))
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        out = prerun.cached_check("ref", "k")
    said = [str(w.message) for w in got if issubclass(w.category, RobotWarning)]
    assert len(said) == 1 and str(path) in said[0] and "ignored and rewritten" in said[0], said
    assert out["verdict"] == "pass" and out["from"] == "computed" and len(calls) == 1
    assert entry_problem(json.loads(path.read_text()), prerun.CACHE_FORMAT) == ""
    prerun._MEMO.clear()
    with warnings.catch_warnings(record=True) as got:  # healed: read from disk, nothing said
        warnings.simplefilter("always")
        assert prerun.cached_check("ref", "k")["from"] == "disk"
    assert not [w for w in got if issubclass(w.category, RobotWarning)] and len(calls) == 1


def test_broken_json_and_a_fifo_heal_too(cache):
    folder, calls = cache
    (folder / "j.json").write_text("{not json")
    os.mkfifo(folder / "f.json")
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        assert prerun.cached_check("ref", "j")["verdict"] == "pass"
        assert prerun.cached_check("ref", "f")["verdict"] == "pass"  # a FIFO is never opened (it would block)
    said = [str(w.message) for w in got if issubclass(w.category, RobotWarning)]
    assert len(said) == 2 and "unreadable" in said[0] and "FIFO" in said[1], said


def test_good_entry_passes_the_schema():
    assert entry_problem(GOOD, prerun.CACHE_FORMAT) == ""
    assert "format" in entry_problem({**GOOD, "format": 0}, prerun.CACHE_FORMAT)


# ------------------------------------------------------------------ environments and batches
def test_parallel_env_is_freed_when_dropped():
    """No cache on the space methods keeps an environment alive (each held ~6 MB, issue 28)."""
    import gc
    import weakref

    pytest.importorskip("pettingzoo")
    from bioform_mj.envs import parallel_env

    env = parallel_env("paper")
    agent = env.possible_agents[0]
    assert env.observation_space(agent) is env.observation_space(agent)  # one space object per agent
    assert env.action_space(agent) is env.action_space(agent)
    env.reset(seed=0)
    env.step({a: env.action_space(a).sample() * 0 for a in env.agents})
    env.close()
    ref = weakref.ref(env)
    del env
    gc.collect()
    assert ref() is None


@pytest.mark.parametrize(
    "kw,needle",
    [({"worlds": 10**9}, "GiB estimated"), ({"worlds": 1, "nconmax": 10**12}, "nconmax/njmax"), ({"njmax": 0}, ">= 1")],
)
def test_batch_env_estimates_memory_before_allocating(kw, needle):
    """worlds, nconmax and njmax all enter the estimate, before the seed list or any array."""
    import time

    from bioform_mj.envs import batch_env

    t0 = time.monotonic()
    with pytest.raises(ValueError, match=needle):
        batch_env("paper", device="cpu", **kw)
    assert time.monotonic() - t0 < 30


# ------------------------------------------------------------------ provenance: every file a robot loads
def test_provenance_hashes_package_meshes_and_xacro_includes(tmp_path):
    """A sweep whose robot's package:// mesh (or xacro include) changed is redone (it resumed as done)."""
    import bioform_mj
    from bioform_mj.jobs.provenance import differences, provenance
    from test_robots_urdf import _package, box_stl, write

    pkg, urdf = _package(tmp_path)
    write(tmp_path / "robot" / "dd.urdf", urdf)
    toml = '[plant]\nkind = "mujoco"\nrobots = [{model = "robot/dd.urdf", package_path = {ddpkg = "ws/src/ddpkg"}}]\n'
    sc = bioform_mj.load(str(write(tmp_path / "s.toml", toml)))
    before = provenance(sc)
    mesh = str((pkg / "meshes" / "chassis.stl").resolve())
    assert before["files"].get(mesh) not in (None, "missing"), before["files"]
    box_stl(pkg / "meshes" / "chassis.stl", 0.15, 0.1, 0.03)  # the mesh changes
    assert any("robot file changed" in w and "chassis.stl" in w for w in differences(before, provenance(sc)))

    pytest.importorskip("xacro")
    ns = 'xmlns:xacro="http://ros.org/wiki/xacro"'
    write(pkg / "urdf" / "part.xacro", f'<robot {ns}><xacro:property name="mc" value="2.0"/></robot>')
    text = urdf.replace(
        '<robot name="dd">', f'<robot name="dd" {ns}><xacro:include filename="$(find ddpkg)/urdf/part.xacro"/>'
    )
    write(pkg / "urdf" / "dd.urdf.xacro", text)
    toml = '[plant]\nkind = "mujoco"\nrobots = [{model = "ws/src/ddpkg/urdf/dd.urdf.xacro", xacro = true}]\n'
    sc = bioform_mj.load(str(write(tmp_path / "x.toml", toml)))
    before = provenance(sc)
    part = str((pkg / "urdf" / "part.xacro").resolve())
    assert before["files"].get(part) not in (None, "missing"), before["files"]
    write(pkg / "urdf" / "part.xacro", f'<robot {ns}><xacro:property name="mc" value="3.0"/></robot>')
    assert any("part.xacro" in w for w in differences(before, provenance(sc)))


# ------------------------------------------------------------------ a file-size limit (or a full disk) with --rrd
def test_rrd_past_a_file_size_limit_is_one_error_line_no_tmp_no_lock(tmp_path):
    """``ulimit -f`` below run.rrd's size: one ``error:`` line naming the file (it was an internal error from
    rerun's writer thread), no ``.tmp``, no lock; what was written before is kept and said."""
    import resource
    import subprocess
    import sys
    from pathlib import Path

    out = tmp_path / "r"
    src = str(Path(__file__).resolve().parents[1] / "src")
    res = subprocess.run(
        [sys.executable, "-m", "bioform_mj.cli", "run", "paper", "--plant", "ideal", "--duration", "5"]
        + ["--rrd", "--out", str(out), "--quiet"],
        preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (700_000, 700_000)),  # log.npz ~0.5 MB fits
        env={**os.environ, "PYTHONPATH": src},
        capture_output=True,
        text=True,
        timeout=300,
    )
    err = [line for line in res.stderr.splitlines() if line.strip()]
    assert res.returncode != 0 and len(err) == 1, res.stderr
    assert err[0].startswith("error: cannot write") and "run.rrd" in err[0] and "File too large" in err[0], err
    left = sorted(p.name for p in out.iterdir())
    assert not [n for n in left if n.endswith(".tmp") or n == ".bioform.lock"] and "run.rrd" not in left, left


# ------------------------------------------------------------------ a user's controller gets read-only views
class _Scribbler:
    """The paper's stack, writing into the arrays it is handed (``what``: pose, vel, leader_pose)."""

    def __init__(self, sc, what: str) -> None:
        import numpy as np

        from bioform_mj.control.params import stack_params
        from bioform_mj.control.stack import ControlStack

        self.inner = ControlStack(sc.build_graph(), stack_params(sc, np.array(sc.plant.c_true)))
        self.what = what

    def reset(self, est_pose0, vel0):
        self.inner.reset(est_pose0, vel0)

    def step(self, leader_pose, leader_vel, pose, vel, comm=None):
        tau = self.inner.step(leader_pose, leader_vel, pose, vel)
        if self.what != "none":
            {"pose": pose, "vel": vel, "leader_pose": leader_pose}[self.what][...] = 0.0
        return tau

    def signals(self):
        return self.inner.signals()


@pytest.mark.parametrize("what", ["pose", "vel", "leader_pose"])
def test_a_controller_cannot_write_into_what_it_is_handed(what):
    """Writing into ``pose`` silently changed the logged trajectory and the metrics (issue 28): now it raises,
    named, at the first step; a controller that only reads runs as the package's own stack does."""
    import numpy as np

    import bioform_mj as bf

    sc = bf.load("paper", ["sim.duration=0.2"], plant="ideal")
    with pytest.raises(ValueError, match="read-only") as info:
        bf.simulate(sc, controller=_Scribbler(sc, what))
    assert info.value.result.summary["raised"]["step"] == 0
    reader = bf.simulate(sc, controller=_Scribbler(sc, "none"))
    assert np.array_equal(reader.log["pose"], bf.simulate(sc).log["pose"])


# ------------------------------------------------------------------ the Python API: nothing in the caller's folder
def test_api_turns_mujoco_warnings_into_python_warnings(tmp_path, monkeypatch):
    """``bioform_mj.simulate`` wrote MUJOCO_LOG.TXT into the caller's folder (MuJoCo's default handler)."""
    import mujoco

    import bioform_mj
    from bioform_mj.outputs.mjlog import api_warnings

    assert getattr(bioform_mj.simulate, "__wrapped__", None) is not None  # simulate carries the handler

    @api_warnings
    def noisy(sc=None):
        m = mujoco.MjModel.from_xml_string(
            "<mujoco><worldbody><body><freejoint/><geom size='.1'/></body></worldbody></mujoco>"
        )
        d = mujoco.MjData(m)
        d.qvel[:] = 1e20
        mujoco.mj_step(m, d)  # "Nan, Inf or huge value in QVEL"
        return "done"

    monkeypatch.chdir(tmp_path)
    assert mujoco.get_mju_user_warning() is None
    with pytest.warns(RuntimeWarning, match="MuJoCo: .*QVEL"):
        assert noisy() == "done"
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
    assert mujoco.get_mju_user_warning() is None  # MuJoCo's own handler is back


def test_rrd_write_interrupted_leaves_no_tmp(tmp_path, monkeypatch):
    """SIGINT/SIGTERM (a KeyboardInterrupt from the CLI's handler) between run.rrd's writes: the temporary
    file is removed, run.rrd is absent, the interrupt goes on."""
    import builtins

    import bioform_mj as bf
    from bioform_mj.outputs import rerun_log

    res = bf.simulate(bf.load("paper", ["sim.duration=2.0"], plant="ideal"))
    monkeypatch.setattr(rerun_log, "_WRITE_CHUNK", 4096)
    real_open = builtins.open
    writes = []

    class Interrupting:
        def __init__(self, fh):
            self.fh = fh

        def write(self, data):
            writes.append(len(data))
            if len(writes) == 3:
                raise KeyboardInterrupt
            return self.fh.write(data)

        def __getattr__(self, name):
            return getattr(self.fh, name)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

    def fake_open(file, mode="r", *a, **k):
        fh = real_open(file, mode, *a, **k)
        return Interrupting(fh) if "w" in mode and str(file).endswith(".tmp") else fh

    monkeypatch.setattr(builtins, "open", fake_open)
    with pytest.raises(KeyboardInterrupt):
        rerun_log.write_rrd(res, tmp_path / "run.rrd")
    monkeypatch.setattr(builtins, "open", real_open)
    assert len(writes) == 3 and sorted(p.name for p in tmp_path.iterdir()) == [], list(tmp_path.iterdir())

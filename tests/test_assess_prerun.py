"""Issue 18 item 6: ``bioform run`` warns, before any work, what ``robot check`` fails (design §14.2).

A robot built here from the shipped paper robot with a rear caster that brakes (the floor's friction,
22 % of the weight: ``robot check`` fails it) runs with a ``warning:`` naming the failed check and the
cause before the run, and ``summary.json`` holds it; the shipped robots do not warn; the check is
done once per robot (in the process, then from the disk cache); ``--no-robot-check`` skips it. A
run's braking casters are named and chosen as ``robot check`` names and chooses them.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from bioform_mj.assess import prerun
from bioform_mj.assess.check import check
from bioform_mj.cli import main as cli
from bioform_mj.robots.refs import models_dir
from bioform_mj.scenario.loader import load

PAPER = (models_dir() / "paper_robot.xml").read_text()


def _braking(tmp_path: Path, name: str = "caster", unnamed: bool = False) -> str:
    """The paper robot with its rear caster at the floor's friction, 3 cm of centre of mass behind the
    axle: the caster carries 23.5 g · 0.03 / 0.13 = 53.2 N and brakes (test_verdict's robot)."""
    edits = [
        ('condim="1" priority="2" friction="0 0 0"', 'condim="3" friction="1 0.005 0.0001"'),
        ('pos="-0.13 0 -0.0745"', 'pos="-0.13 0 -0.0755"'),
        ('<inertial pos="0 0 0" mass="23.5"', '<inertial pos="-0.03 0 0" mass="23.5"'),
    ] + ([('name="back_caster" ', "")] if unnamed else [])
    text = PAPER
    for old, new in edits:
        assert old in text, old  # each edit finds its place: a changed paper robot would make another robot
        text = text.replace(old, new)
    assert text.count("friction=") and text != PAPER and (not unnamed or "back_caster" not in text)
    p = tmp_path / f"{name}.xml"
    p.write_text(text)
    return str(p)


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch):
    """An empty disk cache and memo, the check not skipped."""
    monkeypatch.setenv(prerun.CACHE_ENV, str(tmp_path / "cache"))
    monkeypatch.delenv(prerun.SKIP_ENV, raising=False)
    monkeypatch.setattr(prerun, "_MEMO", {})
    return tmp_path / "cache"


def _run(tmp_path: Path, robot: str, *flags: str, out: str = "run") -> tuple[int, Path]:
    o = tmp_path / out
    sets = ["--set", "plant.kind=mujoco", "--set", f'plant.robots=[{{model="{robot}"}}]']
    code = cli.main(["run", "paper", *sets, "--set", "sim.duration=0.1", "--quiet", "--out", str(o), *flags])
    return code, o


def test_run_warns_before_the_run_what_robot_check_fails_and_checks_once(tmp_path, capsys, fresh_cache):
    path = _braking(tmp_path)
    rep = check(path)  # the reference: robot check's own verdict
    assert rep["verdict"] == "fail" and rep["cause"]["kind"] == "braking_caster"
    n0 = prerun.COMPUTED[0]
    capsys.readouterr()
    code, out = _run(tmp_path, path)
    err = capsys.readouterr().err.splitlines()
    assert code == 0  # a warning, not a refusal: the run goes ahead
    mine = [i for i, ln in enumerate(err) if ln.startswith("warning: followers 1, 2, 3: robot check fails")]
    assert len(mine) == len(rep["fail_reasons"]) >= 1, err
    assert all(f"'{path}'" in err[i] for i in mine)
    assert any("back_caster" in err[i] for i in mine)  # the named cause
    # before the run: ahead of every outcome of the run and of the hardware verdict
    summary = json.loads((out / "summary.json").read_text())
    ends = [f"warning: follower {f['id']}: {o['kind']} (" for f in summary["followers"] for o in f["outcomes"]]
    after = [i for i, ln in enumerate(err) if ln.startswith(("warning: hardware", *ends))]
    assert after and max(mine) < min(after), err
    s = summary["robot_check"]
    assert s["skipped"] is False and len(s["robots"]) == 1
    r = s["robots"][0]
    assert r["followers"] == [1, 2, 3] and r["verdict"] == "fail"
    assert not set(prerun.VOLATILE) & (set(r) | set(s))  # the summary is the same bit for bit for the same seed
    assert r["fail_reasons"] == rep["fail_reasons"] and r["cause"]["kind"] == "braking_caster"
    # the same deterministic check: here a, b cannot be identified at all (the caster stops the robot)
    assert r["relative_error"] == rep["relative_error"] and r["identified"] == {"a": rep["a_identified"], "b": None}
    assert any(w.startswith("cannot identify a, b: braking_caster") for w in r["fail_reasons"])
    assert r["formula"]["a"] == pytest.approx(rep["a_eff"], rel=1e-12)
    # summary.json names the robot's file relative to the run's folder (no absolute path; outputs/summary_paths.py)
    rel = os.path.relpath(path, out.resolve())
    assert all(f"'{rel}'" in w and str(tmp_path) not in w for w in s["warnings"])
    assert len(s["warnings"]) == len(mine) and all(
        w.replace(f"'{rel}'", f"'{path}'") in err[i] for w, i in zip(s["warnings"], mine)
    )
    assert prerun.COMPUTED[0] == n0 + 1
    assert len(list((fresh_cache / "robot-check").glob("*.json"))) == 1
    # a second run in the process: remembered; a new process (memo cleared): from disk; never recomputed
    _run(tmp_path, path, "--overwrite")
    assert json.loads((out / "summary.json").read_text())["robot_check"] == s  # remembered: not computed again
    assert prerun.COMPUTED[0] == n0 + 1
    prerun._MEMO.clear()
    other = tmp_path / "elsewhere"  # the same content at another path: the same robot
    other.mkdir()
    moved = _braking(other)
    _run(tmp_path, moved, "--overwrite")
    s2 = json.loads((out / "summary.json").read_text())["robot_check"]
    assert s2["robots"][0]["fail_reasons"] == rep["fail_reasons"]
    assert prerun.COMPUTED[0] == n0 + 1  # the memo cleared and nothing computed: read from disk


def test_a_mapping_that_fixes_the_caster_is_another_robot_and_does_not_warn(tmp_path, fresh_cache):
    path = _braking(tmp_path)
    n0 = prerun.COMPUTED[0]
    sc = load("paper", overrides=["plant.kind=mujoco", f'plant.robots=[{{model="{path}", caster_friction=0.0}}]'])
    from bioform_mj.run.simulate import make_plant

    res = prerun.before_run(sc, make_plant(sc))
    assert prerun.COMPUTED[0] == n0 + 1
    r = res["robots"][0]
    assert r["verdict"] != "fail" and res["warnings"] == [] and r["fail_reasons"] == []
    assert abs(r["relative_error"]["a"]) < 0.03 and abs(r["relative_error"]["b"]) < 0.03


@pytest.mark.parametrize("preset, robot", [("paper", "paper"), ("tb3", "tb3")])
def test_shipped_robots_do_not_warn(preset, robot, fresh_cache):
    from bioform_mj.run.simulate import make_plant

    sc = load(preset, overrides=["plant.kind=mujoco", f'plant.robots=["{robot}"]'])
    res = prerun.before_run(sc, make_plant(sc))
    (r,) = res["robots"]
    assert r["verdict"] in ("pass", "warn") and res["warnings"] == [] and r["from"] == "computed"
    assert abs(r["relative_error"]["a"]) < 0.01 and abs(r["relative_error"]["b"]) < 0.01
    assert r["followers"] == list(range(1, sc.n + 1))
    assert res["seconds"] < 10.0  # robot check's bound per robot (issue 18); measured 0.35-0.45 s


def test_no_robot_check_skips_it(tmp_path, capsys, fresh_cache, monkeypatch):
    path = _braking(tmp_path)
    n0 = prerun.COMPUTED[0]
    capsys.readouterr()
    code, out = _run(tmp_path, path, "--no-robot-check")
    monkeypatch.delenv(prerun.SKIP_ENV, raising=False)  # the flag set it for this process
    err = capsys.readouterr().err
    assert code == 0 and "robot check fails" not in err
    s = json.loads((out / "summary.json").read_text())["robot_check"]
    assert s["skipped"] is True and s["robots"] == [] and prerun.COMPUTED[0] == n0
    assert not fresh_cache.exists()
    monkeypatch.setenv(prerun.SKIP_ENV, "0")  # "0" does not skip
    assert not prerun.skipped()
    assert os.environ[prerun.SKIP_ENV] == "0"


def test_a_runs_braking_caster_is_labelled_and_chosen_as_robot_check_does(tmp_path):
    """Was: an unnamed caster was '#52' in a follower's outcome, and a run's threshold (1 % of the
    weight) was not robot check's (0.5 %): Fetch Freight's 7.8 N of 790 N was 'none the plant knows'."""
    from bioform_mj.assess.outcomes import braking_casters, unmodelled_causes
    from bioform_mj.robots.contacts import brakes
    from bioform_mj.run.simulate import make_plant

    path = _braking(tmp_path, "unnamed", unnamed=True)
    rep = check(path)
    braking = [c["geom"] for c in rep["floor_contacts"] if brakes(c)]
    assert len(braking) == 1 and braking[0].startswith("base#")  # body name + geom index, as robot check says
    sc = load("paper", overrides=["plant.kind=mujoco", f'plant.robots=[{{model="{path}"}}]'])
    plant = make_plant(sc)
    plant.reset()
    for k in range(200):  # 0.2 s at rest, as robot check settles
        plant.step(np.zeros((sc.n, 2)), k * plant.control_dt)
    assert [braking_casters(plant, i) for i in range(sc.n)] == [braking] * sc.n
    assert f"caster '{braking[0]}' braking" in unmodelled_causes(None, casters=braking_casters(plant, 0))


def test_a_check_that_breaks_is_a_warning_not_a_failed_run(tmp_path, fresh_cache, monkeypatch):
    import bioform_mj.assess.check as rc
    from bioform_mj.run.simulate import make_plant

    def broken(*a, **k):
        raise RuntimeError("boom")

    monkeypatch.setattr(rc, "check", broken)
    sc = load("paper", overrides=["plant.kind=mujoco"])
    res = prerun.before_run(sc, make_plant(sc))
    assert res["robots"][0]["verdict"] == "error" and "RuntimeError: boom" in res["robots"][0]["error"]
    assert len(res["warnings"]) == 1 and "robot check cannot check" in res["warnings"][0]
    assert not (fresh_cache / "robot-check").exists()  # an error is not cached


def test_simulate_and_a_sweep_row_say_it(tmp_path, fresh_cache):
    """The Python API warns it (a RobotWarning before the run) and a sweep's row has the column."""
    from bioform_mj.core.errors import RobotWarning
    from bioform_mj.jobs.sweep import expand, run_one
    from bioform_mj.run.simulate import simulate

    path = _braking(tmp_path)
    sets = ["plant.kind=mujoco", f'plant.robots=[{{model="{path}"}}]', "sim.duration=0.05"]
    with pytest.warns(RobotWarning, match=r"followers 1, 2, 3: robot check fails .*back_caster"):
        res = simulate(load("paper", overrides=sets))
    r = res.summary["robot_check"]["robots"][0]
    assert r["verdict"] == "fail"
    n0 = prerun.COMPUTED[0]
    with pytest.warns(RobotWarning):
        row = run_one(expand("paper", 1, ["bioinspired"], [], sets, plant="mujoco")[0])
    assert row["status"] == "ok" and row["robot_check"] == "fail: " + "; ".join(r["fail_reasons"])
    assert prerun.COMPUTED[0] == n0  # the sweep's run took it from memory
    row = run_one(expand("paper", 1, ["bioinspired"], [], sets[2:], plant="mujoco")[0])
    assert row["robot_check"] == "pass"  # the paper robot


def test_an_identification_off_the_formula_is_warned_with_its_size_and_cause(fresh_cache):
    """The paper robot mapped with wheel_radius 0.14 m (its wheels are 0.1 m): the formula takes the
    mapped radius, the physics the wheels': robot check fails it, cause ``mapping``."""
    from bioform_mj.robots.entries import resolve_robot
    from bioform_mj.robots.refs import RobotRef
    from bioform_mj.run.simulate import make_plant

    sc = load("paper", overrides=["plant.kind=mujoco", 'plant.robots=[{model="paper", wheel_radius=0.14}]'])
    res = prerun.before_run(sc, make_plant(sc))
    rep = check(resolve_robot(RobotRef("paper", wheel_radius=0.14)))
    (r,) = res["robots"]
    worst = max(abs(rep["relative_error"]["a"]), abs(rep["relative_error"]["b"]))
    assert worst > 0.10 and r["relative_error"] == pytest.approx(rep["relative_error"], rel=1e-9)
    (line,) = [w for w in res["warnings"] if "identification differs" in w]
    assert f"by {100 * worst:.1f} % (> 10 %); cause mapping" in line and "followers 1, 2, 3" in line

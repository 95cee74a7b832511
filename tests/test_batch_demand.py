"""Issue 27 item 4: the batch engine checks the scenario's demand before its worlds run, as a single run does
(design §21): the same ``warning:`` lines, once per distinct scenario (worlds that differ by their seed are one), and
each world's summary gets the single run's ``demand``."""

from __future__ import annotations

import warnings

import pytest

from bioform_mj.assess import prerun
from bioform_mj.batch.demand_check import _ranges, scenario_key
from bioform_mj.core.errors import RobotWarning
from bioform_mj.scenario.loader import load

#: the paper robot told a top speed of 0.1 m/s: the paper scenario's wheels ask several times that (warned)
SLOW = ["plant.kind=mujoco", "sim.duration=0.2", 'plant.robots=[{model = "paper", top_speed = 0.1}]']


def test_worlds_that_differ_by_seed_are_one_scenario():
    a, b = load("paper", SLOW + ["sim.seed=0"]), load("paper", SLOW + ["sim.seed=7"])
    c = load("paper", SLOW + ["kinematic.k1=3"])
    assert scenario_key(a) == scenario_key(b) != scenario_key(c)
    assert _ranges([0, 1, 2, 5, 7, 8]) == "0-2, 5, 7-8" and _ranges([3]) == "3"


@pytest.mark.slow
def test_a_batch_warns_the_demand_once_per_scenario_and_keeps_it_per_world(tmp_path, monkeypatch):
    pytest.importorskip("warp")
    pytest.importorskip("mujoco_warp")
    from bioform_mj.batch.runner import run_batch
    from bioform_mj.run import demand
    from bioform_mj.run.simulate import simulate

    monkeypatch.setenv(prerun.CACHE_ENV, str(tmp_path / "cache"))
    monkeypatch.delenv(prerun.SKIP_ENV, raising=False)
    calls = []
    real = demand.before_run
    monkeypatch.setattr(demand, "before_run", lambda *a, **k: calls.append(a[0].sim.seed) or real(*a, **k))
    scs = [load("paper", SLOW + [f"sim.seed={s}"]) for s in (0, 1)]
    with warnings.catch_warnings(record=True) as single:
        warnings.simplefilter("always")
        one = simulate(scs[0]).summary
    said = [str(w.message) for w in single if issubclass(w.category, RobotWarning)]
    assert one["demand"]["warnings"] and all(said.count(s) == 1 for s in one["demand"]["warnings"])
    assert any("peak wheel ground speed" in s and "top speed (mapping)" in s for s in one["demand"]["warnings"])
    calls.clear()
    with warnings.catch_warnings(record=True) as batch:
        warnings.simplefilter("always")
        out = run_batch(scs)
    assert calls == [0]  # one twin for the two seeds
    lines = [str(w.message) for w in batch if issubclass(w.category, RobotWarning)]
    for s in one["demand"]["warnings"]:
        assert lines.count(s) == 1, (s, lines)  # the single run's line, said once, not per world
    for world in out:
        assert world["demand"] == one["demand"]  # the same comparison, the same numbers

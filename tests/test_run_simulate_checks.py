"""``simulate`` on a scenario changed in Python (checked as ``load`` checks a file, its scale applied)
and its :class:`~bioform_mj.OutcomeWarning` per follower that did not end ``ok`` (design §18.1)."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

import bioform_mj as bf
from bioform_mj.core.errors import InputError, OutcomeWarning, ScenarioError

SHORT = ["sim.duration=0.2"]
#: backstepping beyond a speed limit of 0.05 m/s: diverges at the first step, every follower lost (ideal plant)
DIVERGES = ["sim.duration=0.5", "limits.speed=0.05"]


def _outcome_warnings(fn):
    """``(result, [OutcomeWarning, ...])`` of ``fn()``, every warning kept (no once-per-place filter)."""
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        res = fn()
    return res, [w.message for w in got if issubclass(w.category, OutcomeWarning)]


def _replaced(sc, table: str, **changes):
    return dataclasses.replace(sc, **{table: dataclasses.replace(getattr(sc, table), **changes)})


# ---- the scenario is checked as load checks a file --------------------------------------------------


@pytest.mark.parametrize(
    "table,changes,key,value",
    [
        ("kinematic", {"k1": float("nan")}, "kinematic.k1", "nan"),  # from_dict's finite-number check
        ("torque", {"c": (float("inf"), 3.0)}, "torque.c", "[inf, 3.0]"),
        ("kinematic", {"k2": "two"}, "kinematic.k2", "'two'"),  # a string for a number
        ("estimator", {"kp": (15.0, -1.0, 15.0)}, "estimator.kp", "[15.0, -1.0, 15.0]"),  # validate's
        ("sim", {"duration": 0.0}, "sim.duration", "0.0"),
        ("formation", {"scale": -1.0}, "formation.scale", "-1.0"),  # apply_scale's range
    ],
)
def test_a_replaced_bad_value_is_refused_with_loads_error(table, changes, key, value):
    sc = bf.load("paper", SHORT, plant="ideal")
    with pytest.raises(InputError) as by_load:
        bf.load("paper", [*SHORT, f"{key}={value}"], plant="ideal")
    with pytest.raises(InputError) as by_simulate:
        bf.simulate(_replaced(sc, table, **changes))
    assert type(by_simulate.value) is type(by_load.value) and issubclass(type(by_load.value), ScenarioError)
    assert str(by_simulate.value) == str(by_load.value)
    assert key in str(by_simulate.value)


def test_a_valid_scenario_runs_as_given_bit_for_bit():
    sc = bf.load("paper", SHORT, plant="ideal")
    a, b = bf.simulate(sc), bf.simulate(sc)
    assert a.scenario is sc  # nothing rebuilt: the same object ran
    assert np.array_equal(a.log["pose"], b.log["pose"]) and len(a.log["t"]) == 20


def test_a_replaced_scale_is_applied_as_load_applies_it():
    written = bf.load("paper", SHORT, plant="ideal")
    res = bf.simulate(_replaced(written, "formation", scale=0.5))
    loaded = bf.load("paper", [*SHORT, "formation.scale=0.5"], plant="ideal")
    assert res.scenario == loaded and res.scenario.formation.offsets == ((1.5, 0.0), (2.0, 2.5), (2.0, -2.5))
    assert res.scenario.kinematic.k2 == loaded.kinematic.k2 == written.kinematic.k2 / 0.25
    assert res.summary["formation_scale"] == 0.5
    assert np.array_equal(res.log["pose"], bf.simulate(loaded).log["pose"])  # the same run, bit for bit
    # a scaled scenario rescaled: lengths end at 0.25 of those written, once (not 0.5 x 0.25)
    again = bf.simulate(_replaced(loaded, "formation", scale=0.25)).scenario
    assert np.allclose(again.formation.offsets, np.array(written.formation.offsets) * 0.25, rtol=1e-15, atol=0)
    # another value of a scaled scenario changed: it is taken as given, not scaled again
    moved = _replaced(loaded, "formation", offsets=((1.0, 0.0), (2.0, 2.5), (2.0, -2.5)))
    assert bf.simulate(moved).scenario is moved


def test_scale_applied_is_not_a_scenario_key():
    sc = bf.load("paper", ["formation.scale=0.5"], plant="ideal")
    assert sc.formation.scale_applied == 0.5 and "scale_applied" not in sc.to_dict()["formation"]
    with pytest.raises(ScenarioError, match="formation.scale_applied': unknown key"):
        bf.load("paper", ["formation.scale_applied=0.5"])


# ---- an OutcomeWarning per follower that did not end ok ---------------------------------------------


def test_outcome_warning_is_exported_and_filterable():
    assert bf.OutcomeWarning is OutcomeWarning and issubclass(OutcomeWarning, UserWarning)
    assert "OutcomeWarning" in bf.__all__


def test_a_clean_paper_run_warns_nothing():
    res, got = _outcome_warnings(lambda: bf.simulate(bf.load("paper", plant="ideal")))  # 20 s, the paper's run
    assert res.diverged is None and all(f["outcomes"] == [] for f in res.summary["followers"])
    assert got == []


def test_a_diverged_run_warns_each_lost_follower_and_the_divergence():
    sc = bf.load("paper", DIVERGES, method="backstepping", plant="ideal")
    res, got = _outcome_warnings(lambda: bf.simulate(sc))
    fs = res.summary["followers"]
    assert res.diverged is not None and all([o["kind"] for o in f["outcomes"]] == ["lost"] for f in fs)
    assert [w.follower for w in got] == [1, 2, 3, None]  # one per follower, then the run's
    for w, f in zip(got, fs):
        assert str(w) == f"paper / backstepping: follower {f['id']}: lost ({f['outcomes'][0]['detail']})"
        assert w.outcomes == f["outcomes"]
    assert str(got[3]).startswith("paper / backstepping: the simulation diverged at t = 0 s: ")
    with warnings.catch_warnings(record=True) as quiet:  # what a user's filter does
        warnings.simplefilter("always")
        warnings.simplefilter("ignore", bf.OutcomeWarning)
        bf.simulate(sc)
    assert [w for w in quiet if issubclass(w.category, OutcomeWarning)] == []


def test_a_tipped_follower_gets_exactly_one_warning_naming_it():
    """tb3 in the unscaled paper scenario tips every follower within 0.5 s (tests/test_robots_mapping.py)."""
    sc = bf.load("paper", plant="mujoco", overrides=['plant.robots=["tb3"]', "sim.duration=0.5"])
    res, got = _outcome_warnings(lambda: bf.simulate(sc))
    for f in res.summary["followers"]:
        assert f["outcome"] == "tipped"
        mine = [w for w in got if w.follower == f["id"]]
        assert len(mine) == 1 and f"follower {f['id']}: tipped (" in str(mine[0])
        assert all(f"{o['kind']} ({o['detail']})" in str(mine[0]) for o in f["outcomes"])  # every kind, its detail
    assert len(got) == 3


# ---- who reads the outcomes itself does not warn ----------------------------------------------------


def test_the_cli_prints_each_outcome_line_once(tmp_path, capsys):
    from bioform_mj.cli.main import main

    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        code = main(
            ["run", "paper", "--plant", "ideal", "--method", "backstepping", "--quiet"]
            + [a for s in DIVERGES for a in ("--set", s)]
            + ["--out", str(tmp_path)]
        )
    err = capsys.readouterr().err.splitlines()
    assert code == 3
    for i in (1, 2, 3):
        assert sum(f"follower {i}: lost (" in ln for ln in err) == 1, err  # not also as an OutcomeWarning
        assert f"warning: follower {i}: lost (final formation error" in "\n".join(err)
    assert sum("diverged" in ln for ln in err) == 1 and not any("OutcomeWarning" in ln for ln in err), err
    assert [w for w in got if issubclass(w.category, OutcomeWarning)] == []


def test_a_sweep_row_tabulates_outcomes_without_warning():
    from bioform_mj.jobs.sweep import expand, run_one

    spec = expand("paper", 1, ["backstepping"], [], DIVERGES, plant="ideal")[0]
    row, got = _outcome_warnings(lambda: run_one(spec))
    assert row["outcome"] == "diverged" and row["follower_outcomes"] == "lost;lost;lost"
    assert got == []


def test_a_sweeps_runs_are_not_checked_again():
    """``expand`` validated each configuration by ``load`` and each seed itself: its per-seed copies
    are marked, so ``simulate`` spends nothing on them (the check costs 2-5 ms; an ideal run's set-up ~10 ms)."""
    from bioform_mj.jobs.sweep import expand
    from bioform_mj.scenario.loader import checked

    specs = expand("paper", 3, ["bioinspired"], [], ["formation.init_jitter=0.1"], plant="ideal")
    assert [sp.scenario.sim.seed for sp in specs] == [0, 1, 2]
    assert all(checked(sp.scenario) is sp.scenario for sp in specs)
    replaced = dataclasses.replace(specs[0].scenario, method="backstepping")  # a change of one's own: checked
    assert getattr(replaced, "_bioform_checked", False) is False and checked(replaced) is replaced


def test_quiet_outcomes_ignores_only_outcome_warnings():
    from bioform_mj.core.errors import quiet_outcomes

    sc = bf.load("paper", DIVERGES, method="backstepping", plant="ideal")
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        with quiet_outcomes():
            res = bf.simulate(sc)
            warnings.warn("another", RuntimeWarning, stacklevel=1)
        bf.simulate(sc)  # outside again: said
    kinds = [w.category.__name__ for w in got]
    assert res.diverged is not None and kinds == ["RuntimeWarning"] + ["OutcomeWarning"] * 4, kinds


def test_the_kernels_warm_up_says_nothing_of_its_outcomes(monkeypatch):
    """A 0.01 s run per plant leaves every follower c_hat_off: a sweep's warm-up must not say so."""
    from bioform_mj.jobs import runner as jobs

    monkeypatch.setattr(jobs, "_KERNELS", [])
    _, got = _outcome_warnings(jobs.load_kernels)
    assert jobs._KERNELS == [True] and got == []
    _, said = _outcome_warnings(lambda: bf.simulate(bf.load("paper", ["sim.duration=0.01"], plant="ideal")))
    assert [w.follower for w in said] == [1, 2, 3] and all("c_hat_off (" in str(w) for w in said)


def test_table1_prints_each_followers_outcome_warning_once_and_the_divergence_as_its_error(tmp_path, capsys):
    from bioform_mj.cli.main import main

    sets = [a for s in DIVERGES for a in ("--set", s)]
    assert main(["table1", "paper", "--plant", "ideal", *sets, "--quiet", "--out", str(tmp_path / "t")]) == 3
    err = capsys.readouterr().err.splitlines()
    table = __import__("json").loads((tmp_path / "t" / "table1.json").read_text())
    expected = [(m, f["id"]) for m, s in table["methods"].items() for f in s["followers"] if f["outcomes"]]
    assert len(expected) >= 6  # backstepping's three followers lost, at least
    for m, i in expected:
        assert sum(ln.startswith(f"warning: paper / {m}: follower {i}: ") for ln in err) == 1, err
    assert sum(ln.startswith("warning:") for ln in err) == len(expected)  # the divergence: not a warning ...
    assert sum(ln.startswith("error: simulation diverged for") for ln in err) == 1  # ... its error line


class _Spoiled:
    """The paper's stack; after 50 steps NaN torques for follower 2 (``nan``) or a raise (``raise``)."""

    def __init__(self, sc, mode: str) -> None:
        from bioform_mj.control.params import stack_params
        from bioform_mj.control.stack import ControlStack

        self.inner = ControlStack(sc.build_graph(), stack_params(sc, np.array(sc.plant.c_true)))
        self.n, self.k, self.mode = sc.n, 0, mode

    def reset(self, est_pose0, vel0):
        self.inner.reset(est_pose0, vel0)

    def step(self, *a):
        tau = self.inner.step(*a)
        self.k += 1
        if self.k > 50 and self.mode == "raise":
            raise ValueError("boom")
        if self.k > 50:
            tau = tau.copy()
            tau[1, 0] = np.nan
        return tau

    def signals(self):
        return self.inner.signals()


def test_a_users_nonfinite_torques_are_warned_and_a_raise_is_not():
    sc = bf.load("paper", SHORT, plant="ideal")
    res, got = _outcome_warnings(lambda: bf.simulate(sc, controller=_Spoiled(sc, "nan")))
    assert [w.follower for w in got] == [2, None]  # follower 2's controller_nonfinite, then the divergence
    assert str(got[0]).startswith("paper / _Spoiled: follower 2: controller_nonfinite (_Spoiled.step returned")
    assert res.summary["followers"][1]["outcomes"] == got[0].outcomes
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        with pytest.raises(ValueError, match="boom") as info:
            bf.simulate(sc, controller=_Spoiled(sc, "raise"))
    assert info.value.result.summary["raised"]["step"] == 50  # the exception is the news: no OutcomeWarning
    assert [w for w in seen if issubclass(w.category, OutcomeWarning)] == []


def test_the_environment_checks_a_scenario_object_as_simulate_does():
    pytest.importorskip("pettingzoo")
    from bioform_mj.envs import parallel_env

    sc = bf.load("paper", SHORT, plant="ideal")
    # the environment's contract: an InputError as a ValueError with the same one-line message
    with pytest.raises(ValueError, match="scenario key 'kinematic.k1': expected a finite number, got nan"):
        parallel_env(_replaced(sc, "kinematic", k1=float("nan")))
    env = parallel_env(_replaced(sc, "formation", scale=0.5))  # applied, as simulate applies it
    assert env._sc.formation.offsets == ((1.5, 0.0), (2.0, 2.5), (2.0, -2.5))

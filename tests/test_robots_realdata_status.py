"""What ``bioform robot fit`` may call found (issue 29; design §8.4; ``robots/realdata/status.py``): the chunk
length a short recording gets, a recording too short for an interval that holds, a parameter whose interval
includes 0, and a parameter whose finite-difference trial at the optimum diverged.

The recordings come from ``tests/realdata_recorder.py`` (a plain MuJoCo loop and ``rosbags``' writer): the tb3
with a 0.3 kg payload, wheel damping 0.002/0.0025 N·m·s/rad and dry friction **0** on the left wheel, 0.003 N·m on
the right, 12 s at 0.025 N·m. Measured once (load 6, 16.5 s CPU): 12 chunks of 1 s; the left dry friction 0 with
interval ±0.00029 N·m (5 % of the left wheel's RMS effort is 0.00065 N·m); the right 0.00300 ± 0.00029; the other
four identified and holding the truth.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")
pytest.importorskip("tabulate")  # mujoco.sysid's dependency (the 'fit' extra)

sys.path.insert(0, str(Path(__file__).parent))
import realdata_recorder as rr  # noqa: E402
from bioform_mj.robots.realdata import fit as fit_mod  # noqa: E402
from bioform_mj.robots.realdata.recording import Recording, read_recording  # noqa: E402
from bioform_mj.robots.realdata.simmodel import other_joints, sim_spec  # noqa: E402
from bioform_mj.robots.realdata.status import (  # noqa: E402
    CHUNK_FLOOR_S,
    choose_chunk,
    settle_zero,
    too_short_why,
)
from bioform_mj.robots.refs import as_ref  # noqa: E402

TRUTH = rr.Truth(payload_kg=0.3, payload_yaw_kgm2=0.001, damping=(0.002, 0.0025), frictionloss=(0.0, 0.003))
TB3 = {"mass": 0.943 + 0.3, "yaw_inertia": 0.0020064 + 0.001, "damping_L": 0.002, "damping_R": 0.0025}


def _rec(seconds: float, hz: float = 100.0, gap: tuple[float, float] | None = None) -> Recording:
    t = np.arange(0.0, seconds + 1e-9, 1.0 / hz)
    if gap is not None:
        t = t[(t < gap[0]) | (t > gap[1])]
    z = np.zeros((len(t), 2))
    return Recording("synthetic", ("l", "r"), t, z, z + 1.0, z + 0.01)


def test_a_short_recording_gets_shorter_chunks_and_an_explicit_one_is_honoured():
    # 6 parameters want 10 chunks: 60 s and 20 s give 10 of 2 s; 12 s gives 6, so shorter ones up to the 12 of
    # --max-chunks: 1 s (1.1 s gives 10); 8 s: 0.6 s (13; 0.7 s gives 11); 4 s reaches only 8 at the 0.5 s floor
    # (the jackknife's minimum p + 2); an explicit --chunk is kept as given
    assert choose_chunk(_rec(60.0), 6, None, 12) == (2.0, [])
    assert choose_chunk(_rec(20.0), 6, None, 12) == (2.0, [])
    length, notes = choose_chunk(_rec(12.0), 6, None, 12)
    assert length == pytest.approx(1.0) and "12 of 1 s" in notes[0] and "6 chunks of 2 s" in notes[0]
    assert choose_chunk(_rec(12.0), 6, None, 10)[0] == pytest.approx(1.2)  # --max-chunks 10: 10 of 1.2 s
    assert choose_chunk(_rec(8.0), 6, None, 12)[0] == pytest.approx(0.6)
    assert choose_chunk(_rec(4.0), 6, None, 12)[0] == pytest.approx(CHUNK_FLOOR_S) == 0.5
    assert choose_chunk(_rec(12.0), 6, 2.0, 12) == (2.0, [])
    assert choose_chunk(_rec(12.0), 2, None, 12) == (2.0, [])  # 2 parameters: 6 chunks of 2 s are enough
    # a pause (dropped messages, 4-5.5 s) costs chunks: no chunk spans it, so 20 s gives 8 of 2 s (0-2, 6-20) and
    # 1.4 s gives 12 (0-2.8, 5.6-19.6; 1.5 s gives 11)
    length, notes = choose_chunk(_rec(20.0, gap=(4.0, 5.5)), 6, None, 12)
    assert length == pytest.approx(1.4) and "8 chunks of 2 s" in notes[0] and "12 of 1.4 s" in notes[0]


def test_too_few_chunks_say_how_long_to_record():
    assert too_short_why(8, 6, 0.5, 12) == ""
    why = too_short_why(6, 6, 0.5, 12)  # 6 parameters + 4 chunks of 0.5 s
    assert why.startswith("recording too short for an interval that holds") and "record ≥ 5 s" in why
    assert "shorter --chunk, down to 0.5 s" in too_short_why(5, 6, 2.0, 12)  # an explicit 2 s: shorter would do
    assert "--max-chunks" in too_short_why(4, 6, 2.0, 4)  # the user's cap, not the recording


def test_an_interval_that_includes_zero_is_never_identified():
    eff = {"frictionloss_L": (1.0, 0.013), "damping_L": (20.0, 0.013)}  # N·m per unit, RMS effort N·m
    row = {"name": "frictionloss_L", "unit": "N·m", "ci95": [-3e-4, 3e-4], "status": "identified", "why": ""}
    settle_zero(row, eff)  # 3e-4 N·m < 5 % of 0.013 N·m: negligible, and it says the bound
    assert row["status"] == "negligible" and "below 0.0003 N·m" in row["why"] and "includes 0" in row["why"]
    row = {"name": "damping_L", "unit": "N·m·s/rad", "ci95": [-1e-4, 1e-4], "status": "identified", "why": ""}
    settle_zero(row, eff)  # 1e-4 × 20 rad/s = 0.002 N·m, 15 % of the effort: not negligible
    assert row["status"] == "not identified" and "the recording says only that it is below 0.0001" in row["why"]
    row = {"name": "mass", "unit": "kg", "ci95": [-0.1, 2.0], "status": "not identified"}
    row["why"] = "interval ±1 kg is wide"
    settle_zero(row, eff)  # no effect bound for a mass: not identified, the bound said
    assert row["status"] == "not identified" and "includes 0" in row["why"] and "is wide" not in row["why"]
    wide = {"name": "frictionloss_L", "unit": "N·m", "ci95": [1e-5, 3e-4], "status": "not identified"}
    wide["why"] = "interval ±0.000145 N·m is wide"
    settle_zero(wide, eff)  # not including 0 but too wide to identify, and below a negligible bound
    assert wide["status"] == "negligible" and "includes 0" not in wide["why"] and "below 0.0003 N·m" in wide["why"]
    wide = {**wide, "status": "not identified", "why": "interval ±0.0145 N·m is wide", "ci95": [1e-3, 0.03]}
    settle_zero(wide, eff)  # its upper end is not negligible: it stays as it was
    assert wide["status"] == "not identified" and wide["why"] == "interval ±0.0145 N·m is wide"
    held = {"name": "frictionloss_L", "unit": "N·m", "ci95": [-3e-4, 3e-4], "status": "not identified"}
    held["why"] = "the residual is not smooth in it (...)"
    settle_zero(held, eff)  # an interval that does not hold bounds nothing
    assert held["status"] == "not identified" and held["why"] == "the residual is not smooth in it (...)"


@pytest.fixture(scope="module")
def short_bag(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("short") / "tb3_12s"
    rr.record(p, "tb3", TRUTH, duration=12.0, tau=0.025, seed=0)
    return p


def _fit(bag: Path, **kw):
    robot = sim_spec(as_ref("tb3"))
    rec = read_recording(bag, TRUTH.joints, None, other_joints(robot))
    res, _ = fit_mod.fit(robot, rec, progress=False, time_budget_s=600, **kw)
    return res, {p["name"]: p for p in res.parameters}


@pytest.fixture(scope="module")
def short_fit(short_bag):
    return _fit(short_bag)


def _diverge_off_the_optimum(monkeypatch, diverges) -> None:
    """Make ``mujoco.sysid.model_residual`` raise as on NaN ("Nan, Inf or huge value in QACC") for a trial point
    ``x`` where ``diverges(x, x_opt)``, but only once ``fit``'s Jacobian at the optimum ``x_opt`` has begun (armed
    by ``jacobian_at``): the optimiser's path and optimum stay those of the fit without it."""
    from mujoco import sysid

    real_res, real_jac = sysid.model_residual, fit_mod.jacobian_at
    armed: dict[str, np.ndarray] = {}

    def model_residual(x, *a, **kw):
        if "x" in armed and diverges(np.ravel(np.asarray(x, float)), armed["x"]):
            raise ValueError("Nan, Inf or huge value in QACC")
        return real_res(x, *a, **kw)

    def jacobian_at(residual, x, *a, **kw):
        armed["x"] = np.array(x, float)
        return real_jac(residual, x, *a, **kw)

    monkeypatch.setattr(sysid, "model_residual", model_residual)
    monkeypatch.setattr(fit_mod, "jacobian_at", jacobian_at)


def test_a_short_recordings_fit_chooses_its_chunks_and_tells_zero_from_positive(short_fit):
    res, got = short_fit
    assert res.n_chunks == 12 and res.chunk_s == pytest.approx(1.0)
    assert res.notes[0].startswith("12 chunks of 1 s") and any("not 2 s" in n for n in res.notes)
    zero, pos = got["frictionloss_L"], got["frictionloss_R"]
    assert zero["status"] == "negligible" and zero["ci95"][0] <= 0.0 <= zero["ci95"][1], zero
    assert zero["ci95"][1] < 0.05 * 0.013  # its bound: under 5 % of the wheel's RMS effort (~0.013 N·m)
    assert pos["status"] == "identified" and pos["ci95"][0] > 0 and pos["ci95"][0] <= 0.003 <= pos["ci95"][1], pos
    for name, true in TB3.items():
        p = got[name]
        assert p["status"] == "identified" and p["ci95"][0] <= true <= p["ci95"][1], (name, p)


def test_a_recording_too_short_even_at_the_floor_identifies_nothing(tmp_path):
    bag = tmp_path / "tb3_3s"
    rr.record(bag, "tb3", TRUTH, duration=3.0, tau=0.025, seed=0)
    res, got = _fit(bag, max_iters=3)
    assert res.n_chunks == 6 and res.chunk_s == pytest.approx(CHUNK_FLOOR_S)  # 3 s recorded: 6 chunks of 0.5 s
    for p in got.values():
        assert p["status"] == "not identified" and "record ≥ 5 s" in p["why"], p
    assert any(n.startswith("no parameter is reported identified: recording too short") for n in res.notes)


def test_a_trial_that_diverges_at_the_optimum_is_not_identified_and_the_others_are_unaffected(
    short_bag, short_fit, monkeypatch
):
    """The rollouts diverge (``mujoco.sysid.model_residual`` raising as on NaN) whenever ``damping_R`` is moved
    off the optimum, and only in the Jacobian after the optimiser (armed by ``jacobian_at``): the optimiser's path
    and optimum are those of the fit without it."""
    k = list(short_fit[1]).index("damping_R")
    _diverge_off_the_optimum(monkeypatch, lambda x, x_opt: abs(x[k] - x_opt[k]) > 1e-12)
    res, got = _fit(short_bag)
    row = got["damping_R"]
    assert row["status"] == "not identified" and "made the rollouts diverge" in row["why"]
    assert row["ci95"] is None  # no interval from a column that is no slope
    assert any("damping_R at the optimum diverged" in n for n in res.notes)
    for name, p in short_fit[1].items():
        if name == "damping_R":
            continue
        assert got[name]["fitted"] == p["fitted"] and got[name]["status"] == p["status"], name
        assert np.isfinite(got[name]["ci95_halfwidth"])


def test_every_trial_diverging_at_the_optimum_still_gives_a_result(short_bag, monkeypatch):
    """Every parameter's finite-difference trial diverges at the optimum (here ``mass`` and ``yaw_inertia``, the
    only two fitted): no column is a slope, so there is no interval at all; the fit reports each not identified
    with the reason and no interval (it raised IndexError in the interval code, which had no column left)."""
    _diverge_off_the_optimum(monkeypatch, lambda x, x_opt: np.abs(x - x_opt).max() > 1e-12)
    res, got = _fit(short_bag, which=("mass", "yaw_inertia"), max_iters=3)
    assert sorted(got) == ["mass", "yaw_inertia"]
    for row in got.values():
        assert row["status"] == "not identified" and "made the rollouts diverge" in row["why"], row
        assert row["ci95"] is None and row["correlated_with"] == []
    assert any("mass, yaw_inertia at the optimum diverged" in n for n in res.notes)

"""Issue 27: the hardware verdict's ``control_rate`` check has a way to know a robot's rate (design §19).

The mapping key ``control_rate`` (Hz, the maker's figure; ``--control-rate`` on ``run``, ``robot check``, ``identify``)
is the limit, "the mapping's"; else a shipped preset's rate, as before; else the check is not made and says exactly
how to give the rate. Bad values: one ``error:`` line, exit 2, before any work.
"""

from __future__ import annotations

import json
import shutil

import pytest

from bioform_mj.assess.hardware import NO_CONTROL_RATE, robot_control_rates
from bioform_mj.cli import main as cli
from bioform_mj.robots.refs import models_dir
from bioform_mj.run.simulate import make_plant
from bioform_mj.scenario.loader import load


@pytest.fixture
def copy(tmp_path):
    """The paper robot under another path: no shipped preset drives it."""
    p = tmp_path / "my_robot.xml"
    shutil.copy(models_dir() / "paper_robot.xml", p)
    return str(p)


def _rates(robots: str) -> list:
    sc = load("paper", overrides=["plant.kind=mujoco", f"plant.robots={robots}"])
    return robot_control_rates(sc, make_plant(sc))


def test_the_three_sources_of_a_robots_control_rate(copy):
    from bioform_mj.assess.hardware import preset_control_rate
    from bioform_mj.robots.entries import resolve_robot

    rate, preset = preset_control_rate(resolve_robot("paper").model)  # a MuJoCo preset that drives it (as before)
    assert rate == pytest.approx(1000.0) and preset
    assert _rates('["paper"]') == [(rate, f"the '{preset}' preset's rate")]
    assert _rates('[{model = "paper", control_rate = 30}]') == [(30.0, "the mapping's")]  # the mapping first
    assert _rates(f'["{copy}"]') == [(None, "")]
    # two robots: each its own source (the check takes the slowest)
    two = _rates(f'["paper", {{model = "{copy}", control_rate = 50}}, "paper"]')
    assert sorted(two, key=str) == sorted([(rate, f"the '{preset}' preset's rate"), (50.0, "the mapping's")], key=str)
    assert "control_rate" in NO_CONTROL_RATE and "--control-rate" in NO_CONTROL_RATE  # how to give it


@pytest.mark.parametrize("bad", ["0", "-30", "nan", "inf", '"fast"', "true"])
def test_a_bad_control_rate_key_is_refused(copy, bad):
    from bioform_mj.core.errors import InputError

    with pytest.raises(InputError, match=r"plant\.robots(\[0\])?\.control_rate': expected a finite number > 0 \(Hz"):
        load("paper", overrides=["plant.kind=mujoco", f'plant.robots=[{{model = "{copy}", control_rate = {bad}}}]'])


@pytest.mark.parametrize(
    "argv",
    [
        ["run", "paper", "--plant", "mujoco", "--control-rate", "0"],
        ["run", "paper", "--plant", "mujoco", "--control-rate", "nan"],
        ["robot", "check", "paper", "--control-rate", "-1"],
        ["identify", "paper", "--control-rate", "inf"],
    ],
)
def test_a_bad_control_rate_flag_is_one_error_line_and_exit_2(argv, tmp_path, capsys):
    code = cli.main([*argv, *(["--out", str(tmp_path / "run")] if argv[0] == "run" else [])])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("error: ") and "--control-rate" in err[0], err
    assert "Traceback" not in "".join(err) and not (tmp_path / "run").exists()


def test_robot_check_shows_the_mapped_rate(copy):
    """``robot check``'s limits (its JSON ``limits`` and the printed block) carry the mapped rate, or say how to give
    one (the check's static part: no identification needed for the limits)."""
    from bioform_mj.assess.check import check
    from bioform_mj.robots.limits import block
    from bioform_mj.robots.refs import RobotRef

    lim = check(RobotRef(model=copy, control_rate=30.0), identify_=False)["limits"]
    assert lim["control_rate_hz"] == 30.0 and lim["control_rate_source"] == "mapping"
    assert "    control rate 30 Hz (the mapping's)" in block(lim)
    none = check(RobotRef(model=copy), identify_=False)["limits"]
    assert none["control_rate_hz"] is None and any("control_rate" in ln and "not given" in ln for ln in block(none))


def test_a_run_checks_its_rate_against_the_mapped_one_or_says_how_to_give_it(copy, tmp_path):
    """0.2 s at the paper scenario's 1 kHz: the mapped 500 Hz fails the check (value 1000, limit 500, the mapping's);
    --control-rate 1000 passes it; without a rate the check is not made and the verdict is incomplete, with the how."""
    runs = {}
    for name, flags in (("slow", ["--control-rate", "500"]), ("own", ["--control-rate", "1000"]), ("none", [])):
        o = tmp_path / name
        argv = ["run", "paper", "--set", "plant.kind=mujoco", "--set", f'plant.robots=["{copy}"]', "--quiet"]
        code = cli.main([*argv, "--duration", "0.2", "--no-robot-check", "--out", str(o), *flags])
        assert code == 0
        runs[name] = json.loads((o / "summary.json").read_text())["hardware"]
    c = runs["slow"]["checks"]["control_rate"]
    assert (c["value"], c["limit"], c["pass"], c["reason"]) == (pytest.approx(1000.0), 500.0, False, "the mapping's")
    assert runs["slow"]["verdict"] == "fail" and "control_rate" in runs["slow"]["failed"]
    assert runs["own"]["checks"]["control_rate"]["pass"] is True
    c = runs["none"]["checks"]["control_rate"]
    assert c["pass"] is None and c["reason"] == NO_CONTROL_RATE and "control_rate" in runs["none"]["not_checked"]
    assert runs["none"]["verdict"] in ("incomplete", "fail")  # "fail" only by another check, never this one
    assert "control_rate" not in runs["none"]["failed"]

"""The controller registry (design §22, ``control/registry.py``): every entry runs (conformance), a user's
controller registered by name runs through ``simulate``, the CLI's ``--method``, ``table1 --methods`` and a
sweep, and an installed package's entry point is found by the CLI. The user's controller is the example of
``docs/guide/controllers.md``, run from the page itself."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

import bioform_mj as bf
from bioform_mj.cli.main import main
from bioform_mj.control import registry
from bioform_mj.control.registry import controller_names, is_registered, register_controller, unregister_controller
from bioform_mj.control.stack import METHODS
from bioform_mj.core.errors import InputError
from bioform_mj.run.hooks import check_controller

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "guide" / "controllers.md"
SHORT = {"sim.duration": 0.3}


def _example() -> str:
    """The guide's Python example, without its last lines (the register call and the 2 s run)."""
    block = PAGE.read_text().split("## Your controller by name", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
    return block.split("\nbf.register_controller(", 1)[0] + "\n"


_NS: dict = {}
exec(compile(_example(), str(PAGE), "exec"), _NS)  # SlotPD, make_slot_pd
if not is_registered("slot-pd"):
    register_controller("slot-pd", _NS["make_slot_pd"])


@pytest.fixture
def fresh_registry(monkeypatch):
    """The registry as it is, restored after the test (entry points read again)."""
    monkeypatch.setattr(registry, "_ENTRIES", dict(registry._ENTRIES))
    monkeypatch.setattr(registry, "_SCANNED", False)


def test_the_papers_methods_are_the_first_entries():
    assert controller_names()[:4] == METHODS
    assert "slot-pd" in controller_names()


@pytest.mark.parametrize("name", controller_names())
def test_every_registered_controller_runs_by_name(name):
    """Conformance: each entry builds a controller for the scenario (the methods of ``bf.Controller``) and runs on
    the ideal plant by name."""
    sc = bf.load("paper", SHORT, method=name, plant="ideal")
    res = bf.simulate(sc)
    assert res.summary["method"] == name and res.diverged is None
    check_controller(registry.build_controller(name, sc, res.plant))  # the protocol's methods (design §17)
    tau = res.log["tau"]
    assert tau.shape[1:] == (sc.n, 2) and len(tau) > 0 and np.isfinite(tau).all()
    assert res.summary["engine"] == ("compiled" if name in METHODS else "stepwise")


def test_the_guides_example_runs_as_written(fresh_registry, capsys):
    block = PAGE.read_text().split("## Your controller by name", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
    block = block.replace('"sim.duration": 2.0', '"sim.duration": 0.5')
    unregister_controller("slot-pd")  # the page registers it itself
    exec(compile(block, str(PAGE), "exec"), {})
    assert capsys.readouterr().out.startswith("slot-pd [")


def test_register_refuses_bad_names_and_replacing(fresh_registry):
    with pytest.raises(ValueError, match="paper's methods"):
        register_controller("bioinspired", _NS["make_slot_pd"])
    with pytest.raises(ValueError, match="registered already"):
        register_controller("slot-pd", _NS["make_slot_pd"])
    register_controller("slot-pd", _NS["make_slot_pd"], replace=True)
    with pytest.raises(ValueError, match="run folder"):
        register_controller("a/b", _NS["make_slot_pd"])
    with pytest.raises(TypeError, match="callable"):
        register_controller("x", 3)  # type: ignore[arg-type]


def test_an_unknown_method_names_the_registered_ones():
    with pytest.raises(InputError, match=re.escape("unknown method 'nope' (expected one of: backstepping,")) as e:
        bf.load("paper", method="nope")
    assert "slot-pd" in str(e.value)


def test_a_factory_that_refuses_the_scenario_is_named():
    sc = bf.load("paper", {**SHORT, "formation.frame": "leader"}, method="slot-pd", plant="ideal")
    with pytest.raises(ValueError, match="world frame only") as e:
        bf.simulate(sc)
    assert "factory of controller 'slot-pd'" in "".join(getattr(e.value, "__notes__", []))


def test_the_cli_runs_a_registered_controller(tmp_path):
    out = tmp_path / "run"
    assert main(["run", "paper", "--plant", "ideal", "--set", "sim.duration=0.3", "--method", "slot-pd"] + [
        "--out", str(out), "--quiet"]) == 0  # fmt: skip
    summary = json.loads((out / "summary.json").read_text())
    assert summary["method"] == "slot-pd" and summary["controller"] == "SlotPD"
    assert main(["run", "paper", "--plant", "ideal", "--method", "nope", "--out", str(tmp_path / "x")]) == 2


def test_table1_and_a_sweep_take_a_registered_controller(tmp_path):
    assert main(["table1", "paper", "--plant", "ideal", "--set", "sim.duration=0.3", "--methods"] + [
        "bioinspired-learning,slot-pd", "--out", str(tmp_path / "t1"), "--quiet"]) == 0  # fmt: skip
    table = json.loads((tmp_path / "t1" / "table1.json").read_text())
    assert list(table["methods"]) == ["bioinspired-learning", "slot-pd"]
    assert table["ordering_holds"] is True  # among the paper's methods run: one
    from bioform_mj.jobs.sweep import expand, sweep

    specs = expand("paper", 1, ["slot-pd", "bioinspired"], [], ["sim.duration=0.3"], plant="ideal")
    got = sweep(specs, tmp_path / "sw", workers=1, warn=None)
    rows = got["rows"]
    assert sorted(r["method"] for r in rows) == ["bioinspired", "slot-pd"]
    assert main(["sweep", "paper", "--methods", "slot-pd,nope", "--out", str(tmp_path / "sw2")]) == 2


def test_the_batch_engine_refuses_a_registered_controller():
    from bioform_mj.batch.support import unsupported

    assert "registered controller" in unsupported(bf.load("paper", method="slot-pd", plant="mujoco"))


_PACKAGE = """
import numpy as np
{example}

def make(sc, plant):
    return make_slot_pd(sc, plant)
"""


def test_an_installed_packages_entry_point_is_found_by_the_cli(tmp_path, monkeypatch, fresh_registry):
    """A package declaring ``[project.entry-points."bioform_mj.controllers"]`` is found without registering."""
    site = tmp_path / "site"
    (site / "bioform_userctl").mkdir(parents=True)
    (site / "bioform_userctl" / "__init__.py").write_text(_PACKAGE.format(example=_example()))
    info = site / "bioform_userctl-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: bioform-userctl\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[bioform_mj.controllers]\nslot-pd-ep = bioform_userctl:make\n")
    monkeypatch.syspath_prepend(str(site))
    assert "slot-pd-ep" in controller_names()
    assert registry._ENTRIES["slot-pd-ep"].source == "entry point bioform-userctl"
    out = tmp_path / "run"
    assert main(["run", "paper", "--plant", "ideal", "--set", "sim.duration=0.3", "--method", "slot-pd-ep"] + [
        "--out", str(out), "--quiet"]) == 0  # fmt: skip
    assert json.loads((out / "summary.json").read_text())["method"] == "slot-pd-ep"
    sw = tmp_path / "sweep"  # bioform sweep --methods NAME: a forked worker finds it as the parent did
    assert main(["sweep", "paper", "--plant", "ideal", "--set", "sim.duration=0.3", "--methods"] + [
        "slot-pd-ep,bioinspired", "--workers", "2", "--out", str(sw), "--quiet"]) == 0  # fmt: skip
    rows = [json.loads(p.read_text()) for p in (sw / "runs").glob("*.json")]
    assert sorted(r["method"] for r in rows) == ["bioinspired", "slot-pd-ep"]

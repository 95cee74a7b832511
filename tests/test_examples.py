"""The user-written controller of examples/ plugs into simulate() without copying the loop."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from bioform_mj.control.base import Controller

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "kanayama.py"


@pytest.fixture(scope="module")
def kanayama():
    spec = importlib.util.spec_from_file_location("kanayama_example", EXAMPLE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_user_controller_holds_the_formation_and_is_compared_with_the_four_methods(kanayama):
    summ = kanayama.compare("ideal", duration=10.0)
    user = summ["kanayama (examples/)"]
    assert user["controller"] == "Kanayama" and user["engine"] == "stepwise"
    fe = [f["final_formation_error_m"] for f in user["followers"]]
    assert max(fe) < 0.1  # measured 0.02-0.03 m after 10 s
    assert all(f["outcome"] == "ok" for f in user["followers"])
    j_user = np.array([f["total_velocity_error"] for f in user["followers"]])
    j_bio = np.array([f["total_velocity_error"] for f in summ["bioinspired-learning"]["followers"]])
    assert np.all(np.isfinite(j_user)) and np.all(j_bio < j_user)  # measured 1.3 vs 4.6-7.0 over 20 s
    # signals the controller does not provide are NaN, not zeros
    assert all(np.isnan(f["c_hat"][0]) for f in user["followers"])
    md = kanayama.table(summ)
    assert md.count("\n") == 2 + 5 and "kanayama" in md


def test_user_controller_satisfies_the_protocol(kanayama):
    from bioform_mj.scenario import load
    from bioform_mj.sim import make_plant

    sc = load("paper")
    pl = make_plant(sc)
    assert isinstance(kanayama.Kanayama(sc, pl.c_true(), np.full(3, 20.0)), Controller)

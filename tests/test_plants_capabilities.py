"""The plants' capabilities (design §22, ``plants/base.py``): each shipped plant declares, by the protocols it
satisfies, what the loop, the summary, the outcomes and the hardware verdict may read of it, and runs by its kind
(conformance over every plant kind)."""

from __future__ import annotations

import numpy as np
import pytest

import bioform_mj as bf
from bioform_mj.control import base as control_base
from bioform_mj.plants import base
from bioform_mj.run.simulate import make_plant
from bioform_mj.scenario.config import PLANTS

CAPABILITIES = (
    base.CompiledChunk,
    base.Sensing,
    base.RobotModels,
    base.LumpedBodies,
    base.TipSlipWatch,
    base.ContactWatch,
    control_base.Obstacles,
    base.Unmodelled,
    base.DeliveredTorques,
)
EXPECTED = {
    "ideal": {"CompiledChunk", "LumpedBodies"},
    "mujoco": {
        "CompiledChunk",
        "Sensing",
        "RobotModels",
        "TipSlipWatch",
        "ContactWatch",
        "Obstacles",
        "Unmodelled",
        "DeliveredTorques",
    },
}


def test_every_capability_is_a_runtime_checkable_protocol():
    for cap in CAPABILITIES:
        assert getattr(cap, "_is_runtime_protocol", False), cap
    assert not isinstance(object(), base.CompiledChunk)


@pytest.mark.parametrize("kind", PLANTS)
def test_each_plant_declares_its_capabilities_and_runs(kind):
    assert set(EXPECTED) == set(PLANTS)  # a new plant kind says what it offers here
    sc = bf.load("paper", {"sim.duration": 0.2}, plant=kind)
    plant = make_plant(sc)
    got = {cap.__name__ for cap in CAPABILITIES if isinstance(plant, cap)}
    assert got == EXPECTED[kind]
    for name in ("reset", "observe", "step", "c_true", "set_leader", "add_payload"):  # the Plant interface
        assert callable(getattr(plant, name)), name
    res = bf.simulate(sc, plant=plant)
    assert res.diverged is None and np.isfinite(res.log["pose"]).all()
    assert res.summary["engine"] == "compiled"

"""The plant registry (design §22): every registered kind builds a plant from a scenario that behaves as the paper's
model says, and a new kind is one registration."""

from __future__ import annotations

import numpy as np
import pytest

import bioform_mj as bf
from bioform_mj.plants.registry import plant_factory, plant_kinds, register_plant
from bioform_mj.run.simulate import make_plant

#: the paper's robot: a = 0.4 m/(s²·N·m), b = 10 rad/(s²·N·m) (Xu et al., Sec. V; the shipped paper robot's
#: formula values, design §5), written here independently of the code
PAPER_AB = (0.4, 10.0)


def test_shipped_kinds_registered():
    """The run package registers the two shipped kinds, and nothing else is registered on import."""
    assert plant_kinds()[:2] == ("ideal", "mujoco")


@pytest.mark.parametrize("kind", plant_kinds())  # ideal 1.5 s, mujoco 1.3 s here
def test_each_kind_drives_as_the_paper_model(kind):
    """From rest at the scenario's initial poses: 0.2 s of τ_L = τ_R = 0.2 N·m gives υ = a τ_a t, then 0.2 s of
    τ_R = −τ_L = 0.2 N·m gives ω = b τ_b t (eq. 34 without disturbance), within 0.1 % of the paper's a, b."""
    sc = bf.load("paper", ["disturbance.bias=[0,0]", "disturbance.amp=[0,0]"], plant=kind)
    plant = make_plant(sc)
    pose, vel = plant.observe()
    np.testing.assert_allclose(pose, sc.initial_poses(), atol=1e-9)
    np.testing.assert_allclose(vel, 0.0, atol=1e-12)
    np.testing.assert_allclose(plant.c_true(), np.tile(PAPER_AB, (sc.n, 1)), rtol=1e-6)
    T, dt, k_end = 0.2, sc.sim.control_dt, 200
    for k in range(k_end):
        plant.step(np.full((sc.n, 2), T), k * dt)
    v = plant.observe()[1][:, 0]
    np.testing.assert_allclose(v, PAPER_AB[0] * 2 * T * k_end * dt, rtol=1e-3)
    for k in range(k_end, 2 * k_end):
        plant.step(np.tile([-T, T], (sc.n, 1)), k * dt)
    w = plant.observe()[1][:, 1]
    np.testing.assert_allclose(w, PAPER_AB[1] * 2 * T * k_end * dt, rtol=1e-3)


def test_a_new_kind_is_one_registration():
    """A registered factory is what make_plant's lookup returns; an unknown kind is refused naming the known ones."""
    made = []

    def factory(sc):
        made.append(sc)
        return "plant"

    register_plant("test-kind", factory)
    try:
        assert plant_factory("test-kind")("scenario") == "plant" and made == ["scenario"]
        assert "test-kind" in plant_kinds()
    finally:
        from bioform_mj.plants import registry

        registry._FACTORIES.pop("test-kind")
    with pytest.raises(ValueError, match=r"unknown plant kind 'nope'; registered: ideal, mujoco"):
        plant_factory("nope")
    with pytest.raises(ValueError, match="non-empty name"):
        register_plant("", factory)

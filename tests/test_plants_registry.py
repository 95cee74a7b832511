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
    for bad in ("", "a/b", " x"):
        with pytest.raises(ValueError, match="run folder's name"):
            register_plant(bad, factory)


class _Wrapped:
    """A toy plant of its own class: the ideal plant behind the :class:`~bioform_mj.plants.base.Plant` interface
    only (no capability, so the loop drives it step by step in Python)."""

    def __init__(self, inner):
        self._inner = inner
        self.n, self.control_dt = inner.n, inner.control_dt

    def reset(self):
        self._inner.reset()

    def observe(self):
        return self._inner.observe()

    def step(self, tau, t):
        self._inner.step(tau, t)

    def c_true(self):
        return self._inner.c_true()

    def set_leader(self, pose, slots):
        self._inner.set_leader(pose, slots)

    def add_payload(self, i, mass_kg, inertia_kgm2):
        self._inner.add_payload(i, mass_kg, inertia_kgm2)


def test_a_registered_kind_is_chosen_by_a_scenario(tmp_path, capsys):
    """``plant.kind = "toy"`` in a scenario file (and ``--plant toy``) runs a registered plant: validation asks the
    registry, so before registration the kind is one error naming the known kinds (``ideal, mujoco``), after it the
    run of a toy that wraps the ideal plant logs the ideal plant's run bit for bit (poses, velocities, torques, the
    estimates) with the summary's errors equal; ``bioform run --plant toy`` runs it too, ``--plant nope`` is one
    ``error:`` line naming ``toy`` among the known kinds, exit 2, before any work."""
    from bioform_mj.cli import main as cli
    from bioform_mj.core.errors import ScenarioError
    from bioform_mj.plants import registry
    from bioform_mj.run.simulate import ideal_plant, simulate

    toml = tmp_path / "toy.toml"
    toml.write_text('[sim]\nduration = 2.0\n\n[plant]\nkind = "toy"\n')
    with pytest.raises(ScenarioError, match=r"plant\.kind.*unknown plant 'toy' \(expected one of: ideal, mujoco\)"):
        bf.load(str(toml))
    built = []

    def toy(sc):
        built.append(sc.plant.kind)
        return _Wrapped(ideal_plant(sc))

    register_plant("toy", toy)
    try:
        sc = bf.load(str(toml))
        assert sc.plant.kind == "toy"
        res_toy = simulate(sc)
        res_ideal = simulate(bf.load(str(toml), plant="ideal"))
        assert built == ["toy"]
        assert set(res_toy.log) == set(res_ideal.log)
        for k in res_ideal.log:
            np.testing.assert_array_equal(res_toy.log[k], res_ideal.log[k], err_msg=k)
        for k in ("e_rms", "e_final", "e_max"):
            if k in res_ideal.summary:
                assert res_toy.summary[k] == res_ideal.summary[k], k
        out = tmp_path / "run"
        assert cli.main(["run", "paper", "--plant", "toy", "--duration", "0.2", "--out", str(out)]) == 0
        assert built == ["toy", "toy"] and (out / "summary.json").is_file()
        capsys.readouterr()
        assert cli.main(["run", "paper", "--plant", "nope", "--out", str(tmp_path / "nope")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("error:") and "expected one of: ideal, mujoco, toy" in err[0], err
        assert not (tmp_path / "nope").exists() and built == ["toy", "toy"]
    finally:
        registry._FACTORIES.pop("toy")
    with pytest.raises(ScenarioError, match="unknown plant 'toy'"):
        bf.load(str(toml))


def test_a_registered_kind_is_known_to_load_before_any_run():
    """In a fresh process, a kind registered with ``plants.registry.register_plant`` before anything of the run is
    imported is accepted by ``bioform_mj.load``: it imports the run package, which hands the registry's kinds to the
    scenario's validation."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "import bioform_mj as bf\n"
        "from bioform_mj.plants.registry import register_plant\n"
        "register_plant('toy', lambda sc: None)\n"
        "assert 'bioform_mj.run' not in sys.modules\n"
        "sc = bf.load('paper', ['plant.kind=\"toy\"'])\n"
        "print(sc.plant.kind, 'bioform_mj.run' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["toy", "True"]


def test_an_installed_packages_plant_is_found_by_the_cli(tmp_path, monkeypatch):
    """A package declaring ``[project.entry-points."bioform_mj.plants"]`` is found without registering: listed by
    ``plant_kinds`` (its module not imported yet), and ``bioform run --plant toy-ep`` builds its plant (the ideal
    plant here) and logs the ideal plant's run bit for bit."""
    import json
    import sys

    from bioform_mj.cli import main as cli
    from bioform_mj.plants import registry

    monkeypatch.setattr(registry, "_FACTORIES", dict(registry._FACTORIES))
    monkeypatch.setattr(registry, "_ENTRY_POINTS", {})
    monkeypatch.setattr(registry, "_SCANNED", False)
    site = tmp_path / "site"
    (site / "bioform_userplant").mkdir(parents=True)
    (site / "bioform_userplant" / "__init__.py").write_text(
        "from bioform_mj.run.simulate import ideal_plant\n\n\ndef make(sc):\n    return ideal_plant(sc)\n"
    )
    info = site / "bioform_userplant-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: bioform-userplant\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[bioform_mj.plants]\ntoy-ep = bioform_userplant:make\n")
    monkeypatch.syspath_prepend(str(site))
    assert plant_kinds()[-1] == "toy-ep" and "bioform_userplant" not in sys.modules
    runs = {}
    for kind in ("toy-ep", "ideal"):
        out = tmp_path / kind
        argv = ["run", "paper", "--plant", kind, "--set", "sim.duration=0.3", "--out", str(out), "--quiet"]
        assert cli.main(argv) == 0
        assert json.loads((out / "summary.json").read_text())["plant"] == kind
        runs[kind] = np.load(out / "log.npz")
    assert "bioform_userplant" in sys.modules and registry._FACTORIES["toy-ep"] is sys.modules["bioform_userplant"].make
    assert set(runs["toy-ep"]) == set(runs["ideal"])
    for k in runs["ideal"]:
        np.testing.assert_array_equal(runs["toy-ep"][k], runs["ideal"][k], err_msg=k)

"""Per-world outcomes of the batch engine that the CPU engine also reports: a slipping wheel
(``mujoco_kernels.watch_slip`` and the batch kernel both call ``equations.slip_ratio``), and
MuJoCo Warp's contact / constraint capacity overflowing (the CPU stops on MuJoCo's warnings; the
batch engine stops the world and says which capacity to raise, never silently)."""

import csv

import numpy as np
import pytest

wp = pytest.importorskip("warp")
pytest.importorskip("mujoco_warp")

from bioform_mj.cli.main import main  # noqa: E402
from bioform_mj.run.simulate import simulate  # noqa: E402
from bioform_mj.scenario.loader import load  # noqa: E402

wp.config.quiet = True

#: wheels that slip by construction: the mapping declares a wheel radius 40 % above the paper robot's
#: (robot_check warns), so every wheel's rate × that radius runs ahead of its chassis. Measured (Warp
#: CPU device): both engines report all three followers slipping, by t = 0.501 / 0.501 / 0.503 s.
#: (A low-friction patch made them slip before; the batch engine refuses patches now:
#: test_friction_patch_is_refused.)
SLIPPERY = ["plant.kind=mujoco", "sim.duration=1.0", 'plant.robots=[{model="paper", wheel_radius=0.14}]']


@pytest.mark.slow  # ≥ 7 s warm here (make test keeps to the fast set; make test-slow runs it)
def test_slipping_robot_is_reported_by_both_engines():
    from bioform_mj.batch.runner import run_batch

    sc = load("paper", overrides=SLIPPERY)
    cpu = simulate(sc).summary
    (bat,) = run_batch([sc])
    assert cpu["diverged"] is None and not bat["diverged"], bat["diverged_reason"]
    for s in (cpu, bat):
        for f in s["followers"]:
            assert f["outcome"] == "slipping", f
            assert f["outcome_detail"].startswith("wheel slip ratio > 0.2 for 0.5 s, by t = ")
            assert f["outcomes"][0]["kind"] == "slipping" and f["outcomes"][0]["detail"] == f["outcome_detail"]
    # every outcome, listed alike by both engines (sim.outcome_list; design §14)
    for fc, fb in zip(cpu["followers"], bat["followers"]):
        assert [o["kind"] for o in fc["outcomes"]] == [o["kind"] for o in fb["outcomes"]], (fc, fb)
    # the same onset on both engines (measured: identical here; float32 physics may move a threshold
    # crossing by a control step on another CPU, so within 10 steps, not bit for bit)
    onset = lambda s: [float(f["outcome_detail"].rsplit("t = ", 1)[1].split()[0]) for f in s["followers"]]  # noqa: E731
    np.testing.assert_allclose(onset(bat), onset(cpu), atol=0.01)


def test_friction_patch_is_refused():
    """MuJoCo Warp's ellipsoid-wheel-on-box contacts are not C MuJoCo's (docs/warp_engine.md): measured,
    one physics step of the paper scene from the same state on a μ = 1 patch (the floor's own μ), MuJoCo
    Warp against C MuJoCo: qvel differs by up to 35× (relative) in some steps, against ≤ 1.5e-2 on
    the bare floor; seed 2 ended with all three followers tipped on the device, one on the CPU. So the
    batch engine refuses patches up front instead of running worlds that differ from the CPU's."""
    from bioform_mj.batch.runner import run_batch
    from bioform_mj.batch.support import unsupported

    sc = load("paper", overrides=["plant.kind=mujoco", "sim.duration=0.1", "faults.friction_patch=[-5,-5,5,5,0.3]"])
    assert "faults.friction_patch" in unsupported(sc)
    with pytest.raises(ValueError, match="friction_patch"):
        run_batch([sc])


def test_no_slip_on_the_paper_floor():
    """The watch does not fire on the ordinary floor (the batch engine's ok detail is empty, as the CPU's)."""
    from bioform_mj.batch.runner import run_batch

    (bat,) = run_batch([load("paper", overrides=["plant.kind=mujoco", "sim.duration=0.6"])])
    assert [(f["outcome"], f["outcome_detail"]) for f in bat["followers"]] == [("ok", "")] * 3


def test_contact_capacity_overflow_marks_every_affected_world_diverged():
    """6 contacts per world (the scene has 6 at rest; broadphase finds more candidates): MuJoCo Warp
    only prints a warning, the batch engine stops both worlds with the reason."""
    from bioform_mj.batch.runner import run_batch

    ov = ["plant.kind=mujoco", "sim.duration=0.02"]
    out = run_batch([load("paper", overrides=[*ov, f"sim.seed={s}"]) for s in range(2)], nconmax=6)
    for r in out:
        assert r["diverged"]
        assert r["diverged_reason"].startswith("contact capacity exceeded: raise --nconmax (now 6 per world)")
        assert r["steps"] < 20


def test_constraint_capacity_overflow_and_the_sweep_flag(tmp_path):
    """``bioform sweep --backend warp --njmax 4``: the rows are diverged with the reason in ``error``."""
    out = tmp_path / "sw"
    args = ["sweep", "paper", "--plant", "mujoco", "--duration", "0.02", "--seeds", "2", "--quiet"]
    args += ["--backend", "warp", "--device", "cpu", "--njmax", "4", "--out", str(out)]
    assert main(args) == 0
    with open(out / "runs.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 2
    for r in rows:
        assert r["status"] == "diverged" and r["outcome"] == "diverged"
        assert r["error"].startswith("constraint capacity exceeded: raise --njmax (now 4 rows per world)")
        assert r["capacity_exceeded"] == "True" and r["batch_njmax"] == "4"


def test_a_resume_with_more_capacity_redoes_the_capacity_stops(tmp_path, capsys):
    """Rows that stopped on capacity are finished rows, but a resume with other capacities redoes
    them (one ``resume:`` line with the count and why); the same capacities keep them; healthy rows are
    always kept."""
    out = tmp_path / "sw"
    args = ["sweep", "paper", "--plant", "mujoco", "--duration", "0.02", "--seeds", "2", "--quiet"]
    args += ["--backend", "warp", "--device", "cpu", "--out", str(out)]
    assert main([*args, "--njmax", "4"]) == 0
    capsys.readouterr()
    assert main([*args, "--njmax", "4"]) == 0  # same capacity: nothing to redo
    assert "redone" not in capsys.readouterr().err
    assert main(args) == 0  # the default capacity (112 rows for 3 robots): redone, now healthy
    err = capsys.readouterr().err
    assert "resume: 2 row(s) redone (it stopped on MuJoCo Warp's capacity" in err
    assert "njmax 4; now nconmax 40, njmax 112" in err
    with open(out / "runs.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["status"] for r in rows] == ["ok", "ok"] and all(r["capacity_exceeded"] == "False" for r in rows)
    assert main(args) == 0
    assert "redone" not in capsys.readouterr().err


def test_capacity_flags_need_the_warp_backend(tmp_path, capsys):
    assert main(["sweep", "paper", "--nconmax", "8", "--out", str(tmp_path / "x")]) == 2
    assert "--nconmax applies to --backend warp only" in capsys.readouterr().err
    with pytest.raises(ValueError, match="njmax must be >= 1"):
        from bioform_mj.batch.runner import BatchRun

        BatchRun([load("paper", overrides=["plant.kind=mujoco", "sim.duration=0.01"])], njmax=0)


def test_physics_probe_tells_a_contact_model_apart_from_float32(tmp_path, capsys, monkeypatch):
    """physics_probe: one step at a time from C MuJoCo's state, MuJoCo Warp's velocities against C
    MuJoCo's. Float32 on the bare floor: ≤ 2e-3 (measured 1.9e-4 here); a box patch under the wheels
    (MuJoCo Warp's ellipsoid–box contacts are not C MuJoCo's): ≥ 0.1. A scene beyond PROBE_TOL is
    refused up front by the sweep (exit 2, one line) and by BatchRun."""
    from bioform_mj.batch import probe as control
    from bioform_mj.batch.runner import BatchRun
    from bioform_mj.run.simulate import make_plant

    ok = control.physics_probe(make_plant(load("paper", overrides=["plant.kind=mujoco"])))
    patch = ["plant.kind=mujoco", "faults.friction_patch=[-50.0,-50.0,50.0,50.0,1.0]"]
    bad = control.physics_probe(make_plant(load("paper", overrides=patch)))
    assert ok < control.PROBE_TOL / 10 and bad > 3 * control.PROBE_TOL, (ok, bad)
    # the refusal path, forced on the paper scene by a limit below its float32 difference
    monkeypatch.setattr(control, "PROBE_TOL", ok / 2)
    monkeypatch.setattr(control, "_probed", {})
    out = tmp_path / "sw"
    args = ["sweep", "paper", "--plant", "mujoco", "--duration", "0.02", "--seeds", "2", "--quiet"]
    assert main([*args, "--backend", "warp", "--device", "cpu", "--out", str(out)]) == 2
    err = [e for e in capsys.readouterr().err.strip().splitlines() if e.startswith("error")]
    assert len(err) == 1 and err[0].startswith("error: --backend warp: scenario 'paper': MuJoCo Warp's physics")
    assert not out.exists()
    with pytest.raises(ValueError, match="differs from C MuJoCo's"):
        BatchRun([load("paper", overrides=["plant.kind=mujoco", "sim.duration=0.01"])])

"""One definition per concept (design §0): each concept below is defined (a ``def`` or a module-level
assignment) in exactly one module of the package, and its users share that one definition."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

PKG = Path(__file__).resolve().parent.parent / "src" / "bioform_mj"

#: concept -> the one module (relative to the package) that defines it
ONE_HOME: dict[str, str] = {
    "wrap": "core/equations.py",
    "welded_to": "robots/layout.py",
    "SUPPORT_CLEARANCE": "robots/layout.py",
    "floor_contacts": "robots/contacts.py",
    "self_contacts": "robots/contacts.py",
    "CASTER_LOAD": "robots/contacts.py",
    "is_caster": "robots/contacts.py",
    "brakes": "robots/contacts.py",
    "SELF_CONTACT_LOAD": "assess/causes.py",
}


def _definitions() -> dict[str, list[str]]:
    """name -> the modules that define it at their top level (``def``/``class`` or an assignment; not
    ``name = x.name``, which names another module's definition)."""
    out: dict[str, list[str]] = {}
    for p in sorted(PKG.rglob("*.py")):
        rel = p.relative_to(PKG).as_posix()
        for node in ast.parse(p.read_text()).body:
            names: list[str] = []
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                names = [node.name]
            elif isinstance(node, ast.Assign):
                names = [t.id for t in node.targets if isinstance(t, ast.Name)]
                if isinstance(node.value, ast.Attribute) and names == [node.value.attr]:
                    names = []  # ``wrap = EQ.wrap``: the same definition under its own name (a translation)
            elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
                names = [node.target.id]
            for n in names:
                out.setdefault(n, []).append(rel)
    return out


@pytest.mark.parametrize("name", sorted(ONE_HOME))
def test_defined_once(name):
    """The concept is defined in its one home and nowhere else (a wrapper under another name may use it)."""
    assert _definitions().get(name, []) == [ONE_HOME[name]], _definitions().get(name)


def test_array_wrap_is_the_equation():
    """``control.common.wrap_angles`` (figures, rerun) runs ``core.equations.wrap``'s own source on arrays,
    bit-equal to the compiled scalar."""
    from bioform_mj.control import common
    from bioform_mj.core import equations as eq

    assert common._WRAP is eq.EQUATIONS["wrap"]
    x = np.array([0.0, np.pi, -np.pi, 3 * np.pi, -3 * np.pi, 1e-17, 7.5, -7.5, 1e6, -1e6, 2 * np.pi])
    scalar = np.array([eq.wrap(float(v)) for v in x])
    assert np.array_equal(common.wrap_angles(x), scalar)


# ----------------------------------------------------------------------------- the outcome thresholds
def test_outcome_thresholds_have_one_home():
    """Every outcome threshold is defined in ``core/thresholds.py`` only (``SPIN`` was 10 rad/s in the fault
    table against 6 in a run's outcomes, ``tipped`` 60° against 30°)."""
    from bioform_mj.core import thresholds

    defs = _definitions()
    for name in thresholds.__all__:
        assert defs[name] == ["core/thresholds.py"], (name, defs[name])
    assert "SPIN" not in defs or defs["SPIN"] == ["batch/device.py"]


class _Plant:
    def __init__(self, cos_tilt):
        self._up = np.asarray(cos_tilt, dtype=float)

    def upright(self):
        return self._up


class _Result:
    """What ``run.faults.outcome`` reads of a run: a scenario, a log, a plant's ``upright``."""

    def __init__(self, cos_tilt, yaw_rate):
        from bioform_mj.scenario.loader import load

        self.scenario = load("paper")
        t = np.linspace(0.0, self.scenario.sim.duration, 5)
        n = self.scenario.n
        self.log = {
            "t": t,
            "formation_error": np.zeros((len(t), n)),
            "vel": np.zeros((len(t), n, 2)),
        }
        self.log["vel"][-1, :, 1] = yaw_rate
        self.diverged = None
        self.plant = _Plant(cos_tilt)


def test_fault_table_uses_the_run_thresholds():
    """The fault table's ``tipped_over``/``spinning`` (``run.faults.outcome``) flip where a run's outcomes do:
    at ``TIP_ANGLE_DEG`` and ``SPIN_RAD_S``."""
    import math

    from bioform_mj.core.thresholds import SPIN_RAD_S, TIP_ANGLE_DEG
    from bioform_mj.run.faults import outcome

    c = math.cos(math.radians(TIP_ANGLE_DEG))
    o = outcome(_Result([c + 1e-6, c - 1e-6, 1.0], [SPIN_RAD_S * 0.999, SPIN_RAD_S * 1.001, -SPIN_RAD_S * 1.001]))
    assert o["tipped_over"] == [2]
    assert o["spinning"] == [2, 3]


def test_outcome_list_reads_the_table():
    """A run's ``tipped``/``slipping`` details say the table's numbers (the CPU loops and the batch engine
    share :func:`~bioform_mj.assess.outcomes.outcome_list`)."""
    import inspect

    from bioform_mj.assess.outcomes import outcome_list
    from bioform_mj.core import thresholds as T

    sig = inspect.signature(outcome_list)
    assert sig.parameters["slip_ratio"].default == T.SLIP_RATIO
    assert sig.parameters["slip_time"].default == T.SLIP_TIME
    got = outcome_list(
        tip_t=1.0,
        slip_t=None,
        spinning=True,
        final=0.0,
        fe0=0.0,
        t_end=5.0,
        learning=False,
        c_hat=np.zeros(2),
        lo=np.zeros(2),
        hi=np.zeros(2),
        c_true=np.ones(2),
    )
    assert f"{T.TIP_ANGLE_DEG:g} deg" in got[0]["detail"] and f"{T.SPIN_RAD_S:g} rad/s" in got[1]["detail"]


def test_mujoco_plant_watches_the_table():
    """The MuJoCo plant's in-loop tilt watch compares with ``cos(TIP_ANGLE_DEG)`` of the table."""
    import math

    from bioform_mj.core.thresholds import TIP_ANGLE_DEG
    from bioform_mj.plants.mujoco.plant import MujocoPlant

    assert MujocoPlant.TIP_ANGLE == pytest.approx(math.radians(TIP_ANGLE_DEG), rel=0, abs=0)


def test_batch_device_constant_is_the_table():
    """The batch engine's ``SPIN`` device constant is the table's ``SPIN_RAD_S`` (derived, not typed again)."""
    pytest.importorskip("warp")
    pytest.importorskip("mujoco_warp")
    from bioform_mj.batch import device
    from bioform_mj.core.thresholds import SPIN_RAD_S

    assert float(device.SPIN) == SPIN_RAD_S


# ----------------------------------------------------------------------------- floor contacts and braking
def test_no_second_braking_threshold():
    """Identification's own ``CASTER_MU`` (μ > 0.01) and ``CASTER_LOAD`` (1 %) are gone: it uses robot check's."""
    defs = _definitions()
    assert "CASTER_MU" not in defs and "SELF_FORCE" not in defs  # robot check's 1 % self-contact force: causes'
    assert defs["CASTER_LOAD"] == ["robots/contacts.py"]


@pytest.mark.parametrize("share", [0.004, 0.006, 0.02])
@pytest.mark.parametrize("mu", [5e-4, 2e-3, 0.5])
@pytest.mark.parametrize("condim", [1, 3])
@pytest.mark.parametrize("rolls", [False, True])
def test_identification_and_robot_check_share_the_braking_rule(share, mu, condim, rolls):
    """A floor contact brakes for identification (at rest and as a drive test's mean,
    ``causes.dragging_brakes``) exactly when it does for robot check and a run's outcomes
    (``contacts.brakes`` on a row classified by ``contacts.is_caster``)."""
    from bioform_mj.assess.causes import dragging_brakes
    from bioform_mj.robots.contacts import CASTER_LOAD, brakes, is_caster

    weight = 100.0
    row = {"load_n": share * weight, "friction": mu, "condim": condim, "rolls": rolls, "geom": "g", "body": "b"}
    at_rest = {**row, "role": "caster" if is_caster(row["load_n"], weight) else "other"}
    want = share > CASTER_LOAD and mu >= 1e-3 and condim != 1 and not rolls
    assert brakes(at_rest) == want
    assert dragging_brakes({**row, "role": "other"}, weight) == want
    assert dragging_brakes({**row, "role": "caster"}, weight) == want  # the role is the mean's, not a sample's
    assert dragging_brakes({**row, "role": "other"}, weight, named=True) == (mu >= 1e-3 and condim != 1 and not rolls)
    assert not dragging_brakes({**row, "role": "wheel"}, weight)

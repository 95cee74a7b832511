"""The robot-format registry (design §12): every registered format loads a small sample robot through
``prepare_robot`` and yields the same layout, with the numbers the zoo's independent reference recorded.

The sample of every format is the same robot, ROBOTIS' TurtleBot3 Burger, as published in MJCF (the menagerie) and
in URDF (turtlebot3_description): a new format adds its module, its registry line and its sample here."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import pytest

from bioform_mj.robots.formats import RobotFormat, format_of, register_format, robot_formats
from bioform_mj.robots.prepare import prepare_robot
from bioform_mj.robots.refs import ROBOT_SUFFIXES, RobotRef

ZOO = Path(__file__).resolve().parent / "zoo"
EXPECT = json.loads((ZOO / "expectations.json").read_text())
#: format -> zoo robot (expectations.json): the same TurtleBot3 Burger in each format
SAMPLES = {"mjcf": "robotis_tb3_burger", "urdf": "tb3_burger_urdf"}


def _ref(name: str) -> RobotRef:
    e = EXPECT[name]
    m = e["mapping"]
    # tau_max: the XL430-W250's stall torque (the zoo's reference; neither file has a usable limit)
    return RobotRef(str(ZOO / e["file"]), base=m["base"], left_wheel=m["left_wheel"], right_wheel=m["right_wheel"],
                    tau_max=1.4)  # fmt: skip


def test_every_format_has_a_sample_and_its_suffixes_make_a_path():
    names = [f.name for f in robot_formats()]
    assert set(names) == set(SAMPLES)
    assert names[-1] == "mjcf"  # the fallback is tried last
    for f in robot_formats():
        assert set(f.suffixes) <= set(ROBOT_SUFFIXES), f.name
        assert f.confines and isinstance(f.xacro, bool)
    assert [f.name for f in robot_formats() if f.xacro] == ["urdf"]
    assert [f.name for f in robot_formats() if not f.self_collision] == ["urdf"]  # the Gazebo convention


@pytest.mark.parametrize("fmt", [f.name for f in robot_formats()])
def test_each_format_loads_its_sample(fmt):
    """Detected as its format; the layout has the same fields and mapping for each, and the wheel radius and half
    track the zoo's reference (mujoco + numpy, tests/zoo/reference.py) recorded, within 0.1 %."""
    name = SAMPLES[fmt]
    ref = _ref(name)
    assert format_of(ref.model).name == fmt
    _spec, layout, _axle, _yaw = prepare_robot(ref)
    assert set(asdict(layout)) == set(asdict(prepare_robot(_ref(SAMPLES["mjcf"]))[1]))
    assert layout.base == ref.base and list(layout.wheel_joints) == [ref.left_wheel, ref.right_wheel]
    assert layout.wheel_radius == pytest.approx(EXPECT[name]["r_m"], rel=1e-3)
    assert layout.half_track == pytest.approx(EXPECT[name]["l_m"], rel=1e-3)
    assert layout.tau_max == pytest.approx(1.4)
    if (precheck := format_of(ref.model).precheck) is not None:
        precheck(ref)  # the published sample passes its format's checks before any work
    from bioform_mj.jobs.provenance import file_hash, model_files

    read = format_of(ref.model).files
    files = read(ref, file_hash) if read is not None else model_files(ref.model)
    assert files[str(Path(ref.model).resolve())] == file_hash(ref.model)  # the provenance holds the file itself
    from bioform_mj.robots.overlaps import published_model

    pub = published_model(ref)  # as published: the base and both wheel joints are there
    assert pub.body(ref.base).id >= 0 and pub.joint(ref.left_wheel).id >= 0 and pub.joint(ref.right_wheel).id >= 0


def test_a_new_format_is_one_registration(tmp_path):
    """A registered format is tried before the fallback, and prepare_robot loads a file of it with its loader."""
    from bioform_mj.robots.mjcf import load_mjcf

    calls = []
    tb3 = Path(_ref(SAMPLES["mjcf"]).model)

    def load(ref, path):  # reads the published TurtleBot3 in place of the probe file
        calls.append(path)
        return load_mjcf(ref, tb3)

    fmt = RobotFormat("probe", (".xml",), lambda p: p.name == "probe.xml", load, "nothing", False)
    register_format(fmt)
    try:
        f = tmp_path / "probe.xml"
        f.write_text("<mujoco/>")
        assert format_of(f) is fmt and format_of(tmp_path / "other.xml").name == "mjcf"
        assert [x.name for x in robot_formats()][-2:] == ["probe", "mjcf"]
        ref = _ref(SAMPLES["mjcf"])
        layout = prepare_robot(RobotRef(str(f), base=ref.base, left_wheel=ref.left_wheel,
                                        right_wheel=ref.right_wheel, tau_max=1.4))[1]  # fmt: skip
        assert calls == [f] and layout.wheel_radius == pytest.approx(EXPECT[SAMPLES["mjcf"]]["r_m"], rel=1e-3)
    finally:
        from bioform_mj.robots import formats

        formats._FORMATS.pop("probe")
    assert [x.name for x in robot_formats()] == ["urdf", "mjcf"]


def test_mjcf_published_model_reads_the_mapping_as_its_loader_does(tmp_path):
    """The MJCF format's published model (robot check's overlaps) applies ``balance_inertia`` as the loader
    does: a chassis inertia 0.3 > 0.0832 + 0.137 breaks the triangle inequality, MuJoCo refuses it unbalanced
    (a ModelError naming the option, exit 2; it was a bare ValueError there), and with the mapping's
    balance_inertia both the loader and the published model compile it."""
    from dataclasses import replace

    from bioform_mj.robots.formats import format_of
    from bioform_mj.robots.layout import ModelError
    from bioform_mj.robots.refs import models_dir, resolve_robot

    text = (models_dir() / "paper_robot.xml").read_text()
    old = 'diaginertia="0.0832 0.0832 0.137366667"'
    assert text.count(old) == 1
    path = tmp_path / "odd.xml"
    path.write_text(text.replace(old, 'diaginertia="0.3 0.0832 0.137366667"'))
    ref = resolve_robot(str(path))
    fmt = format_of(path)
    with pytest.raises(ModelError, match="does not compile"):
        fmt.published(ref)
    ok = replace(ref, balance_inertia=True)
    model = fmt.published(ok)
    assert model.nbody == fmt.load(ok, path)[1].nbody
    assert model.body_inertia[1:].min() > 0

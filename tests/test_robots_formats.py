"""The robot-format registry (design §12): every registered format loads a small sample robot through
``prepare_robot`` and yields the same layout, with the numbers the zoo's independent reference recorded.

The sample of every format is the same robot, ROBOTIS' TurtleBot3 Burger, as published in MJCF (the menagerie) and
in URDF (turtlebot3_description): a new format adds its module, its registry line and its sample here."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import pytest

from bioform_mj.robots.formats import (
    RobotFormat,
    format_of,
    looks_like_path,
    register_format,
    robot_formats,
    robot_suffixes,
)
from bioform_mj.robots.prepare import prepare_robot
from bioform_mj.robots.refs import RobotRef

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
        assert set(f.suffixes) <= set(robot_suffixes()), f.name
        assert f.confines and isinstance(f.xacro, bool)
    assert [f.name for f in robot_formats() if f.xacro] == ["urdf"]
    assert [f.name for f in robot_formats() if not f.self_collision] == ["urdf"]  # the Gazebo convention
    assert robot_suffixes() == (".urdf", ".xacro", ".xml")
    assert [f.name for f in robot_formats() if f.wheel_speed is not None] == ["urdf"]  # MJCF states no top speed
    assert all(f.editable is not None for f in robot_formats())  # each can be calibrated (robot fit)


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

    from bioform_mj.robots.entries import resolve_robot
    from bioform_mj.robots.formats import format_of
    from bioform_mj.robots.layout import ModelError
    from bioform_mj.robots.refs import models_dir

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


def _toy_format():
    """A toy format: a ``.toyrobot`` file is an MJCF file renamed (without assets), read from its text (MuJoCo picks
    its decoder by the suffix); its stated top wheel speed is 2.5 rad/s (the hook a format's top speed comes
    through)."""
    import mujoco

    def spec_of(path):
        return mujoco.MjSpec.from_string(Path(path).read_text())

    def load(ref, path):
        spec = spec_of(path)
        return spec, spec.compile(), ref, (), "", (), ()

    return RobotFormat(
        "toyrobot",
        (".TOYROBOT",),
        lambda p: str(p).lower().endswith(".toyrobot"),
        load,
        "nothing: a toy",
        False,
        published=lambda ref: spec_of(ref.model).compile(),
        wheel_speed=lambda ref, path, joints: 2.5,
        wheel_speed_what="the toy file's wheel speed",
        editable=lambda ref: spec_of(ref.model),
    )


def test_a_registered_format_is_a_path(tmp_path, monkeypatch):
    """Registering a ``.toyrobot`` format (the paper robot's MJCF renamed) makes its suffix a path (the registry's
    suffixes, not a hand-written list): a bare ``paper.toyrobot`` is refused as an unknown robot before and resolves
    to the file after, a scenario file's relative entry is rebased, ``prepare_robot`` loads it with the ``.xml``'s
    layout, and its format's stated wheel speed is what :func:`file_wheel_speed` reads (MJCF: none)."""
    from dataclasses import asdict

    from bioform_mj.core.errors import InputError
    from bioform_mj.robots import formats
    from bioform_mj.robots.entries import rebase_entries, resolve_robot
    from bioform_mj.robots.limits import file_wheel_speed
    from bioform_mj.robots.refs import models_dir

    monkeypatch.chdir(tmp_path)
    toy = tmp_path / "paper.toyrobot"
    toy.write_text((models_dir() / "paper_robot.xml").read_text())
    assert not looks_like_path("paper.toyrobot") and ".toyrobot" not in robot_suffixes()
    with pytest.raises(InputError, match="unknown robot 'paper.toyrobot'"):
        resolve_robot("paper.toyrobot")
    assert rebase_entries(["paper.toyrobot"], tmp_path / "sub") == ["paper.toyrobot"]  # a name, not a path
    register_format(_toy_format())
    try:
        assert robot_suffixes() == (".urdf", ".xacro", ".toyrobot", ".xml")
        assert looks_like_path("paper.toyrobot") and looks_like_path("Paper.TOYROBOT")
        assert format_of(toy).name == "toyrobot" and format_of(tmp_path / "x.xml").name == "mjcf"
        assert resolve_robot("paper.toyrobot").model == "paper.toyrobot"
        assert rebase_entries(["paper.toyrobot", "paper"], tmp_path / "sub") == [
            str(tmp_path / "sub" / "paper.toyrobot"),
            "paper",
        ]
        lay = asdict(prepare_robot(resolve_robot("paper.toyrobot"))[1])
        ref_lay = asdict(prepare_robot(resolve_robot("paper"))[1])
        assert lay == {**ref_lay, "file": lay["file"]} and Path(lay["file"]).resolve() == toy.resolve()
        w, why, fmt = file_wheel_speed(str(toy), ["left_wheel", "right_wheel"])
        assert (w, why, fmt.name) == (2.5, "", "toyrobot")
        w, why, fmt = file_wheel_speed(str(models_dir() / "paper_robot.xml"), ["left_wheel", "right_wheel"])
        assert (w, why, fmt.name) == (None, "", "mjcf")
    finally:
        formats._FORMATS.pop("toyrobot")
    assert ".toyrobot" not in robot_suffixes() and not looks_like_path("paper.toyrobot")


@pytest.mark.slow
def test_robot_check_and_a_run_read_a_registered_format(tmp_path, monkeypatch):
    """``robot check --json`` on the toy format's ``paper.toyrobot`` reports every number the ``.xml``'s does, but
    the top speed the format states (2.5 rad/s × r, source ``toyrobot``); a 0.5 s MuJoCo run on it logs the same
    trajectory and torques, bit for bit, as the run on the ``.xml``."""
    import numpy as np

    from bioform_mj.cli import main as cli
    from bioform_mj.robots import formats
    from bioform_mj.robots.refs import models_dir
    from bioform_mj.run.simulate import simulate
    from bioform_mj.scenario.loader import load

    monkeypatch.chdir(tmp_path)
    toy = tmp_path / "paper.toyrobot"
    toy.write_text((models_dir() / "paper_robot.xml").read_text())
    register_format(_toy_format())
    try:
        reports = {}
        for name, entry in (("toy", "paper.toyrobot"), ("xml", "paper")):
            out = tmp_path / f"{name}.json"
            assert cli.main(["robot", "check", entry, "--json", str(out)]) == 0
            reports[name] = json.loads(out.read_text())
        toy_r, xml_r = reports["toy"], reports["xml"]
        r = xml_r["wheel_radius_m"]
        assert toy_r["model"] == toy_r["parts"]["file"] == "paper.toyrobot"
        assert toy_r["limits"]["top_speed_source"] == "toyrobot" and toy_r["limits"]["missing"] == []
        assert toy_r["limits"]["top_speed_mps"] == pytest.approx(2.5 * r, rel=1e-12)
        assert toy_r["limits"]["top_speed_note"].startswith("the toy file's wheel speed 2.5 rad/s")
        assert xml_r["limits"]["top_speed_mps"] is None  # the paper's MJCF states none
        same = {**toy_r, "model": xml_r["model"], "parts": {**toy_r["parts"], "file": xml_r["parts"]["file"]}}
        keep = ("top_speed_mps", "top_speed_source", "top_speed_note", "wheel_speed_radps", "missing")
        same["limits"] = {**toy_r["limits"], **{k: xml_r["limits"][k] for k in keep}}
        assert same == xml_r  # every other number robot check reports is the .xml's
        logs = {}
        for name, entry in (("toy", "paper.toyrobot"), ("xml", "paper")):
            sc = load(None, ["sim.duration=0.5", f"plant.robots=[{json.dumps(entry)}]", "plant.kind=mujoco"])
            logs[name] = simulate(sc).log
        for k in ("pose", "tau"):
            np.testing.assert_array_equal(logs["toy"][k], logs["xml"][k])
    finally:
        formats._FORMATS.pop("toyrobot")
    assert ".toyrobot" not in robot_suffixes() and not looks_like_path("paper.toyrobot")

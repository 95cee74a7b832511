"""An MJCF robot's files stay in its folder (issue 28, design §12; :mod:`bioform_mj.robots.mjcf_assets`).

Hostile robot files (an absolute ``/etc`` path as a mesh, a ``../`` escape, a symlink out, an include chain
escaping, ``meshdir`` pointing out, a cube texture's face, a height field, a flexcomp, a scenario naming such a
robot) are refused with one ``error:`` line naming the element and the path, exit 2, before MuJoCo reads
anything: the file outside is a FIFO, which any read would block on (the test would time out, not pass), and
nothing of it reaches a run's folder. ``asset_roots`` / ``--asset-root`` let the same files in."""

from __future__ import annotations

import os
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from bioform_mj.cli import main as cli
from bioform_mj.robots.mjcf_assets import AssetEscape, confine_mjcf, grant_roots
from bioform_mj.robots.refs import RobotRef, as_ref, models_dir

SRC = str(Path(__file__).resolve().parents[1] / "src")
PAPER = (models_dir() / "paper_robot.xml").read_text()
HOW = 'assets kept elsewhere: --asset-root DIR, or asset_roots = ["DIR"] in the robot\'s table'


def _stl(path: Path, scale: float = 0.01) -> Path:
    """A binary STL tetrahedron of edge ``scale`` m (4 facets)."""
    v = [(0, 0, 0), (scale, 0, 0), (0, scale, 0), (0, 0, scale)]
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    data = b"\0" * 80 + struct.pack("<I", len(faces))
    for f in faces:
        data += struct.pack("<3f", 0, 0, 0) + b"".join(struct.pack("<3f", *v[i]) for i in f) + b"\0\0"
    path.write_bytes(data)
    return path


def _robot(folder: Path, name: str, assets: str = "", compiler: str = "", head: str = "") -> Path:
    """The shipped paper robot with ``assets`` (XML) before its worldbody, ``compiler`` attributes, ``head`` XML."""
    text = PAPER.replace(
        '<compiler angle="radian" autolimits="true"/>', f'<compiler angle="radian" autolimits="true"{compiler}/>{head}'
    ).replace("<worldbody>", f"{assets}<worldbody>", 1)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_text(text)
    return folder / name


@pytest.fixture
def place(tmp_path):
    """``(robot folder, outside folder)``; the outside holds a FIFO ``trap.stl`` (a read blocks) and a mesh."""
    r, out = tmp_path / "robot", tmp_path / "outside"
    (r / "meshes").mkdir(parents=True)
    out.mkdir()
    os.mkfifo(out / "trap.stl")
    _stl(out / "ok.stl")
    grant_roots(())
    yield r, out
    grant_roots(())


def _hostile(r: Path, out: Path, case: str) -> tuple[Path, str]:
    """A hostile robot file and the text its refusal must hold (element and path)."""
    trap = out / "trap.stl"
    if case == "absolute-etc":
        return _robot(r, "a.xml", '<asset><mesh name="e" file="/etc/passwd"/></asset>'), '<mesh file="/etc/passwd"/>'
    if case == "dotdot":
        return _robot(r, "a.xml", '<asset><mesh name="e" file="../outside/trap.stl"/></asset>'), (
            f"<mesh file=\"../outside/trap.stl\"/> ('{trap}')"
        )
    if case == "symlink-out":
        os.symlink(trap, r / "meshes" / "link.stl")
        return _robot(r, "a.xml", '<asset><mesh name="e" file="link.stl"/></asset>', ' meshdir="meshes"'), (
            f"a symlink to '{trap}'"
        )
    if case == "meshdir-out":
        return _robot(r, "a.xml", '<asset><mesh name="e" file="trap.stl"/></asset>', ' meshdir="../outside"'), (
            '<compiler meshdir="../outside"/>'
        )
    if case == "assetdir-abs":
        return _robot(r, "a.xml", '<asset><mesh name="e" file="trap.stl"/></asset>', f' assetdir="{out}"'), (
            f'<compiler assetdir="{out}"/>'
        )
    if case == "include-chain":
        (r / "inc1.xml").write_text('<mujoco><include file="meshes/inc2.xml"/></mujoco>')
        (r / "meshes" / "inc2.xml").write_text('<mujoco><include file="../outside/inc3.xml"/></mujoco>')
        (out / "inc3.xml").write_text('<mujoco><asset><mesh name="e" file="/etc/hostname"/></asset></mujoco>')
        return _robot(r, "a.xml", head='<include file="inc1.xml"/>'), (
            '<include file="inc1.xml"/> → <include file="meshes/inc2.xml"/> → <include file="../outside/inc3.xml"/>'
        )
    if case == "include-fifo-abs":
        return _robot(r, "a.xml", head=f'<include file="{out / "trap.stl"}"/>'), f'<include file="{trap}"/>'
    if case == "included-mesh-out":  # the include is inside; the mesh it names is not
        (r / "inc.xml").write_text(f'<mujoco><asset><mesh name="e" file="{trap}"/></asset></mujoco>')
        return _robot(
            r, "a.xml", head='<include file="inc.xml"/>'
        ), f'<include file="inc.xml"/> → <mesh file="{trap}"/>'
    if case == "attached-model":  # an <asset><model file> inside the folder whose own mesh is not
        (r / "sub").mkdir()
        (r / "sub" / "child.xml").write_text(
            f'<mujoco><asset><mesh name="e" file="{trap}"/></asset><worldbody><body name="c"/></worldbody></mujoco>'
        )
        return _robot(r, "a.xml", '<asset><model name="c" file="sub/child.xml"/></asset>'), (
            f'<model file="sub/child.xml"/> → <mesh file="{trap}"/>'
        )
    if case == "cube-face":
        faces = " ".join(f'file{s}="a.png"' for s in ("left", "up", "down", "front", "back"))
        return _robot(r, "a.xml", f'<asset><texture name="t" type="cube" fileright="{trap}" {faces}/></asset>'), (
            f'<texture fileright="{trap}"/>'
        )
    if case == "hfield":
        return _robot(r, "a.xml", f'<asset><hfield name="h" file="{trap}" size="1 1 1 1"/></asset>'), (
            f'<hfield file="{trap}"/>'
        )
    if case == "flexcomp":  # read while parsing, not compiling
        return _robot(r, "a.xml", head=f'<worldbody><flexcomp name="f" type="mesh" file="{trap}"/></worldbody>'), (
            f'<flexcomp file="{trap}"/>'
        )
    raise AssertionError(case)


CASES = [
    "absolute-etc",
    "dotdot",
    "symlink-out",
    "meshdir-out",
    "assetdir-abs",
    "include-chain",
    "include-fifo-abs",
    "included-mesh-out",
    "attached-model",
    "cube-face",
    "hfield",
    "flexcomp",
]


@pytest.mark.parametrize("case", CASES)
def test_hostile_mjcf_refused_before_mujoco_reads(place, case, capsys):
    r, out = place
    path, needle = _hostile(r, out, case)
    code = cli.main(["robot", "check", str(path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith(f"error: {path}: "), err
    assert needle in err[0] and "outside the robot's folder" in err[0] and HOW in err[0], err
    with pytest.raises(AssetEscape):  # the Python API: a ValueError naming the same
        confine_mjcf(path)


@pytest.mark.slow  # ~3.5 s: a process of its own (the in-process cases above already read FIFOs that would hang)
def test_scenario_naming_hostile_robot_writes_nothing(place, tmp_path):
    """``bioform run scenario.toml`` whose robot (relative to the file) reads a FIFO outside: exit 2 in a
    subprocess (a read would hang it past the timeout), no run folder, nothing of the outside copied."""
    r, out = place
    _hostile(r, out, "dotdot")
    scen = tmp_path / "s.toml"
    scen.write_text('[plant]\nkind = "mujoco"\nrobots = ["robot/a.xml"]\n[sim]\nduration = 0.1\n')
    run = tmp_path / "run"
    res = subprocess.run(
        [sys.executable, "-m", "bioform_mj.cli", "run", str(scen), "--out", str(run), "--quiet"],
        env={**os.environ, "PYTHONPATH": SRC},
        capture_output=True,
        text=True,
        timeout=120,
    )
    err = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(err) == 1 and '<mesh file="../outside/trap.stl"/>' in err[0], err
    assert not run.exists()


def test_files_inside_the_folder_are_taken(place):
    """No false refusal: ``meshdir="meshes"`` with ``../m2/x.stl`` (still inside), an include in a subfolder
    naming a mesh relative to ``meshdir``, an absolute path inside the folder: the model compiles with 3 meshes."""
    from bioform_mj.robots.prepare import prepare_robot

    r, _ = place
    (r / "m2").mkdir()
    _stl(r / "m2" / "x.stl")
    _stl(r / "meshes" / "y.stl")
    _stl(r / "z.stl")
    (r / "parts").mkdir()
    (r / "parts" / "inc.xml").write_text('<mujoco><asset><mesh name="y" file="y.stl"/></asset></mujoco>')
    assets = f'<asset><mesh name="x" file="../m2/x.stl"/><mesh name="z" file="{r / "z.stl"}"/></asset>'
    path = _robot(r, "good.xml", assets, ' meshdir="meshes"', '<include file="parts/inc.xml"/>')
    confine_mjcf(path)
    spec = prepare_robot(RobotRef(model=str(path)))[0]
    assert spec.compile().nmesh == 3


def test_asset_roots_opt_in(place, capsys):
    """The same outside mesh: refused without, compiled with ``asset_roots`` (the mapping key) and with
    ``--asset-root`` (the flag: as far as the robot check's own refusal, which names no asset)."""
    from bioform_mj.robots.prepare import prepare_robot

    r, out = place
    path = _robot(r, "a.xml", '<asset><mesh name="ok" file="../outside/ok.stl"/></asset>')
    with pytest.raises(ValueError, match="outside the robot's folder"):
        prepare_robot(RobotRef(model=str(path)))
    ref = as_ref({"model": str(path), "asset_roots": [str(out)]})
    assert ref.asset_roots == (str(out),) and not ref.mapped and ref.to_entry()["asset_roots"] == [str(out)]
    assert prepare_robot(ref)[0].compile().nmesh == 1
    grant_roots([out])
    assert prepare_robot(RobotRef(model=str(path)))[0].compile().nmesh == 1
    grant_roots(())
    code = cli.main(["robot", "check", str(path), "--asset-root", str(out / "nope")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err == [f"error: --asset-root {out / 'nope'}: no such directory"], err


def test_sweep_refuses_asset_root_flag(place, capsys):
    _, out = place
    code = cli.main(["sweep", "paper", "--asset-root", str(out), "--out", str(out / "sw")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "sweep --asset-root" in err[0] and "asset_roots" in err[0], err
    assert not (out / "sw").exists()


def test_toml_asset_roots_relative_to_the_file(tmp_path):
    """``asset_roots`` in a scenario file resolve against the file's folder, as its robot paths do."""
    from bioform_mj.scenario.loader import load

    (tmp_path / "robot").mkdir()
    (tmp_path / "robot" / "a.xml").write_text(PAPER)
    (tmp_path / "shared").mkdir()
    scen = tmp_path / "s.toml"
    scen.write_text('[plant]\nkind = "mujoco"\nrobots = [{model = "robot/a.xml", asset_roots = ["shared"]}]\n')
    ref = load(str(scen)).plant.robots[0]
    assert ref.asset_roots == (str((tmp_path / "shared").resolve()),)


# ------------------------------------------------------------------ a URDF's absolute and file:// meshes
@pytest.mark.parametrize("form", ["absolute", "file-uri"])
def test_urdf_absolute_mesh_outside_refused_unless_granted(place, form, capsys):
    """A URDF collision mesh named ``/…/outside/ok.stl`` (a real mesh) or ``file://`` of it is refused, exit 2,
    naming it; a visual one is dropped with a note (never read); ``asset_roots`` lets it in."""
    from bioform_mj.robots.urdf import import_urdf
    from test_robots_urdf import diff_drive, write

    r, out = place
    name = str(out / "ok.stl") if form == "absolute" else f"file://{out / 'ok.stl'}"
    path = write(r / "urdf" / "dd.urdf", diff_drive(chassis_collision=f'<mesh filename="{name}"/>'))
    code = cli.main(["robot", "check", str(path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and f"<collision> mesh '{name}' of link 'base_link'" in err[0], err
    assert f"'{out / 'ok.stl'}' is outside the robot's package '{r}'" in err[0] and HOW in err[0], err
    vis = write(r / "urdf" / "v.urdf", diff_drive(chassis_visual=f'<mesh filename="{name}"/>'))
    notes = import_urdf(RobotRef(model=str(vis))).notes
    assert any("1 visual mesh(es) dropped" in n and "outside the robot's package" in n for n in notes), notes
    good = write(r / "urdf" / "g.urdf", diff_drive(chassis_visual=f'<mesh filename="{name}"/>'))
    assert import_urdf(RobotRef(model=str(good), asset_roots=(str(out),))).model.nmesh == 1


def test_scenario_naming_hostile_robot_in_process(place, tmp_path, capsys):
    """The same through ``cli.main`` and ``bioform_mj.load``: exit 2 / a ValueError naming the mesh, no run folder."""
    import bioform_mj

    r, out = place
    _hostile(r, out, "symlink-out")
    scen = tmp_path / "s.toml"
    scen.write_text('[plant]\nkind = "mujoco"\nrobots = ["robot/a.xml"]\n[sim]\nduration = 0.1\n')
    run = tmp_path / "run"
    code = cli.main(["run", str(scen), "--out", str(run), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and f"a symlink to '{out / 'trap.stl'}'" in err[0], err
    assert not run.exists()
    with pytest.raises(ValueError, match="outside the robot's folder"):
        bioform_mj.load(str(scen))


@pytest.mark.slow  # a robot check: ~3 s
def test_urdf_top_speed_read_with_the_asset_roots(place):
    """A URDF whose collision mesh is let in only through ``asset_roots`` still reports its wheels'
    ``<limit velocity>`` 10 rad/s × r as the top speed (issue 28: it was re-read without the roots and
    silently reported none)."""
    from bioform_mj.assess.check import check
    from bioform_mj.robots.entries import resolve_robot
    from test_robots_urdf import R_WHEEL, diff_drive, write

    r, out = place
    path = write(r / "urdf" / "dd.urdf", diff_drive(chassis_collision=f'<mesh filename="{out / "ok.stl"}"/>'))
    ref = resolve_robot(RobotRef(model=str(path), asset_roots=(str(out),)))
    lim = check(ref, identify_=False)["limits"]
    assert lim["top_speed_source"] == "urdf", lim
    assert lim["top_speed_mps"] == pytest.approx(10.0 * R_WHEEL, rel=1e-9)


# ------------------------------------------------------------------ asset_roots that do not exist (issue 28)
@pytest.mark.parametrize("what", ["missing", "a-file", "unreadable"])
def test_asset_roots_entry_must_be_a_readable_directory(what, tmp_path, capsys, monkeypatch):
    """A typo in ``asset_roots`` is one ``error:`` line naming the key and the path, exit 2, before any work
    (it was taken in and surfaced only as an "outside the robot's folder" refusal naming the roots)."""
    (tmp_path / "robot").mkdir()
    (tmp_path / "robot" / "a.xml").write_text(PAPER)
    root = tmp_path / "shraed"
    if what == "a-file":
        root.write_text("x")
    elif what == "unreadable":  # root reads every folder: the permission is simulated
        root.mkdir()
        real = os.access
        monkeypatch.setattr(os, "access", lambda p, m, **k: False if str(p) == str(root) else real(p, m, **k))
    scen = tmp_path / "s.toml"
    scen.write_text(
        '[plant]\nkind = "ideal"\nrobots = [{model = "robot/a.xml", asset_roots = ["shraed"]}]\n'
        "[sim]\nduration = 0.05\n"
    )
    code = cli.main(["run", str(scen), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    why = {"missing": "does not exist", "a-file": "is not a directory", "unreadable": "cannot be read"}[what]
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith("error: scenario key 'plant.robots[0].asset_roots': ") and why in err[0], err
    assert str(root) in err[0] and not (tmp_path / "out").exists()
    from bioform_mj.robots.prepare import prepare_robot

    with pytest.raises(ValueError, match=f"asset_roots: '{root}' {why}"):  # the Python API too
        prepare_robot(RobotRef(model=str(tmp_path / "robot" / "a.xml"), asset_roots=(str(root),)))


# ------------------------------------------------------------------ one list of a spec's files (issue 28)
def test_spec_files_lists_every_cube_face_for_every_user(tmp_path):
    """:func:`spec_files` is the one list: the escape check, the special-file check and the absolute names
    each see all six cube faces, a mesh, a skin-less hfield; the spec's own assets and empty names are left out."""
    import mujoco

    from bioform_mj.robots.mjcf import absolute_asset_files
    from bioform_mj.robots.mjcf_assets import spec_escape
    from bioform_mj.robots.sanity import spec_file_problem
    from bioform_mj.robots.spec_files import CUBE_FACES, spec_files

    faces = " ".join(f'{a}="t/{a}.png"' for a in CUBE_FACES)
    xml = _robot(
        tmp_path / "r",
        "a.xml",
        f'<asset><texture name="c" type="cube" {faces}/><mesh name="m" file="m.stl"/>'
        '<hfield name="h" file="h.png" size="1 1 1 1"/><texture name="g" type="2d" builtin="checker" '
        'width="8" height="8"/></asset>',
    )
    spec = mujoco.MjSpec.from_file(str(xml))
    got = [(f.kind, f.attr, f.name) for f in spec_files(spec)]
    assert got == [
        ("mesh", "file", "m.stl"),
        ("hfield", "file", "h.png"),
        *(("texture", a, f"t/{a}.png") for a in CUBE_FACES),
    ]
    assert spec_escape(spec, (str(tmp_path / "elsewhere"),)).startswith('<mesh file="m.stl"/>')
    (tmp_path / "r" / "t").mkdir()
    os.mkfifo(tmp_path / "r" / "t" / "filedown.png")  # the fourth face: a read would block
    assert spec_file_problem(spec) == (
        f"texture filedown {tmp_path / 'r' / 't' / 'filedown.png'}: "
        f"'{tmp_path / 'r' / 't' / 'filedown.png'}' is a FIFO (named pipe), not a regular file: not read "
        "(reading it could block)"
    )
    absolute_asset_files(spec)
    assert list(spec.textures[0].cubefiles) == [str(tmp_path / "r" / "t" / f"{a}.png") for a in CUBE_FACES]
    assert [f.name for f in spec_files(spec)][:2] == [str(tmp_path / "r" / "m.stl"), str(tmp_path / "r" / "h.png")]


def test_fifo_cube_face_inside_the_folder_is_a_bounded_refusal(tmp_path):
    """A FIFO inside the robot's folder as a cube texture's face passes the escape check (it is inside) and
    was handed to MuJoCo's compiler, whose read blocks: now ``robot check`` refuses it before MuJoCo reads the
    file (the XML walk checks every file it names), one ``error:`` line naming the face, exit 2 (in a process
    of its own: a regression times out, never passes)."""
    r = tmp_path / "r"
    r.mkdir()
    os.mkfifo(r / "face.png")
    faces = " ".join(f'{a}="face.png"' for a in ("fileright", "fileleft", "fileup", "filedown", "filefront"))
    xml = _robot(r, "a.xml", f'<asset><texture name="c" type="cube" {faces} fileback="face.png"/></asset>')
    res = subprocess.run(
        [sys.executable, "-m", "bioform_mj.cli", "robot", "check", str(xml)],
        env={**os.environ, "PYTHONPATH": SRC},
        capture_output=True,
        text=True,
        timeout=120,
    )
    err = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(err) == 1, err
    assert err[0].startswith("error: ") and f"<texture fileright=\"face.png\"/> ('{r / 'face.png'}')" in err[0], err
    assert f"'{r / 'face.png'}' is a FIFO" in err[0], err

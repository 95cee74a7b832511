"""Red team, round three (issue 28): hostile paths, robot files and scenarios not covered elsewhere.

Each case runs ``bioform`` in-process and must end in exactly one ``error:`` line naming the cause,
exit 2, before any work (nothing written), or, where the input is legitimate, a correct answer. The
FIFO cases would block a read: a regression hangs (the test times out), it never passes. Cases measured
before the fixes (``/tmp`` harness under ``ulimit -v 4000000``, ``timeout 60``): a FIFO beside a glTF
mesh hung ``robot check``; a URDF of 10^5 links ran 538 s and an MJCF of 10^5 bodies over 590 s,
deaf to SIGTERM; a name too long for the file
system and a TOML nested 10^5 deep were ``internal error`` lines with exit 1."""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from bioform_mj.cli import main as cli
from bioform_mj.robots.refs import models_dir

PAPER = (models_dir() / "paper_robot.xml").read_text()
PY = sys.executable
IDEAL = 'name = "t"\n[plant]\nkind = "ideal"\n[sim]\nduration = 0.05\n'


def _robot(folder: Path, name: str = "r.xml", assets: str = "", head: str = "") -> Path:
    """The shipped paper robot with ``assets`` before its worldbody and ``head`` before ``</mujoco>``."""
    folder.mkdir(parents=True, exist_ok=True)
    text = PAPER.replace("<worldbody>", f"{assets}<worldbody>", 1).replace("</mujoco>", f"{head}</mujoco>")
    (folder / name).write_text(text)
    return folder / name


def _stl(path: Path, declared: int) -> Path:
    """A binary STL of 4 facets whose header declares ``declared`` facets."""
    v = [(0, 0, 0), (0.01, 0, 0), (0, 0.01, 0), (0, 0, 0.01)]
    data = b"\0" * 80 + struct.pack("<I", declared)
    for f in ((0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)):
        data += struct.pack("<3f", 0, 0, 0) + b"".join(struct.pack("<3f", *v[i]) for i in f) + b"\0\0"
    path.write_bytes(data)
    return path


def _gltf(folder: Path, buffer: str) -> Path:
    """A one-triangle glTF whose vertex buffer is the external file ``buffer``."""
    g = {
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"uri": buffer, "byteLength": 44}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 6},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"},
        ],
    }
    (folder / "m.gltf").write_text(json.dumps(g))
    return folder / "m.gltf"


def _case(name: str, t: Path) -> tuple[list[str], str]:
    """``(argv, a substring of the one error: line)`` of hostile case ``name`` built under ``t``."""
    from test_robots_urdf import diff_drive

    out = str(t / "out")
    scen = t / "s.toml"
    scen.write_text(IDEAL)
    if name == "gltf-buffer-fifo":
        pytest.importorskip("trimesh")
        os.mkfifo(t / "buf.bin")
        _gltf(t, "buf.bin")
        (t / "dd.urdf").write_text(diff_drive(chassis_collision='<mesh filename="m.gltf"/>'))
        return ["robot", "check", str(t / "dd.urdf")], f"'{t / 'buf.bin'}' is a FIFO (named pipe)"
    if name == "urdf-1e5-links":
        up = ["base_link", *(f"l{i}" for i in range(1, 100000))]
        tail = "".join(
            f'<link name="l{i}"/><joint name="j{i}" type="fixed"><parent link="{up[i - 1]}"/>'
            f'<child link="l{i}"/></joint>'
            for i in range(1, 100000)
        )
        (t / "r.urdf").write_text(diff_drive(tail=tail))
        return ["robot", "check", str(t / "r.urdf")], "200009 <link> and <joint> elements, above the 10000"
    if name == "mjcf-1e5-bodies":
        bodies = "".join(f'<body name="b{i}" pos="{i} 0 -5"><geom size=".01"/></body>' for i in range(100000))
        xml = _robot(t, head=f"<worldbody>{bodies}</worldbody>")
        return ["identify", str(xml)], "100003 <body> elements, above the 5000 a robot may have"
    if name == "robot-name-too-long":
        return ["robot", "check", str(t / ("x" * 256 + ".xml"))], "cannot be looked up (File name too long)"
    if name == "robot-path-over-PATH_MAX":
        return ["identify", str(t / "/".join(["d" * 200] * 25) / "r.xml")], "cannot be looked up (File name too long)"
    if name == "scenario-name-too-long":
        return ["run", str(t / ("s" * 300 + ".toml")), "--out", out], "cannot be looked up (File name too long)"
    if name == "toml-nested-1e5":
        scen.write_text(IDEAL + "x = " + "[" * 100000 + "]" * 100000 + "\n")
        return ["run", str(scen), "--out", out], "nested too deeply to read"
    if name == "set-nested-1e5":
        return ["run", str(scen), "--set", "sim.seed=" + "[" * 100000, "--out", out], "nested too deeply"
    if name == "json-nested-1e5":
        (t / "summary.json").write_text("[" * 100000 + "]" * 100000)
        return ["run", str(t / "summary.json"), "--out", out], "nested too deeply to read"
    if name == "symlink-loop":
        os.symlink(t / "b.xml", t / "a.xml")
        os.symlink(t / "a.xml", t / "b.xml")
        return ["robot", "check", str(t / "a.xml")], "a.xml"
    if name == "directory-as-robot":
        (t / "d.xml").mkdir()
        return ["robot", "check", str(t / "d.xml")], "d.xml"
    if name == "robot-dev-zero":
        return ["robot", "check", "/dev/zero"], "is a device"
    if name == "urdf-symlink-to-dev-zero":
        os.symlink("/dev/zero", t / "r.urdf")
        return ["identify", str(t / "r.urdf")], "is a device"
    if name == "include-cycle":
        (t / "a.xml").write_text('<mujoco><include file="b.xml"/><worldbody/></mujoco>')
        (t / "b.xml").write_text('<mujoco><include file="a.xml"/></mujoco>')
        return ["robot", "check", str(t / "a.xml")], "includes itself"
    if name == "size-memory-1000G":
        return ["robot", "check", str(_robot(t, head='<size memory="1000G"/>'))], "r.xml"
    if name == "nconmax-1e9":
        return ["robot", "check", str(_robot(t, head='<size nconmax="1000000000" njmax="1000000000"/>'))], "r.xml"
    if name == "stl-declares-1e7-faces":
        _stl(t / "m.stl", 10**7)
        return ["robot", "check", str(_robot(t, assets='<asset><mesh name="x" file="m.stl"/></asset>'))], "m.stl"
    if name == "duration-1e308":
        return ["run", str(scen), "--duration", "1e308", "--out", out], "duration"
    if name == "control-dt-denormal":
        return ["run", str(scen), "--set", "sim.control_dt=5e-324", "--out", out], "control_dt"
    if name == "seed-negative":
        return ["run", str(scen), "--seed", "-1", "--out", out], "seed"
    if name == "seed-2**70":
        return ["run", str(scen), "--seed", str(2**70), "--out", out], "seed"
    if name == "out-is-a-file":
        (t / "out").write_text("x")
        return ["run", str(scen), "--out", out], "not a directory"
    if name == "out-under-a-file":
        (t / "f").write_text("x")
        return ["run", str(scen), "--out", str(t / "f" / "sub")], "f"
    if name == "sweep-seeds-1e12":
        return ["sweep", str(scen), "--seeds", str(10**12), "--out", out], "estimated"
    if name == "out-newline":  # "outputs in o\nerror: forged/" forged a line on stdout (a second pass, issue 28)
        return ["run", str(scen), "--out", str(t / "o\nerror: forged")], "holds a control character"
    if name == "sweep-out-newline":
        return ["sweep", str(scen), "--seeds", "2", "--out", str(t / "s\rerror: x")], "'" + str(t / "s\\rerror: x")
    if name == "scenario-fifo":
        os.mkfifo(t / "f.toml")
        return ["run", str(t / "f.toml"), "--out", out], "is a FIFO"
    raise AssertionError(name)


CASES = [
    "gltf-buffer-fifo",
    "urdf-1e5-links",
    "mjcf-1e5-bodies",
    "robot-name-too-long",
    "robot-path-over-PATH_MAX",
    "scenario-name-too-long",
    "toml-nested-1e5",
    "set-nested-1e5",
    "json-nested-1e5",
    "symlink-loop",
    "directory-as-robot",
    "robot-dev-zero",
    "urdf-symlink-to-dev-zero",
    "include-cycle",
    "size-memory-1000G",
    "nconmax-1e9",
    "stl-declares-1e7-faces",
    "duration-1e308",
    "control-dt-denormal",
    "seed-negative",
    "seed-2**70",
    "out-is-a-file",
    "out-under-a-file",
    "sweep-seeds-1e12",
    "scenario-fifo",
    "out-newline",
    "sweep-out-newline",
]


@pytest.mark.parametrize("name", CASES)
def test_hostile_input_is_one_error_line_and_exit_2(name, tmp_path, capsys):
    argv, want = _case(name, tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    code = cli.main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    errors = [e for e in err if e.startswith("error:")]
    assert code == 2 and len(errors) == 1, (code, err)
    assert want in errors[0], errors[0]
    assert not any("Traceback" in e or "internal error" in e for e in err), err
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written, not even an empty out/


def _compiles_within(xml: Path, seconds: float = 60.0) -> subprocess.CompletedProcess:
    """MuJoCo compiles ``xml`` in a child process; a read of a FIFO would block it past ``seconds``."""
    code = f"import mujoco; m = mujoco.MjModel.from_xml_path({str(xml)!r}); print(m.nmesh, m.nmat)"
    return subprocess.run([PY, "-c", code], capture_output=True, text=True, timeout=seconds)


def test_mujoco_reads_no_obj_mtllib(tmp_path):
    """An OBJ mesh's ``mtllib`` lines, a FIFO beside it, one outside and ``/dev/zero``, are never read by
    MuJoCo 4's OBJ loader (each read would block or never end): the mesh compiles, no material taken in."""
    os.mkfifo(tmp_path / "trap.mtl")
    os.mkfifo(tmp_path / "out.mtl")
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "a.obj").write_text(
        "mtllib trap.mtl\nmtllib ../out.mtl\nmtllib /dev/zero\nv 0 0 0\nv .01 0 0\nv 0 .01 0\nv 0 0 .01\n"
        "usemtl m\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
    )
    os.replace(tmp_path / "trap.mtl", tmp_path / "r" / "trap.mtl")
    xml = _robot(tmp_path / "r", assets='<asset><mesh name="x" file="a.obj"/></asset>')
    p = _compiles_within(xml)
    assert p.returncode == 0, p.stderr
    assert p.stdout.split() == ["1", "0"]  # the mesh, and no material from any .mtl


def test_mujoco_plugin_config_names_no_file(tmp_path):
    """A shipped plugin's ``<config>`` value naming a FIFO is parsed as a number, never opened: MuJoCo 4
    refuses it as an invalid value without blocking. The plugins it registers (``mujoco.pid``,
    ``mujoco.sensor.touch_grid``, ``mujoco.sdf.{bolt,bowl,gear,nut,torus}``; no ``mujoco.plugins`` entry
    point is installed) take numbers only, and an MJCF file cannot load a plugin library."""
    os.mkfifo(tmp_path / "f")
    xml = tmp_path / "p.xml"
    xml.write_text(
        '<mujoco><extension><plugin plugin="mujoco.sdf.torus"><instance name="t">'
        f'<config key="radius1" value="{tmp_path / "f"}"/><config key="radius2" value="{tmp_path / "f"}"/>'
        '</instance></plugin></extension><asset><mesh name="m"><plugin instance="t"/></mesh></asset>'
        "<worldbody/></mujoco>"
    )
    p = _compiles_within(xml)
    assert p.returncode == 1 and "invalid attribute value for 'radius1'" in p.stderr, p.stderr


def test_mesh_resolver_reads_a_sibling_buffer_and_refuses_the_rest(tmp_path):
    """:func:`~bioform_mj.robots.sanity.mesh_resolver`: a glTF's regular sibling ``.bin`` is read (its
    triangle's vertices come back exactly), a FIFO beside it and a file outside its folder are refused
    before any read."""
    trimesh = pytest.importorskip("trimesh")
    import numpy as np

    from bioform_mj.robots.sanity import mesh_resolver

    v = [0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 0.25, 0.0]
    (tmp_path / "ok.bin").write_bytes(struct.pack("<9f", *v) + struct.pack("<3H", 0, 1, 2) + b"\0\0")
    gltf = _gltf(tmp_path, "ok.bin")
    mesh = trimesh.load(gltf, force="mesh", resolver=mesh_resolver(gltf))
    assert np.array_equal(np.asarray(mesh.vertices), np.reshape(v, (3, 3)))
    os.mkfifo(tmp_path / "fifo.bin")
    (tmp_path.parent / "outside.bin").write_bytes(b"\0" * 44)
    res = mesh_resolver(gltf)
    with pytest.raises(ValueError, match="is a FIFO"):
        res.get("fifo.bin")
    with pytest.raises(ValueError, match="escapes resolver root"):
        res.get("../outside.bin")
    assert res.get("ok.bin")[:36] == struct.pack("<9f", *v)

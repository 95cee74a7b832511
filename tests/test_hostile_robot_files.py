"""Red team, round three, second pass (issue 28): hostile MJCF robot files the other tests do not cover.

Each case runs ``bioform robot check`` in a process of its own with a time limit (a regression hangs or
allocates for minutes: the test fails by its timeout, it never passes) and must end in exactly one ``error:``
line naming the element, exit 2, nothing written. Measured before the fixes (``robot check`` under a 45 s
limit and an 8 GB address-space limit): one geom in ``<replicate count="1000000">``, two nested replicates of
1000, 10^6 ``<site>`` elements, ``<size nkey="100000000">``, ``<size nuser_body="100000000">``,
``<option iterations="1000000000" tolerance="0">`` and ``noslip_iterations`` ran past the limit; a FIFO inside
the robot's folder as a ``<flexcomp file>`` hung MuJoCo's parser; ``<hfield nrow="100000" ncol="100000">`` took
38 s to fail; ``<option timestep>`` 0, negative or NaN was an ``internal error`` (exit 1); NaN or infinite
gravity or density ended in exit 1 after the check had run; a NaN wind ran (exit 0); a ``<model file>`` that
attaches itself (or a model that attaches it) crashed the process (SIGSEGV); 20 files each attaching or including
the next twice ran past 60 s. URDF: 3·10^5 ``<material>`` elements ran past 60 s, and a ``.xml`` URDF with a
50 MB root attribute took longer than 60 s just to be recognised as a URDF; a 1.1 MB PNG texture of 20000 ×
20000 pixels grew ``robot check`` to 3.7 GB and ran past 120 s."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bioform_mj.robots.refs import models_dir

SRC = str(Path(__file__).resolve().parents[1] / "src")
PAPER = (models_dir() / "paper_robot.xml").read_text()


def _robot(d: Path, assets: str = "", head: str = "", option: str = "") -> str:
    """The shipped paper robot with ``assets`` and ``option`` before its worldbody, ``head`` before ``</mujoco>``."""
    text = PAPER.replace("<worldbody>", f"{assets}{option}<worldbody>", 1).replace("</mujoco>", f"{head}</mujoco>")
    (d / "r.xml").write_text(text)
    return str(d / "r.xml")


def _png(path: Path, w: int, h: int) -> Path:
    """A valid all-black RGB PNG of ``w`` × ``h`` pixels (its zlib stream about 1/1000 of the decoded size)."""
    import struct
    import zlib

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    z = zlib.compressobj(9)
    row = b"\0" * (3 * w + 1)
    data = b"".join(z.compress(row) for _ in range(h)) + z.flush()
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", data) + chunk(b"IEND", b""))
    return path


def _case(name: str, d: Path) -> tuple[str, str]:
    """``(robot file, a substring of the one error: line)`` of case ``name`` built in ``d``."""
    geom = '<geom size=".001" pos="5 5 -1"/>'
    if name == "replicate-1e6":
        body = f'<worldbody><replicate count="1000000" offset="0 0 .01">{geom}</replicate></worldbody>'
        return _robot(d, head=body), "1000019 <geom> elements, above the 20000"
    if name == "replicate-nested":
        inner = f'<replicate count="1000" offset=".01 0 0"><body pos="5 5 -1">{geom}</body></replicate>'
        body = f'<worldbody><replicate count="1000" offset="0 0 .01">{inner}</replicate></worldbody>'
        return _robot(d, head=body), "1000003 <body> elements, above the 5000"
    if name == "sensors-2e5":
        return _robot(d, head="<sensor>" + '<jointpos joint="left_wheel"/>' * 200000 + "</sensor>"), (
            "200063 elements (<replicate> repeats counted), above the 100000"
        )
    if name == "flexcomp-fifo-inside":
        os.mkfifo(d / "f.obj")
        return _robot(d, head='<worldbody><flexcomp name="f" type="mesh" file="f.obj"/></worldbody>'), (
            f"<flexcomp file=\"f.obj\"/> ('{d / 'f.obj'}'): '{d / 'f.obj'}' is a FIFO"
        )
    if name == "flexcomp-count":
        flex = '<worldbody><flexcomp name="f" type="grid" count="200 200 200" spacing=".01 .01 .01"/></worldbody>'
        return _robot(d, head=flex), "<flexcomp count='200 200 200'>: above the 100000 points"
    if name == "hfield-1e10":
        return _robot(d, assets='<asset><hfield name="h" nrow="100000" ncol="100000" size="1 1 1 1"/></asset>'), (
            "<hfield nrow='100000' ncol='100000'>: above the 1e+07 samples"
        )
    if name == "texture-4e10":
        tex = '<asset><texture name="t" type="2d" builtin="checker" width="200000" height="200000"/></asset>'
        return _robot(d, assets=tex), "<texture width='200000' height='200000'>: above the 67108864 pixels"
    if name == "cube-texture-6x":  # 3500² × 6 = 7.4e7 pixels: the six faces count
        tex = '<asset><texture name="t" type="cube" builtin="gradient" width="3500" height="3500"/></asset>'
        return _robot(d, assets=tex), "<texture width='3500' height='3500'>: above the 67108864 pixels"
    if name in ("png-bomb-texture", "png-bomb-hfield"):  # 1.1 MB of 20000² pixels: 3.7 GB, past 120 s before
        _png(d / "t.png", 9000, 9000)
        el = '<texture name="t" type="2d" file="t.png"/>' if "texture" in name else '<hfield name="h" file="t.png" '
        el += "" if "texture" in name else 'size="1 1 1 1"/>'
        return _robot(d, assets=f"<asset>{el}</asset>"), "a PNG image of 9000 × 9000 pixels, above the 67108864"
    if name == "include-big-twice":  # a 40 MB file included twice: 80 MB of XML parsed
        (d / "big.xml").write_text('<mujoco><custom><text name="x" data="' + "a" * 40_000_000 + '"/></custom></mujoco>')
        return _robot(d, head='<include file="big.xml"/><include file="big.xml"/>'), (
            "the XML read comes to more than 64 MB (each include counted each time)"
        )
    if name == "one-mesh-600x":  # 300 meshes of one 7.5 MB STL: 75 s and gigabytes before failing
        (d / "m.stl").write_bytes(b"\0" * 1_000_000)
        meshes = "".join(f'<mesh name="m{i}" file="m.stl"/>' for i in range(600))
        return _robot(d, assets=f"<asset>{meshes}</asset>"), "the files the robot loads come to more than 512 MB"
    if name == "size-nkey":
        return _robot(d, head='<size nkey="100000000"/>'), "<size nkey='100000000'>: at most 10000"
    if name == "size-nuser":
        return _robot(d, head='<size nuser_geom="100000000"/>'), "<size nuser_geom='100000000'>: at most 1000"
    if name == "attach-self":  # MuJoCo attached it again and again until it crashed (SIGSEGV)
        attach = '<worldbody><body name="x" pos="5 5 5"><attach model="c" prefix="c_"/></body></worldbody>'
        return _robot(d, assets='<asset><model name="c" file="r.xml"/></asset>', head=attach), (
            '<model file="r.xml"/> attaches a model that attaches it'
        )
    if name == "attach-mutual":
        (d / "b.xml").write_text(
            '<mujoco><asset><model name="a" file="r.xml"/></asset>'
            '<worldbody><body name="y"><attach model="a" prefix="a_"/></body></worldbody></mujoco>'
        )
        attach = '<worldbody><body name="x" pos="5 5 5"><attach model="b" prefix="b_"/></body></worldbody>'
        return _robot(d, assets='<asset><model name="b" file="b.xml"/></asset>', head=attach), (
            "attaches a model that attaches it"
        )
    if name == "attach-fanout":  # each file attaches the next twice: 2^20 copies of one body from 20 small files
        for i in range(20):
            inner = (
                '<geom size=".001"/>'
                if i == 19
                else '<body name="p"><attach model="m" prefix="a_"/></body><body name="q"><attach model="m" '
                'prefix="b_"/></body>'
            )
            asset = "" if i == 19 else f'<asset><model name="m" file="l{i + 1}.xml"/></asset>'
            body = f'<worldbody><body name="r{i}">{inner}</body></worldbody>'
            (d / f"l{i}.xml").write_text(f"<mujoco>{asset}{body}</mujoco>")
        attach = '<worldbody><body name="x" pos="5 5 5"><attach model="top" prefix="t_"/></body></worldbody>'
        return _robot(d, assets='<asset><model name="top" file="l1.xml"/></asset>', head=attach), (
            "<body> elements with the attached models' copies, above the 5000"
        )
    if name == "include-fanout":  # each file includes the next twice: 2^20 reads
        for i in range(20):
            inner = '<body pos="5 5 5"><geom size=".001"/></body>' if i == 19 else f'<include file="i{i + 1}.xml"/>' * 2
            (d / f"i{i}.xml").write_text(f"<mujoco>{inner}</mujoco>")
        return _robot(d, head='<worldbody><include file="i1.xml"/></worldbody>'), "more than 1000 <include> reads"
    options = {
        "timestep-0": ('timestep="0"', "<option timestep='0'>: a timestep must be a finite number > 0 s"),
        "timestep-negative": ('timestep="-0.001"', "<option timestep='-0.001'>: a timestep must be"),
        "timestep-nan": ('timestep="nan"', "<option timestep='nan'>: a timestep must be"),
        "gravity-nan": ('gravity="0 0 nan"', "<option gravity='0 0 nan'>: must be finite numbers"),
        "gravity-inf": ('gravity="0 0 -inf"', "<option gravity='0 0 -inf'>: must be finite numbers"),
        "wind-nan": ('wind="nan 0 0"', "<option wind='nan 0 0'>: must be finite numbers"),
        "density-inf": ('density="inf"', "<option density='inf'>: must be a finite number >= 0"),
        "viscosity-negative": ('viscosity="-1"', "<option viscosity='-1'>: must be a finite number >= 0"),
        "iterations-1e9": ('iterations="1000000000" tolerance="0"', "<option iterations='1000000000'>: at most 1000"),
        "noslip-1e9": ('noslip_iterations="1000000000" noslip_tolerance="0"', "<option noslip_iterations="),
        "ls-iterations-1e9": ('ls_iterations="1000000000" ls_tolerance="0"', "<option ls_iterations="),
        "ccd-iterations-1e9": ('ccd_iterations="1000000000" ccd_tolerance="0"', "<option ccd_iterations="),
    }
    if name in options:
        attrs, want = options[name]
        return _robot(d, option=f"<option {attrs}/>"), want
    raise AssertionError(name)


CASES = [
    "replicate-1e6",
    "replicate-nested",
    "sensors-2e5",
    "flexcomp-fifo-inside",
    "flexcomp-count",
    "hfield-1e10",
    "texture-4e10",
    "cube-texture-6x",
    "attach-self",
    "attach-mutual",
    "attach-fanout",
    "include-fanout",
    "png-bomb-texture",
    "one-mesh-600x",
    "include-big-twice",
    "png-bomb-hfield",
    "size-nkey",
    "size-nuser",
    "timestep-0",
    "timestep-negative",
    "timestep-nan",
    "gravity-nan",
    "gravity-inf",
    "wind-nan",
    "density-inf",
    "viscosity-negative",
    "iterations-1e9",
    "noslip-1e9",
    "ls-iterations-1e9",
    "ccd-iterations-1e9",
]


def _check(path: str, timeout: float = 120) -> subprocess.CompletedProcess:
    """``bioform robot check PATH`` in a process of its own, under a time limit."""
    return subprocess.run(
        [sys.executable, "-m", "bioform_mj.cli", "robot", "check", path],
        env={**os.environ, "PYTHONPATH": SRC},
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=os.path.dirname(path),
    )


@pytest.mark.parametrize("name", CASES)
def test_hostile_mjcf_is_one_error_line_and_exit_2(name, tmp_path):
    path, want = _case(name, tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    res = _check(path)
    err = res.stderr.strip().splitlines()
    errors = [e for e in err if e.startswith("error:")]
    assert res.returncode == 2 and len(errors) == 1, (res.returncode, err)
    assert want in errors[0], errors[0]
    assert not any("Traceback" in e or "internal error" in e for e in err), err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_the_bounds_refuse_no_published_robot():
    """No false refusal: every shipped robot and every zoo MJCF passes the element, size and option bounds."""
    import mujoco

    from bioform_mj.robots.mjcf_assets import confine_mjcf
    from bioform_mj.robots.sanity import option_problem

    files = sorted(models_dir().glob("*.xml")) + sorted((Path(__file__).parent / "zoo").rglob("*.xml"))
    checked = 0
    for f in files:
        try:
            model = mujoco.MjModel.from_xml_path(str(f))
        except ValueError:
            continue  # an include fragment or a URDF, not a robot of its own
        confine_mjcf(f)
        assert option_problem(model.opt) == "", f
        checked += 1
    assert checked >= 6


def test_a_huge_attribute_is_parsed_in_linear_time(tmp_path):
    """``ET.parse`` feeds expat 64 kB chunks, and expat 2.5 re-parses a token spanning them for each chunk: a
    60 MB attribute took 114 s to walk (6 MB: 1.8 s). :func:`~bioform_mj.robots.sanity.parse_xml` feeds the file
    whole: a 40 MB attribute (about 80 s the old way) is walked in a few seconds, its value intact."""
    from bioform_mj.robots.mjcf_assets import confine_mjcf
    from bioform_mj.robots.sanity import parse_xml

    path = _robot(tmp_path, head='<custom><text name="x" data="' + "a" * 40_000_000 + '"/></custom>')
    t0 = time.perf_counter()
    confine_mjcf(path)
    assert time.perf_counter() - t0 < 20
    assert len(parse_xml(path).find("custom/text").get("data")) == 40_000_000


def test_urdf_with_too_many_elements_refused(tmp_path):
    """3·10^5 ``<material>`` elements (under the link bound) ran ``robot check`` past 60 s: now one line."""
    from test_robots_urdf import diff_drive

    (tmp_path / "r.urdf").write_text(diff_drive(tail='<material name="m"><color rgba="1 1 1 1"/></material>' * 60000))
    res = _check(str(tmp_path / "r.urdf"))
    err = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(err) == 1, err
    assert "120067 elements, above the 100000 a robot may have" in err[0], err


def test_is_urdf_reads_a_huge_root_tag_in_linear_time(tmp_path):
    """An ``.xml`` whose ``<robot>`` tag holds a 40 MB attribute is recognised as a URDF in seconds (``iterparse``
    fed expat 64 kB chunks and took minutes), and an MJCF is still no URDF."""
    from bioform_mj.robots.urdf import is_urdf
    from test_robots_urdf import diff_drive

    (tmp_path / "r.xml").write_text(diff_drive().replace("<robot ", '<robot x="' + "a" * 40_000_000 + '" ', 1))
    t0 = time.perf_counter()
    assert is_urdf(tmp_path / "r.xml")
    assert time.perf_counter() - t0 < 20
    assert not is_urdf(_robot(tmp_path))


def test_urdf_meshes_named_many_times_are_bounded(tmp_path):
    """A URDF naming one 1 MB mesh 600 times (MuJoCo loads it for each) is refused at 512 MB, naming the mesh."""
    from test_robots_urdf import diff_drive

    (tmp_path / "m.stl").write_bytes(b"\0" * 1_000_000)
    visuals = '<visual><geometry><mesh filename="m.stl"/></geometry></visual>' * 600
    joint = '<joint name="deco_joint" type="fixed"><parent link="base_link"/><child link="deco"/></joint>'
    (tmp_path / "r.urdf").write_text(diff_drive(tail=f'<link name="deco">{visuals}</link>{joint}'))
    res = _check(str(tmp_path / "r.urdf"))
    err = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(err) == 1, err
    assert "<visual> mesh 'm.stl' of link 'deco': the meshes the robot loads come to more than 512 MB" in err[0], err


def test_a_huge_urdf_file_is_refused_unread(tmp_path):
    """A 10 GB (sparse) ``.urdf`` was read whole (a MemoryError under an 8 GB limit, an internal error): now its
    size is refused before any read."""
    with open(tmp_path / "r.urdf", "wb") as fh:
        fh.write(b"<robot name='x'>")
        fh.truncate(10 * 10**9)
    res = _check(str(tmp_path / "r.urdf"))
    err = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(err) == 1, err
    assert f"model file '{tmp_path / 'r.urdf'}' is 10000 MB, above the 64 MB a robot file may be" in err[0], err

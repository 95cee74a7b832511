"""A robot file is data (design §12, issue 28 item 1): xacro runs only when asked, in a sandboxed process.

Every hostile file here tries to run a command (creating a marker file), read the machine
(``/etc/passwd``, the environment) or exhaust it; each must end in one refusal, the marker absent and
nothing of the machine in the answer.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bioform_mj.cli import main as cli
from bioform_mj.core.errors import InputError
from bioform_mj.robots import xacro_sandbox
from bioform_mj.robots.params import robot_parameters
from bioform_mj.robots.refs import PackagePath, RobotRef, as_ref
from bioform_mj.robots.urdf import check_file
from bioform_mj.robots.xacro_sandbox import XacroRefused, expand
from test_robots_urdf import (
    I_CASTER,
    I_CHASSIS,
    I_WHEEL_AXIS,
    I_WHEEL_DIAM,
    L_HALF,
    M_CASTER,
    M_CHASSIS,
    M_WHEEL,
    R_WHEEL,
    X_CASTER,
    Z_AXLE,
    compiled,
    diff_drive,
    write,
)

pytest.importorskip("xacro")

NS = 'xmlns:xacro="http://ros.org/wiki/xacro"'
SECRET = "bioform-secret-3141592653"
#: ')' and '(' as properties: xacro's lexer ends $( … ) at the first ')', so the escapes build them so
PARENS = '<xacro:property name="r" value=")"/><xacro:property name="l" value="("/>'


def robot(body: str, props: str = "") -> str:
    """A xacro robot file with ``body`` after one link (what follows the expansion does not matter)."""
    return f'<robot name="h" {NS}>{PARENS}{props}<link name="a"/>{body}</robot>'


def _escapes(marker: Path) -> list[tuple[str, str]]:
    """``(id, xacro body)``: the ways out of xacro's own sandbox, each trying to create ``marker``."""
    touch = f"import os; os.system('touch {marker}'${{r}}"
    return [
        ("subclasses", "<x v=\"${''.__class__.__mro__[1].__subclasses__()}\"/>"),
        ("subclasses-comprehension", '<x v="${[c for c in (1).__class__.__base__.__subclasses__()]}"/>'),
        ("dunder-import", f"<x v=\"${{__import__('os').system('touch {marker}')}}\"/>"),
        ("eval-exec", f'<x v="$(eval exec(&quot;{touch}&quot;, dict(${{r}}${{r}})"/>'),
        ("eval-open", "<x v=\"$(eval open('/etc/passwd'${r}.read(${r})\"/>"),
        ("eval-import-by-chr", "<x v=\"$(eval __import__('os'${r}.system('id'${r})\"/>"),
        ("eval-env", "<x v=\"$(eval env('HOME'${r})\"/>"),
        ("python-vars", "<x v=\"${python['vars'](python['str'])}\"/>"),
        ("python-type", "<x v=\"${python.type('x', (), dict())}\"/>"),
        ("str-format", '<x v="${str.format(t, xacro.load_yaml)}"/>'),
        ("dunder-in-string", "<x v=\"${xacro.dotify(dict(a='{0.__globals__'))}\"/>"),
        ("env", '<x v="$(env HOME)"/>'),
        ("load_yaml-etc", "<x v=\"${xacro.load_yaml('/etc/passwd')}\"/>"),
        ("include-etc", '<xacro:include filename="/etc/hostname"/>'),
        ("include-up", '<xacro:include filename="../../../../../../../../etc/hostname"/>'),
    ]


@pytest.fixture
def hostile(tmp_path, monkeypatch):
    """A robot folder, a marker file path that must stay absent, and the secret in the environment."""
    monkeypatch.setenv("BIOFORM_TEST_SECRET", SECRET)
    monkeypatch.setattr(xacro_sandbox, "XACRO_TIME_S", 15)
    xacro_sandbox._EXPANDED.clear()
    folder = tmp_path / "robot"
    folder.mkdir()
    return folder, tmp_path / "MARKER"


@pytest.mark.parametrize("case", range(15), ids=[c[0] for c in _escapes(Path("m"))])
def test_escape_refused_nothing_runs_nothing_leaks(case, hostile):
    folder, marker = hostile
    name, body = _escapes(marker)[case]
    path = write(folder / f"{name}.urdf.xacro", robot(body, '<xacro:property name="t" value="{0.__globals__}"/>'))
    with pytest.raises(XacroRefused) as err:
        expand(path, PackagePath())
    msg = str(err.value)
    assert "\n" not in msg and str(path) in msg, msg
    assert "root:" not in msg and SECRET not in msg and "uid=" not in msg, msg
    assert not marker.exists()


# ------------------------------------------------------------------ $(optenv)/$(env): never the environment
ENV_R = "BIOFORM_TEST_WHEEL_R"


def _optenv_robot(folder: Path, default: str = "0.05") -> Path:
    """:func:`diff_drive` whose wheel radius (and axle height) is ``$(optenv BIOFORM_TEST_WHEEL_R default)``."""
    text = diff_drive().replace(
        '<robot name="dd">', f'<robot name="dd" {NS}><xacro:property name="r" value="$(optenv {ENV_R} {default})"/>'
    )
    text = text.replace(f'radius="{R_WHEEL!r}" length', 'radius="${r}" length')
    return write(folder / "dd.urdf.xacro", text.replace(f'xyz="0 0 {Z_AXLE!r}"', 'xyz="0 0 ${r}"'))


def _ab_by_hand(r: float) -> tuple[float, float]:
    """``(a_eff, b_eff)`` of :func:`diff_drive` with wheel radius ``r`` (m), from its inertials (design §8)."""
    m = M_CHASSIS + 2 * M_WHEEL + 2 * M_CASTER
    yaw = I_CHASSIS[2] + 2 * (I_WHEEL_DIAM + M_WHEEL * L_HALF**2) + 2 * (I_CASTER + M_CASTER * X_CASTER**2)
    return 1 / (m * r + 2 * I_WHEEL_AXIS / r), L_HALF / (yaw * r + 2 * I_WHEEL_AXIS * L_HALF**2 / r)


@pytest.mark.parametrize(
    "env,args,r",
    [(None, (), 0.05), ("0.09", (), 0.05), ("0.09", ((ENV_R, "0.07"),), 0.07)],
    ids=["default", "environment-ignored", "xacro-arg"],
)
def test_optenv_is_its_default_or_the_xacro_arg_never_the_environment(env, args, r, hostile, monkeypatch):
    """A Clearpath-style ``$(optenv NAME default)`` sizing the wheels: the robot's a, b are those of the default
    radius (0.05 m) by hand, with NAME set in this process's environment too; ``--xacro-arg NAME=0.07`` gives the
    other radius. The import notes say once which value was taken and why."""
    folder, _ = hostile
    if env is None:
        monkeypatch.delenv(ENV_R, raising=False)
    else:
        monkeypatch.setenv(ENV_R, env)
    model, layout = compiled(RobotRef(str(_optenv_robot(folder)), xacro=True, xacro_args=args))
    p = robot_parameters(model)
    a, b = _ab_by_hand(r)
    assert p.wheel_radius == pytest.approx(r, abs=1e-12)
    assert p.a_eff == pytest.approx(a, rel=1e-9) and p.b_eff == pytest.approx(b, rel=1e-9), (p.a_eff, p.b_eff, a, b)
    assert abs(a / _ab_by_hand(0.09)[0] - 1) > 0.2  # the environment's radius would be visibly different
    said = [n for n in layout.import_notes if n.startswith("$(optenv")]
    if args:
        assert said == [f"$(optenv)/$(env) set by --xacro-arg: {ENV_R}='0.07'"], layout.import_notes
    else:
        assert len(said) == 1 and said[0].startswith(
            f"$(optenv) resolved to the file's default, never the environment's value: {ENV_R}='0.05'"
        ), said
        assert "--xacro-arg NAME=VALUE" in said[0]


def test_optenv_and_env_read_nothing_of_the_environment(hostile):
    """``$(optenv)`` without a default is empty, in ``$(eval …)`` too; ``$(env NAME)`` is refused naming the flag
    that sets it, and set by it (the secret is in this process's environment throughout)."""
    folder, _ = hostile
    body = (
        f'<x a="[$(optenv BIOFORM_TEST_SECRET)]" b="$(optenv BIOFORM_TEST_SECRET {SECRET[:3]})" '
        f"c=\"$(eval optenv('BIOFORM_TEST_SECRET', 'dflt'${{r}} + 'X')\" d=\"$(optenv BIOFORM_TEST_SECRET)\"/>"
    )
    out = expand(write(folder / "o.urdf.xacro", robot(body)), PackagePath())
    assert 'a="[]"' in out and f'b="{SECRET[:3]}"' in out and 'c="dfltX"' in out and SECRET not in out, out
    # each default once, in the order read (the empty one twice in the file)
    assert out.env == (
        ("BIOFORM_TEST_SECRET", "", "default"),
        ("BIOFORM_TEST_SECRET", "bio", "default"),
        ("BIOFORM_TEST_SECRET", "dflt", "default"),
    ), out.env
    path = write(folder / "e.urdf.xacro", robot('<x v="$(env BIOFORM_TEST_SECRET)"/>'))
    with pytest.raises(XacroRefused, match=r"reads no environment variable.*--xacro-arg BIOFORM_TEST_SECRET=VALUE"):
        expand(path, PackagePath())
    out = expand(path, PackagePath(), (("BIOFORM_TEST_SECRET", "given"),))
    assert 'v="given"' in out and out.env == (("BIOFORM_TEST_SECRET", "given", "arg"),)
    assert out.unused_args == ()


def test_a_xacro_arg_the_file_never_reads_is_said(hostile):
    """A misspelt ``--xacro-arg`` changes nothing and is named; a declared ``<xacro:arg>`` (even unread), a read
    ``$(arg)`` and a read ``$(optenv)`` count as used. Forty defaults: the note names twelve and counts the rest."""
    folder, _ = hostile
    body = '<xacro:arg name="declared" default="d"/><x a="$(arg read)" b="$(optenv ENV_READ 1)"/>'
    given = (("declared", "1"), ("read", "2"), ("ENV_READ", "3"), ("TYPO_NAME", "4"))
    out = expand(write(folder / "u.urdf.xacro", robot(body)), PackagePath(), given)
    assert out.unused_args == ("TYPO_NAME",) and 'a="2"' in out and 'b="3"' in out, out
    note = xacro_sandbox.env_note(out.env, out.unused_args)
    assert note.endswith(
        "--xacro-arg TYPO_NAME: the file declares and reads no $(arg), $(optenv) or $(env) of that name (misspelt?)"
    ), note
    many = tuple((f"V{i}", "0", "default") for i in range(40))
    note = xacro_sandbox.env_note(many)
    assert note.count("='0'") == xacro_sandbox.ENV_NOTE_DEFAULTS == 12 and "V11='0' and 28 more" in note, note
    assert xacro_sandbox.env_note(()) is None


def test_symlink_out_of_the_package_is_not_read(hostile):
    folder, _ = hostile
    (folder / "params.yaml").symlink_to("/etc/passwd")
    path = write(folder / "s.urdf.xacro", robot("<x v=\"${xacro.load_yaml('params.yaml')}\"/>"))
    with pytest.raises(XacroRefused, match="outside the robot's packages"):
        expand(path, PackagePath())


def test_yaml_and_include_inside_the_package_work_and_args_arrive(hostile, tmp_path):
    folder, _ = hostile
    write(folder / "params.yaml", "mass: 2.5\n")
    write(folder / "part.xacro", f'<robot {NS}><link name="b"/></robot>')
    body = (
        '<xacro:include filename="part.xacro"/>'
        '<x m="${xacro.load_yaml(\'params.yaml\')[\'mass\']}" p="$(arg prefix)" c="$(cwd)"/>'
    )
    path = write(
        folder / "ok.urdf.xacro",
        f'<robot name="h" {NS}><xacro:arg name="prefix" default="d"/><link name="a"/>{body}</robot>',
    )
    out = expand(path, PackagePath(), (("prefix", "left_"),))
    assert 'm="2.5"' in out and 'p="left_"' in out and '<link name="b"/>' in out, out
    assert f'c="{folder.resolve()}"' in out  # $(cwd) is the robot's folder, not the caller's
    assert SECRET not in out


def test_exponential_macro_stopped_by_the_memory_or_time_limit(hostile, monkeypatch):
    folder, _ = hostile
    monkeypatch.setattr(xacro_sandbox, "XACRO_MEMORY_MB", 256)
    monkeypatch.setattr(xacro_sandbox, "XACRO_TIME_S", 10)
    macros = (
        '<xacro:macro name="m0"><x a="aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa"/></xacro:macro>'
    )
    for i in range(1, 9):
        macros += f'<xacro:macro name="m{i}">' + f"<xacro:m{i - 1}/>" * 10 + "</xacro:macro>"
    path = write(folder / "bomb.urdf.xacro", robot("<xacro:m8/>", macros))
    t0 = time.monotonic()
    with pytest.raises(XacroRefused, match="xacro stopped"):
        expand(path, PackagePath())
    assert time.monotonic() - t0 < 25


@pytest.mark.parametrize("expr,limit", [("'a'*10**10", "256 MiB"), ("9**9**9", "time limit")])
def test_huge_values_stopped(expr, limit, hostile, monkeypatch):
    folder, _ = hostile
    monkeypatch.setattr(xacro_sandbox, "XACRO_MEMORY_MB", 256)
    monkeypatch.setattr(xacro_sandbox, "XACRO_TIME_S", 3)
    path = write(folder / "big.urdf.xacro", robot(f'<x v="${{{expr}}}"/>'))
    with pytest.raises(XacroRefused, match=limit):
        expand(path, PackagePath())


def test_the_audit_hook_refuses_processes_files_and_introspection(tmp_path):
    """The layer under the expression checks: in the child, after the hook, nothing of this runs."""
    child = Path(xacro_sandbox.__file__).with_name("_xacro_child.py")
    marker = tmp_path / "MARKER"
    code = f"""
import json, os, runpy, sys
m = runpy.run_path({str(child)!r}, run_name="child")
m["_install_hook"]([{str(tmp_path)!r}], [], [])
tries = {{
    "system": lambda: os.system("touch {marker}"),
    "subprocess": lambda: __import__("subprocess"),
    "posix_spawn": lambda: os.posix_spawn("/bin/touch", ["touch", "{marker}"], {{}}),
    "fork": lambda: os.fork(),
    "read /etc/passwd": lambda: open("/etc/passwd").read(),
    "write": lambda: open({str(tmp_path / "w.txt")!r}, "w"),
    "ctypes": lambda: __import__("ctypes"),
    "frames": lambda: sys._getframe(),
    "gc": lambda: __import__("gc").get_objects(),
    "socket": lambda: __import__("socket"),
    "list /": lambda: os.listdir("/"),
}}
out = {{}}
for k, f in tries.items():
    try:
        f()
        out[k] = "ran"
    except PermissionError as e:
        out[k] = "refused"
    except Exception as e:
        out[k] = type(e).__name__
out["read inside"] = "ran" if open({str(tmp_path / "in.txt")!r}).read() == "ok" else "no"
print(json.dumps(out))
"""
    write(tmp_path / "in.txt", "ok")
    res = subprocess.run([sys.executable, "-I", "-c", code], capture_output=True, text=True, timeout=60)
    got = json.loads(res.stdout.strip().splitlines()[-1])
    assert got.pop("read inside") == "ran"  # the robot's own folder stays readable
    assert all(v == "refused" for v in got.values()), got
    assert not marker.exists() and not (tmp_path / "w.txt").exists()


# ------------------------------------------------------------------ not asked for: refused, one line
@pytest.mark.parametrize(
    "name,text",
    [
        ("r.urdf.xacro", robot("<x v=\"$(eval exec(&quot;import os; os.system('touch MARKER'${r}&quot;${r})\"/>")),
        ("r.urdf", diff_drive().replace('"0.2"', "\"${''.__class__}\"", 1)),
        ("r.xml", diff_drive(tail='<x v="$(env HOME)"/>')),
    ],
    ids=["xacro", "urdf-with-macros", "xml-robot-with-macros"],
)
@pytest.mark.parametrize("command", ["robot check", "identify"])
def test_not_asked_refused_before_anything_runs(name, text, command, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = write(tmp_path / name, text)
    assert cli.main([*command.split(), str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "pass --xacro" in err[0], err
    assert not (tmp_path / "MARKER").exists()


def test_asked_but_hostile_one_error_line(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = write(
        tmp_path / "r.urdf.xacro", robot(f"<x v=\"${{__import__('os').system('touch {tmp_path}/MARKER')}}\"/>")
    )
    assert cli.main(["robot", "check", str(path), "--xacro"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "xacro refused" in err[0], err
    assert not (tmp_path / "MARKER").exists()


def test_xacro_arg_without_xacro_is_refused(tmp_path, capsys):
    path = write(tmp_path / "dd.urdf", diff_drive())
    assert cli.main(["robot", "check", str(path), "--xacro-arg", "a=1"]) == 2
    assert "add --xacro" in capsys.readouterr().err


def test_scenario_robot_needs_the_mapping_key(tmp_path, capsys, monkeypatch):
    """``bioform run`` (even --no-robot-check) and ``bioform_mj.load`` refuse; ``xacro = true`` and
    ``--xacro`` allow, with ``xacro_args`` / ``--xacro-arg`` for $(arg)."""
    import bioform_mj

    monkeypatch.chdir(tmp_path)
    text = diff_drive().replace('<robot name="dd">', f'<robot name="dd" {NS}><xacro:arg name="m" default="x"/>')
    text = text.replace('"0.2"', '"$(arg m)"', 1)
    write(tmp_path / "dd.urdf.xacro", text)
    plain = write(tmp_path / "a.toml", '[plant]\nkind = "mujoco"\nrobots = ["dd.urdf.xacro"]\n')
    out = tmp_path / "out"
    assert cli.main(["run", str(plain), "--duration", "0.05", "--out", str(out), "--no-robot-check"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pass --xacro" in err[0] and not out.exists(), err
    with pytest.raises(InputError, match="pass --xacro"):
        bioform_mj.load(str(plain))
    asked = write(
        tmp_path / "b.toml",
        '[plant]\nkind = "mujoco"\nrobots = [{model = "dd.urdf.xacro", xacro = true, xacro_args = {m = 0.2}}]\n',
    )
    sc = bioform_mj.load(str(asked))
    assert sc.plant.robots[0].xacro and sc.plant.robots[0].xacro_args == (("m", "0.2"),)
    ref = RobotRef(str(tmp_path / "dd.urdf.xacro"), xacro=True, xacro_args=(("m", "0.2"),))
    check_file(ref)
    code = cli.main(["robot", "check", str(tmp_path / "dd.urdf.xacro"), "--xacro", "--xacro-arg", "m=0.2"])
    err = capsys.readouterr()
    assert code != 2 and "expanded by xacro, which runs the file as a program" in err.out + err.err, err


def test_mapping_key_types(tmp_path):
    assert as_ref({"model": "r.urdf", "xacro": True, "xacro_args": {"a": 1, "b": True}}).xacro_args == (
        ("a", "1"),
        ("b", "true"),
    )
    for bad in ({"model": "r.urdf", "xacro": "yes"}, {"model": "r.urdf", "xacro_args": ["a"]}):
        with pytest.raises(InputError):
            as_ref(bad)
    assert RobotRef("r.urdf", xacro=True, xacro_args=(("a", "1"),)).to_table() == {
        "model": "r.urdf",
        "xacro": True,
        "xacro_args": {"a": "1"},
    }


def test_child_environment_holds_nothing_of_the_user(hostile, monkeypatch, tmp_path):
    """The child starts with no variable of the user's: a stand-in child answers with its environment."""
    folder, _ = hostile
    spy = write(tmp_path / "spy.py", "import json, os\nprint(json.dumps({'xml': json.dumps(dict(os.environ))}))\n")
    monkeypatch.setattr(xacro_sandbox, "_CHILD", spy)
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(folder))
    env = json.loads(expand(write(folder / "e.urdf.xacro", robot("")), PackagePath()))
    assert SECRET not in json.dumps(env) and "HOME" not in env and "PATH" not in env, env
    assert set(env) <= {"LC_ALL", "PYTHONHASHSEED", "LC_CTYPE"}, env


def test_without_the_xacro_package_says_how_to_install(tmp_path, monkeypatch):
    """--xacro where the child's Python has no xacro: one line naming the extra and the manual way."""
    blocked = "import runpy, sys\nsys.modules['xacro'] = None\nrunpy.run_path({!r}, run_name='__main__')\n"
    spy = write(tmp_path / "child.py", blocked.format(str(xacro_sandbox._CHILD)))
    monkeypatch.setattr(xacro_sandbox, "_CHILD", spy)
    xacro_sandbox._EXPANDED.clear()
    path = write(tmp_path / "r.urdf.xacro", robot(""))
    with pytest.raises(XacroRefused, match=r"pip install 'bioform-mj\[urdf\]'.*`xacro .* > r.urdf`"):
        expand(path, PackagePath())


def test_run_with_the_xacro_flag(tmp_path, capsys, monkeypatch):
    """``bioform run --xacro --xacro-arg`` expands the scenario's xacro robot; its summary says xacro ran."""
    monkeypatch.chdir(tmp_path)
    text = diff_drive().replace('<robot name="dd">', f'<robot name="dd" {NS}><xacro:arg name="m" default="x"/>')
    write(tmp_path / "dd.urdf.xacro", text.replace('"0.2"', '"$(arg m)"', 1))
    sc = write(tmp_path / "a.toml", '[plant]\nkind = "mujoco"\nrobots = ["dd.urdf.xacro"]\n')
    out = tmp_path / "out"
    args = ["run", str(sc), "--duration", "0.05", "--out", str(out), "--no-robot-check", "--quiet"]
    code = cli.main([*args, "--xacro", "--xacro-arg", "m=0.2"])
    err = capsys.readouterr().err
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    assert any("expanded by xacro" in w for w in summary["import_warnings"]), summary["import_warnings"]
    assert "expanded by xacro" in err  # said before the run, as a warning: line
    # the flags are written into the robot's table: resolved.toml is granted xacro and its args by itself
    xacro_sandbox.grant(False)
    import bioform_mj

    again = bioform_mj.load(str(out / "resolved.toml"))
    assert again.plant.robots[0].xacro and again.plant.robots[0].xacro_args == (("m", "0.2"),)
    assert cli.main(["sweep", str(sc), "--xacro", "--out", str(tmp_path / "sw")]) == 2
    assert "write xacro = true" in capsys.readouterr().err


# ------------------------------------------------------------------ the OS layers (issue 28, design §12)
CHILD = Path(xacro_sandbox.__file__).with_name("_xacro_child.py")
PROBE = """
import ctypes, json, os, platform, sys
libc = ctypes.CDLL(None, use_errno=True)
libc.syscall.restype = ctypes.c_long
abi = libc.syscall(444, None, ctypes.c_size_t(0), ctypes.c_uint32(1))
libc.prctl(38, 1, 0, 0, 0)
flags = 0x40000000 if os.geteuid() == 0 else 0x50000000
print(json.dumps({"landlock": int(abi), "netns": libc.unshare(flags) == 0, "machine": platform.machine()}))
"""
TRY = """
import importlib.util, json, os, socket, subprocess, sys
spec = importlib.util.spec_from_file_location("child", sys.argv[1])
child = importlib.util.module_from_spec(spec)
spec.loader.exec_module(child)
inside, outside = sys.argv[2], sys.argv[3]
layers = child.os_sandbox([inside, *sorted({os.path.realpath(p) for p in sys.path if p and os.path.isdir(p)})])
got = {}
def attempt(name, fn):
    try:
        fn()
        got[name] = "done"
    except OSError as exc:
        got[name] = f"refused {exc.errno}"
attempt("read_inside", lambda: open(os.path.join(inside, "in.txt")).read())
attempt("read_outside", lambda: open(os.path.join(outside, "secret.txt")).read())
attempt("write_inside", lambda: open(os.path.join(inside, "new.txt"), "w").write("x"))
attempt("socket", lambda: socket.socket(socket.AF_INET, socket.SOCK_STREAM))
attempt("process", lambda: subprocess.run(["/bin/true"]))
print(json.dumps({"layers": layers, "got": got}))
"""


def _available() -> dict:
    """What this kernel offers, probed in a process of its own, independently of the child's code."""
    res = subprocess.run([sys.executable, "-I", "-c", PROBE], capture_output=True, text=True, timeout=60)
    return json.loads(res.stdout)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the OS layers are Linux's")
def test_os_layers_applied_where_available(tmp_path):
    """Each layer the kernel offers is on in the child (the probe says which), each one refuses on its own (no
    audit hook here): Landlock a read outside (EACCES 13) and a write inside, seccomp a socket and a new process
    (EPERM 1); a read inside still works. A layer the kernel lacks is said with why, never fatal."""
    avail = _available()
    inside, outside = tmp_path / "in", tmp_path / "out"
    inside.mkdir()
    outside.mkdir()
    (inside / "in.txt").write_text("ok")
    (outside / "secret.txt").write_text(SECRET)
    res = subprocess.run(
        [sys.executable, "-I", "-c", TRY, str(CHILD), str(inside), str(outside)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    out = json.loads(res.stdout)
    layers, got = out["layers"], out["got"]
    assert layers["no_new_privs"] == "on"
    assert got["read_inside"] == "done"
    if avail["landlock"] >= 1:
        assert layers["landlock"].startswith(f"on (ABI {avail['landlock']})"), layers
        assert got["read_outside"] == "refused 13" and got["write_inside"] == "refused 13", got
    else:
        pytest.skip(f"Landlock unavailable here (ABI probe {avail['landlock']}): {layers['landlock']}")
    if avail["machine"] in ("x86_64", "aarch64"):
        assert layers["seccomp"].startswith("on: 34 system calls refused"), layers
        assert got["socket"] == "refused 1" and got["process"] == "refused 1", got
    assert layers["netns"] == ("on" if avail["netns"] else layers["netns"])
    assert not (inside / "new.txt").exists()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the OS layers are Linux's")
def test_expansion_says_its_os_layers(tmp_path):
    """A real expansion: the child answers which layers it applied, and the import notes say so."""
    avail = _available()
    path = write(tmp_path / "r.urdf.xacro", diff_drive().replace('<robot name="dd">', f'<robot name="dd" {NS}>'))
    out = expand(path, (), ())
    want = (
        {"no_new_privs"}
        | ({"landlock"} if avail["landlock"] >= 1 else set())
        | ({"netns"} if avail["netns"] else set())
    )
    want |= {"seccomp"} if avail["machine"] in ("x86_64", "aarch64") else set()
    assert {k for k, v in out.sandbox.items() if v.startswith("on")} == want, out.sandbox
    note = xacro_sandbox.sandbox_note(out.sandbox)
    assert note.startswith(
        "xacro's process was also confined by the OS: " + ", ".join(k for k in out.sandbox if k in want)
    )


def test_find_of_a_package_whose_folder_has_another_name(hostile, tmp_path):
    """``$(find NAME)`` of the robot's own package kept in a folder of another name (a download renamed,
    ``dingo_description`` kept as ``dingo_edit``): found by its ``package.xml``, whose reading imported a module
    after the child's audit hook and was refused ("reading …/sanity.py" or "marshal.loads")."""
    folder, _ = hostile
    write(folder / "package.xml", "<package><name>my_description</name></package>")
    write(folder / "urdf" / "part.xacro", f'<robot {NS}><link name="b"/></robot>')
    path = write(
        folder / "urdf" / "ok.urdf.xacro",
        f'<robot name="h" {NS}><link name="a"/>'
        '<xacro:include filename="$(find my_description)/urdf/part.xacro"/></robot>',
    )
    assert folder.name != "my_description"
    out = expand(path, PackagePath())
    assert '<link name="b"/>' in out, out

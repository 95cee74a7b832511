"""Red team, round four (issue 28): the third round's leftovers and surfaces no round had tried.

Measured before the fixes (``bioform`` in a subprocess, each case in its own folder): a CSV recording with
1e11 s between two rows was fitted (``robot fit`` 72 s, exit 0) and replayed over its interpolated gap; a
payload event of 1e12 kg ran on the ideal plant (exit 0, ``c_true`` 1e-11) and diverged on the MuJoCo plant
(exit 3, ``mjWARN_BADQACC`` at t = 0.029 s); ``env`` randomisation of ``payload`` up to 1e12 kg was accepted;
``leader.speed = 1e12`` ran and stopped as diverged at t = 0 (exit 3, "leader-speed estimate 1e+09 exceeds
limits.speed")."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

from bioform_mj.cli import main as cli
from bioform_mj.core.errors import InputError

HDR = ",".join(["time"] + [f"{j}_wheel.{f}" for j in ("left", "right") for f in ("position", "velocity", "effort")])


def _csv(path: Path, times: list[float]) -> Path:
    rows = "".join(f"{t!r},{0.001 * k!r},0.1,0.01,{0.001 * k!r},0.1,0.01\n" for k, t in enumerate(times))
    path.write_text(HDR + "\n" + rows)
    return path


def _one_error(code: int, err: str, want: str) -> str:
    lines = err.strip().splitlines()
    errors = [e for e in lines if e.startswith("error:")]
    assert code == 2 and len(errors) == 1, (code, lines)
    assert want in errors[0], errors[0]
    assert not any("Traceback" in e or "internal error" in e for e in lines), lines
    return errors[0]


# ------------------------------------------------------------------ part A: the leftovers
def test_a_recording_paused_beyond_the_bound_is_refused_naming_the_lines(tmp_path, capsys):
    """1e11 s between lines 301 and 302 of a CSV (100 Hz otherwise): one error line naming both lines, the gap
    and the bound, exit 2, nothing written."""
    bag = _csv(tmp_path / "r.csv", [0.01 * k for k in range(300)] + [1e11 + 0.01 * k for k in range(300)])
    code = cli.main(["robot", "replay", "tb3", "--bag", str(bag), "--out", str(tmp_path / "out")])
    line = _one_error(code, capsys.readouterr().err, "the joint states pause for 1e+11 s between lines 301 and 302")
    assert "above the 600 s a recording may pause" in line and "every 0.01 s (median)" in line
    assert not (tmp_path / "out").exists()


def test_pause_bound_and_note(tmp_path):
    """Below :data:`PAUSE_MAX_S` a pause is read and said (a note naming the longest), above it refused; gaps of
    up to ten sample periods (or 0.1 s) are no pause at all."""
    from bioform_mj.robots.realdata.recording import PAUSE_MAX_S, pauses, read_recording

    assert PAUSE_MAX_S == 600.0
    joints = ("left_wheel", "right_wheel")
    head = [0.01 * k for k in range(300)]
    ok = read_recording(_csv(tmp_path / "a.csv", head + [2.99 + 599.0 + 0.01 * k for k in range(300)]), joints)
    (note,) = [n for n in ok.notes if n.startswith("the joint states pause")]
    assert "pause 1 time(s)" in note and "the longest 599 s between lines 301 and 302" in note
    with pytest.raises(InputError, match=r"pause for 601 s between lines 301 and 302"):
        read_recording(_csv(tmp_path / "b.csv", head + [2.99 + 601.0 + 0.01 * k for k in range(300)]), joints)
    t = np.arange(100) * 0.01
    t[50:] += 0.09  # 0.1 s between two samples: ten periods, not more
    assert pauses(t).size == 0
    t[70:] += 0.02  # 0.03 s: three periods
    assert pauses(t).size == 0
    t[80:] += 0.2  # 0.21 s
    assert pauses(t).tolist() == [79]
    clean = read_recording(_csv(tmp_path / "c.csv", head), joints)
    assert not [n for n in clean.notes if "pause" in n]


def _old_picks(t: np.ndarray, length: float, max_chunks: int) -> np.ndarray:
    """The chunk choice before pauses were known (every chunk a candidate)."""
    n_all = int((t[-1] - t[0] + 1e-9) // length)
    return np.unique(np.round(np.linspace(0, n_all - 1, min(n_all, max_chunks))).astype(int))


def test_fit_chunks_skip_pauses_and_are_unchanged_without_them():
    """Without a pause the chunks are the ones picked before (bit-equal indices, 300 random recordings); with
    pauses none spans one, as many are picked as there are clean ones (up to ``max_chunks``), counted by brute
    force here."""
    from bioform_mj.robots.realdata.recording import Recording, chunk_starts, pauses

    def rec(t: np.ndarray) -> Recording:
        z = np.zeros((len(t), 2))
        return Recording("x", ("l", "r"), t, z, z, z)

    rng = np.random.default_rng(7)
    for _ in range(300):
        dt = float(rng.choice([0.001, 0.01, 0.02, 1 / 30]))
        t = np.arange(int(rng.integers(3, 3000))) * dt
        length, m = float(rng.choice([0.5, 1.0, 2.0])), int(rng.integers(1, 30))
        assert np.array_equal(chunk_starts(rec(t), length, m), _old_picks(t, length, m))
    for _ in range(100):
        t = np.arange(int(rng.integers(500, 5000))) * 0.01
        for g in rng.integers(1, len(t) - 1, size=int(rng.integers(1, 6))):
            t[g:] += float(rng.choice([0.15, 1.0, 5.0, 100.0]))
        length, m = float(rng.choice([0.5, 2.0])), int(rng.integers(1, 20))
        ks = pauses(t)
        n_all = int((t[-1] + 1e-9) // length)
        clean = [c for c in range(n_all) if all(not (c * length < t[k + 1] and (c + 1) * length > t[k]) for k in ks)]
        got = chunk_starts(rec(t), length, m)
        assert set(got.tolist()) <= set(clean) and len(got) == len(set(got.tolist())) == min(len(clean), m)


def _payload_toml(t: Path, plant: str, mass: float, inertia: float = 0.0) -> Path:
    text = f'name = "t"\n[plant]\nkind = "{plant}"\n[sim]\nduration = 0.2\n'
    text += f'[[events]]\ntime = 0.0\nkind = "payload"\nfollower = 1\nmass = {mass!r}\ninertia = {inertia!r}\n'
    (t / "s.toml").write_text(text)
    return t / "s.toml"


@pytest.mark.parametrize(
    "plant,mass,inertia,want",
    [
        ("ideal", 1e12, 0.0, "'events[0].mass': a payload of 1e+12 kg, above 100 × the robot's (plant.mass) 25 kg"),
        ("mujoco", 1e12, 0.0, "'events[0].mass': a payload of 1e+12 kg, above 100 × the heaviest robot's mass 24.5 kg"),
        ("ideal", 1.0, 1e12, "'events[0].inertia': a payload of 1e+12 kg·m², above 100 × the robot's (plant.inertia)"),
    ],
    ids=["ideal-mass", "mujoco-mass", "ideal-inertia"],
)
def test_a_payload_no_robot_could_carry_is_refused_before_any_step(plant, mass, inertia, want, tmp_path, capsys):
    scen = _payload_toml(tmp_path, plant, mass, inertia)
    code = cli.main(["run", str(scen), "--out", str(tmp_path / "out")])
    assert "no robot of the scene could carry it" in _one_error(code, capsys.readouterr().err, want)
    assert not (tmp_path / "out").exists()


def test_payload_bound_is_the_scenes_robot_mass_times_100():
    """The bound follows the scene: ``plant.mass`` on the ideal plant (just below 100 × loads, above is refused;
    a heavier ``plant.mass`` moves it), the compiled robot's mass on the MuJoCo plant (the paper robot's subtree
    mass, summed here from its bodies); env randomisation refuses a range reaching past it."""
    import mujoco

    from bioform_mj.envs.randomize import Randomization
    from bioform_mj.robots.refs import models_dir
    from bioform_mj.scenario.loader import load

    ev = 'events=[{kind="payload", follower=1, time=0.0, mass=%r}]'
    load("paper", ["sim.duration=0.2", ev % 2499.0])
    with pytest.raises(InputError, match="events"):
        load("paper", ["sim.duration=0.2", ev % 2501.0])
    load("paper", ["sim.duration=0.2", ev % 2501.0, "plant.mass=26"])
    m = mujoco.MjModel.from_xml_path(str(models_dir() / "paper_robot.xml"))
    robot_mass = float(m.body_subtreemass[1])
    load("paper", ["sim.duration=0.2", "plant.kind=mujoco", ev % (99.9 * robot_mass)])
    with pytest.raises(InputError, match=f"mass {robot_mass:.4g} kg"):
        load("paper", ["sim.duration=0.2", "plant.kind=mujoco", ev % (100.1 * robot_mass)])
    base = load("paper")
    Randomization({"payload": (0.0, 2500.0)}, base, 1.0)
    with pytest.raises(ValueError, match=r"randomize\['payload'\] bound 1e\+12 is not accepted: .*could carry it"):
        Randomization({"payload": (0.0, 1e12)}, base, 1.0)


def test_a_leader_no_robot_could_reach_is_refused(tmp_path, capsys):
    """``leader.speed = 1e12``: refused naming the bound, the fastest a robot of the scene could go by the run's end
    from rest at full torque, ``2 a τ_max T`` (the ideal plant's ``c_true[0]``, ``torque.tau_max``,
    ``sim.duration``, at least 10 s, so a short run of a fast leader still runs: 320 m/s in the paper scene,
    computed here). A leader beyond ``limits.speed`` but within that
    reach still runs into the guard (exit 3, as tests force a divergence)."""
    import bioform_mj

    scen = tmp_path / "s.toml"
    scen.write_text('name = "t"\n[plant]\nkind = "ideal"\n[sim]\nduration = 0.2\n')
    code = cli.main(["run", str(scen), "--set", "leader.speed=1e12", "--out", str(tmp_path / "out")])
    want = "'leader.speed': the leader's speed reaches 1e+12 m/s, more than any robot of the scene could reach"
    line = _one_error(code, capsys.readouterr().err, want)
    assert "over 10 s (sim.duration, at least 10 s), 160 m/s; and beyond limits.speed = 100 m/s" in line, line
    assert not (tmp_path / "out").exists()
    sc = bioform_mj.load("paper")
    reach = 2 * sc.plant.c_true[0] * sc.torque.tau_max * sc.sim.duration
    assert reach == pytest.approx(320.0)
    top = lambda s: s.build_leader().speed_range(s.sim.duration)[1]  # noqa: E731
    ok = bioform_mj.load("paper", overrides=[f"leader.speed={0.99 * reach}"])  # beyond the guard: runs, diverges
    assert sc.limits.speed < top(ok) < reach
    with pytest.raises(InputError, match=r"over 20 s \(sim.duration, at least 10 s\), 320 m/s"):
        bioform_mj.load("paper", overrides=[f"leader.speed={1.01 * reach}"])
    bioform_mj.load("paper", overrides=[f"leader.speed={1.01 * reach}", f"limits.speed={2 * reach}"])  # guard wider
    with pytest.raises(InputError, match=r"scenario key 'leader': the leader's speed reaches 7\.07\d*e\+06 m/s"):
        bioform_mj.load("paper", overrides=['leader.kind="figure8"', "leader.frequency=1e6"])
    with pytest.raises(InputError, match=r"from rest at full torque \(5 N·m a wheel"):  # the MuJoCo robot's own drive
        bioform_mj.load("paper", overrides=["plant.kind=mujoco", "leader.speed=1e12"])


def test_kernel_cache_folder_falls_back_to_a_private_temporary_one(tmp_path, monkeypatch):
    """:func:`~bioform_mj.core.jitcache.writable_cache_dir`: a usable folder is taken as it is; one that cannot be
    made (under a file: refused even for root) falls back to ``$TMPDIR/bioform_mj-UID/NAME``, made mode 0700; a
    ``bioform_mj-UID`` folder others may write into (or a symlink) is never used: nothing is cached then."""
    import stat
    import tempfile

    from bioform_mj.core.jitcache import writable_cache_dir

    ok = tmp_path / "home" / ".cache"
    assert writable_cache_dir(str(ok), "k") == (str(ok), "") and ok.is_dir()
    (tmp_path / "file").write_text("")
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    folder, note = writable_cache_dir(str(tmp_path / "file" / "c"), "numba-x")
    private = tmp_path / "tmp" / f"bioform_mj-{os.getuid()}"
    assert folder == str(private / "numba-x") and Path(folder).is_dir()
    assert stat.S_IMODE(private.stat().st_mode) == 0o700
    assert note == f"the compiled kernels are cached in '{folder}' ('{tmp_path / 'file' / 'c'}': Not a directory; " + (
        "set NUMBA_CACHE_DIR)"
    )
    private.chmod(0o777)  # another user's folder, or one anyone may write into
    folder, note = writable_cache_dir(str(tmp_path / "file" / "c"), "numba-x")
    assert folder is None and note.startswith("the compiled kernels are not cached")
    private.chmod(0o700)
    private.rename(tmp_path / "elsewhere")
    private.symlink_to(tmp_path / "elsewhere")
    assert writable_cache_dir(str(tmp_path / "file" / "c"), "numba-x")[0] is None


def test_an_unwritable_home_is_a_warning_line_not_an_internal_error(tmp_path):
    """``HOME`` where ``~/.cache`` cannot be made: every import of the package was an internal error (numba's
    "no locator available"); now one ``warning:`` line names where the kernels are cached, the command goes on;
    Python code gets a :class:`~bioform_mj.core.errors.CacheWarning`."""
    import subprocess
    import sys

    src = str(Path(__file__).resolve().parents[1] / "src")
    (tmp_path / "file").write_text("")
    (tmp_path / "tmp").mkdir()
    env = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path / "file"), "TMPDIR": str(tmp_path / "tmp"), "PYTHONPATH": src}
    p = subprocess.run(
        [sys.executable, "-m", "bioform_mj.cli", "run", "nope.toml"],
        env=env,
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(lines) == 2, p.stderr
    assert lines[0].startswith(f"warning: the compiled kernels are cached in '{tmp_path / 'tmp' / 'bioform_mj-'}")
    assert lines[1] == "error: scenario file 'nope.toml' does not exist"


@pytest.mark.slow  # an interpreter as nobody and a first compile: 1.2-4 s
def test_a_read_only_home_as_a_user_other_than_root(tmp_path):
    """As ``nobody`` (``setpriv``; root ignores permissions): a home of mode 0555. The package imports, its kernels
    compile and run (``wrap(7) = 7 - 2π``) cached in the user's private temporary folder, said in a
    :class:`~bioform_mj.core.errors.CacheWarning`."""
    import shutil
    import subprocess
    import sys
    import tempfile

    if os.getuid() != 0 or shutil.which("setpriv") is None:
        pytest.skip("needs root and setpriv to act as another user")
    src = str(Path(__file__).resolve().parents[1] / "src")
    top = Path(tempfile.mkdtemp(prefix="bioform-ro-", dir="/tmp"))  # pytest's own folder is root's alone
    try:
        top.chmod(0o1777)
        home = top / "ro"
        home.mkdir(mode=0o555)
        code = "import bioform_mj.core.equations as e; print(e._CACHE, e.wrap(7.0))"
        env = {"PATH": "/usr/bin:/bin", "HOME": str(home), "TMPDIR": str(top), "PYTHONPATH": src}
        p = subprocess.run(
            ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", sys.executable, "-c", code],
            env=env,
            capture_output=True,
            text=True,
            cwd=top,
        )
        if p.returncode and "Permission denied" in p.stderr and "Traceback" not in p.stderr:
            pytest.skip(f"the interpreter cannot be run as nobody here: {p.stderr.strip()}")
        if p.returncode and "ModuleNotFoundError" in p.stderr:  # a checkout or venv under a folder of mode 0700
            pytest.skip(f"this checkout or its packages cannot be read by nobody: {p.stderr.strip().splitlines()[-1]}")
        assert p.returncode == 0, p.stderr
        assert p.stdout.split() == ["True", repr(7.0 - 2 * math.pi)]
        assert f"CacheWarning: the compiled kernels are cached in '{top / 'bioform_mj-65534'}" in p.stderr
        assert f"('{home}/.cache/bioform_mj/numba-" in p.stderr and "Permission denied; set NUMBA_CACHE_DIR" in p.stderr
    finally:
        shutil.rmtree(top, ignore_errors=True)


# ------------------------------------------------------------------ part B: surfaces no round had tried
def test_a_dotted_key_of_100000_parts_is_refused_before_parsing(tmp_path, capsys):
    """One line ``a.a.a…= 1`` of 10^5 parts (200 kB): Python's TOML parser keeps every prefix of the key (20,000
    parts: 1.5 GB; 10^5: a MemoryError after 36 s, an internal error). Refused by a linear scan: dots inside
    strings and numbers are no key; 256 parts are read, 257 are not; ``--set`` values (inline tables) alike."""
    from bioform_mj.scenario.loader import MAX_KEY_PARTS, deep_key_line

    scen = tmp_path / "s.toml"
    scen.write_text('name = "t"\n[plant]\nkind = "ideal"\n' + ".".join(["a"] * 100_000) + " = 1\n")
    code = cli.main(["run", str(scen), "--out", str(tmp_path / "out")])
    _one_error(code, capsys.readouterr().err, "s.toml: line 4 has a dotted key of more than 256 parts (not a scenario)")
    assert MAX_KEY_PARTS == 256
    key = ".".join(["a"] * 256)
    assert deep_key_line(f"{key} = 1") == 0 and deep_key_line(f"x = 1\n{key}.b = 1") == 2
    assert deep_key_line("[" + ".".join(['"q.q"'] * 300) + "]") == 1  # quoted parts count once each
    assert deep_key_line('d = "' + ".".join(["a"] * 300) + '"') == 0  # a string value
    assert deep_key_line("v = [" + ", ".join(["1.5"] * 1000) + "]") == 0  # numbers
    assert deep_key_line(" . ".join(["a"] * 300) + " = 1") == 1  # whitespace around the dots
    scen.write_text('name = "t"\n[plant]\nkind = "ideal"\n')
    code = cli.main(["run", str(scen), "--set", "sim={" + ".".join(["a"] * 300) + "=1}", "--out", str(tmp_path / "o")])
    _one_error(code, capsys.readouterr().err, "--set 'sim': the value has a dotted key of more than 256 parts")


def test_an_ascii_terminal_gets_escapes_not_an_internal_error():
    """``PYTHONIOENCODING=ascii`` (or a C locale without UTF-8 mode): the first ``N·m`` a command printed was an
    internal error (UnicodeEncodeError, exit 1). The CLI's streams write what the encoding lacks escaped."""
    import io

    from bioform_mj.cli.proc import _PipeSafe

    raw = io.BytesIO()
    stream = io.TextIOWrapper(raw, encoding="ascii", write_through=True)
    out = _PipeSafe(stream, "stderr")
    assert out.write("warning: 1.4 N·m, 81.7 m/s², μ\u202e\n") > 0
    assert raw.getvalue() == b"warning: 1.4 N\\xb7m, 81.7 m/s\\xb2, \\u03bc\\u202e\n"


def test_files_are_utf8_whatever_the_locale(tmp_path):
    """Under ``LC_ALL=C`` without UTF-8 mode (``PYTHONUTF8=0``, ``PYTHONCOERCECLOCALE=0``) ``bioform run``, ``sweep``,
    ``robot fit`` and ``table1`` ended in internal errors writing ``±``, ``·``, ``∫`` into their text files (the
    locale's ASCII). The writers and the CSV reader name UTF-8."""
    import subprocess
    import sys

    code = (
        "import sys; from pathlib import Path; from bioform_mj.outputs.files import write_text\n"
        "from bioform_mj.robots.realdata.recording import read_recording\n"
        "d = Path(sys.argv[1]); write_text(d / 'a.md', bytes.fromhex(sys.argv[2]).decode())\n"
        "print(read_recording(d / 'r.csv', ('left_wheel', 'right_wheel')).t.size, sys.getfilesystemencoding())\n"
    )
    rows = "".join(f"{0.01 * k!r},{0.001 * k!r},0.1,0.01,{0.001 * k!r},0.1,0.01,ü\n" for k in range(20))
    (tmp_path / "r.csv").write_text(HDR + ",τ_note\n" + rows, encoding="utf-8")  # a column the fit does not use
    env = {"PATH": "/usr/bin:/bin", "LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0"}
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[1] / "src")
    text = "τ ± 2 N·m ∫"
    p = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path), text.encode().hex()], env=env, capture_output=True, text=True
    )
    assert p.returncode == 0, p.stderr
    assert p.stdout.split() == ["20", "ascii"]  # the locale really is ASCII here
    assert (tmp_path / "a.md").read_bytes() == text.encode()


def test_a_complete_graph_beyond_a_million_edges_is_refused_unbuilt():
    """``graph.kind = "complete"`` over 20,000 followers (2e8 edges) was a MemoryError after 25 s while the edge
    list was built; over 1415 followers (1,000,405 edges) it is refused naming the count, before any edge is made."""
    import bioform_mj
    from bioform_mj.scenario.check import MAX_EDGES

    assert MAX_EDGES == 10**6
    for n, edges in ((20_000, 199_990_000), (1415, 1_000_405)):
        ov = {
            "sim.duration": 0.1,
            "graph.kind": "complete",
            "formation.offsets": [[-1.0 - 0.5 * i, 0.0] for i in range(n)],
            "formation.initial_poses": [[-1.0 - 0.5 * i, 0.0, 0.0] for i in range(n)],
        }
        with pytest.raises(InputError, match=f"'complete' over {n} followers is {edges} edges, above the 1e\\+06"):
            bioform_mj.load("paper", overrides=ov)  # (on main, 1415 followers built 1e6 edges in ~7 s and ran)


@pytest.mark.parametrize("reps", ["0", "101", "1000000000"])
def test_bench_reps_beyond_the_bound_is_refused_before_any_run(reps, tmp_path, capsys):
    """``bioform bench --reps 1000000000`` ran on past 120 s with nothing said of its end (each pair runs the scene
    twice): refused outside 1..100 before anything runs."""
    code = cli.main(["bench", "--sizes", "3", "--reps", reps, "--json", str(tmp_path / "b.json")])
    _one_error(code, capsys.readouterr().err, f"--reps must be in 1..100 (each pair runs the scene twice), got {reps}")
    assert not (tmp_path / "b.json").exists()


@pytest.mark.parametrize("bad", [["1", "2"], [True, False], np.array([1j, 0.0]), np.array([0.1, None], dtype=object)])
def test_env_actions_that_are_not_real_numbers_are_refused(bad):
    """The parallel, single-follower and vector environments took ``["1", "2"]``, booleans and complex numbers (the
    imaginary part dropped with a ComplexWarning) as actions; refused naming the agent. Real numbers of any
    width still pass (float32, int, a list)."""
    import bioform_mj.envs as E
    from bioform_mj.envs.single import follower_env

    pe = E.parallel_env("paper", overrides=["sim.duration=0.05"])
    pe.reset(seed=0)
    ok = {a: np.zeros(2, np.float32) for a in pe.agents}
    with pytest.raises(ValueError, match="action of follower_1 must be 2 numbers, got "):
        pe.step(dict.fromkeys(pe.agents, bad))
    if not isinstance(bad[0], bool):  # beside float arrays numpy makes booleans floats (not checked per agent)
        with pytest.raises(ValueError, match="action of follower_2 must be 2 numbers, got "):
            pe.step({**ok, "follower_2": bad})
    pe.step({**ok, "follower_2": [0, 0]})
    fe = follower_env("paper", overrides=["sim.duration=0.05"])
    fe.reset(seed=0)
    with pytest.raises(ValueError, match="action must be 2 real numbers"):
        fe.step(bad)
    fe.step(np.zeros(2, np.float32))


def test_vector_env_threads_beyond_its_worlds_are_refused_before_building():
    """``vector_env(worlds=2, threads=10**6)``: each thread holds an ``MjData``; it ended in MuJoCo's ``FatalError:
    Could not allocate memory``. Refused before anything is built."""
    from bioform_mj.envs.vector import FAST, VectorEnv

    if not FAST:
        pytest.skip("needs numba's JIT")
    with pytest.raises(
        ValueError, match=r"threads must be at most worlds = 2 \(a thread steps a block of worlds\), got"
    ):
        VectorEnv("paper", 2, threads=10**6, overrides=["plant.kind=mujoco"])


def test_a_leader_turning_faster_than_any_robot_could_is_refused():
    """``leader.kind = "circle"`` of radius 1e-300 m: the run diverged at t = 0.001 s (a commanded torque of 1.2e296
    N·m). Refused when the leader's yaw rate passes what a robot of the scene could reach from rest at full torque,
    ``2 b τ_max T`` (the paper: 2 · 10 · 20 · 20 = 8000 rad/s); a 5 m circle at 1 m/s (0.2 rad/s) loads."""
    import bioform_mj

    circle = ['leader.kind="circle"', "leader.y0=5"]
    with pytest.raises(
        InputError, match=r"the leader turns at up to 1e\+300 rad/s.* over 20 s \(sim.duration, at least 10 s\), 8000"
    ):
        bioform_mj.load("paper", overrides=[*circle, "leader.radius=1e-300"])
    sc = bioform_mj.load("paper", overrides=[*circle, "leader.radius=5"])
    assert sc.build_leader().motion_range(sc.sim.duration)[2] == pytest.approx(0.2)
    bioform_mj.load("paper", overrides=[*circle, "leader.radius=1.01e-4", "leader.speed=0.8"])  # 7921 rad/s
    with pytest.raises(InputError, match="the leader turns at up to 8000.8"):
        bioform_mj.load("paper", overrides=[*circle, "leader.radius=0.9999e-4", "leader.speed=0.8"])


def test_a_newline_in_a_robot_or_recording_path_forges_no_line(tmp_path, capsys):
    """A robot file named ``r\\nerror: forged.xml`` (legal on Linux): ``robot check`` printed ``pass: r`` and then a
    line ``error: forged.xml`` on stdout (exit 0); ``robot replay`` of a recording so named did the same. The paths
    are printed escaped (``\\n``)."""
    from bioform_mj.robots.refs import models_dir

    name = "r\nerror: forged"
    (tmp_path / f"{name}.xml").write_text((models_dir() / "paper_robot.xml").read_text())
    assert cli.main(["robot", "check", str(tmp_path / f"{name}.xml")]) == 0
    out = capsys.readouterr().out.splitlines()
    assert not [ln for ln in out if ln.startswith("error:")], out[:3]
    assert out[0] == f"pass: {tmp_path}/r\\nerror: forged.xml"
    _csv(tmp_path / f"{name}.csv", [0.01 * k for k in range(400)])
    assert cli.main(["robot", "replay", "tb3", "--bag", str(tmp_path / f"{name}.csv")]) == 0
    out = capsys.readouterr().out.splitlines()
    assert (
        not [ln for ln in out if ln.startswith("error:")] and "of " + str(tmp_path) + "/r\\nerror: forged.csv" in out[0]
    )

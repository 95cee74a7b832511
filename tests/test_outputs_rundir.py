"""Run folders, locks, signals, MuJoCo's log, up-front path checks (issue 11). All on the ideal plant, short runs."""

from __future__ import annotations

import json
import os
import pty
import re
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from bioform_mj.cli.main import main

SRC = str(Path(__file__).resolve().parents[1] / "src")
ENV = {**os.environ, "PYTHONPATH": SRC + os.pathsep + os.environ.get("PYTHONPATH", "")}


def _run(argv, capsys):
    code = main(argv)
    err = capsys.readouterr().err
    return code, err


def _one_error(err: str, needle: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and needle in lines[0], err
    assert "Traceback" not in err


def _tmp_files(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if p.name.endswith(".tmp")] if folder.exists() else []


# ---- one run per folder -----------------------------------------------------------------------


def test_second_run_into_a_folder_is_refused_then_overwrite_replaces_it(tmp_path, capsys):
    out = tmp_path / "r"
    assert main(["run", "--duration", "0.1", "--quiet", "--out", str(out)]) == 0
    capsys.readouterr()  # (its warnings: a 0.1 s run ends far from the formation)
    (out / "figures").mkdir()
    (out / "figures" / "old.png").write_bytes(b"png")
    (out / "video.mp4").write_bytes(b"old video")
    (out / "MUJOCO_LOG.TXT").write_text("old")
    before = (out / "summary.json").stat().st_mtime_ns
    code, err = _run(["run", "--duration", "0.1", "--quiet", "--out", str(out)], capsys)
    assert code == 2
    _one_error(err, "holds another run's files")
    assert (out / "summary.json").stat().st_mtime_ns == before and (out / "video.mp4").exists()

    assert main(["run", "--duration", "0.2", "--quiet", "--out", str(out), "--overwrite"]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == ["log.npz", "resolved.toml", "summary.json"]  # the old video, figures and MuJoCo log are gone
    assert json.loads((out / "summary.json").read_text())["sim_time_s"] == pytest.approx(0.2)


def test_overwrite_never_deletes_files_that_are_not_a_run(tmp_path, capsys):
    out = tmp_path / "r"
    assert main(["run", "--duration", "0.1", "--quiet", "--out", str(out)]) == 0
    capsys.readouterr()
    (out / "notes.txt").write_text("mine")
    (out / "figures").mkdir()
    (out / "figures" / "draft.svg").write_text("mine too")
    for extra in ([], ["--overwrite"]):
        code, err = _run(["run", "--duration", "0.1", "--quiet", "--out", str(out), *extra], capsys)
        assert code == 2
        _one_error(err, "not a run's")
    assert (out / "notes.txt").read_text() == "mine" and (out / "figures" / "draft.svg").exists()
    assert (out / "summary.json").exists()


def test_table1_folder_is_claimed_too(tmp_path, capsys):
    out = tmp_path / "t"
    out.mkdir()
    (out / "table1.md").write_text("old")
    code, err = _run(["table1", "--duration", "0.05", "--quiet", "--out", str(out)], capsys)
    assert code == 2
    _one_error(err, "holds another run's files")


def test_stale_temporary_files_of_a_killed_run_are_cleared(tmp_path):
    out = tmp_path / "r"
    out.mkdir()
    (out / ".log.npz.abc123.tmp").write_bytes(b"half")
    (out / ".bioform.lock").write_text("12345")  # a killed run's lock file: no lock is held on it
    assert main(["run", "--duration", "0.1", "--quiet", "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["log.npz", "resolved.toml", "summary.json"]


def test_concurrent_writer_is_refused(tmp_path, capsys):
    import fcntl

    out = tmp_path / "r"
    out.mkdir()
    fd = os.open(out / ".bioform.lock", os.O_RDWR | os.O_CREAT)
    try:
        os.write(fd, b"4242")
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # as a run in progress holds it
        code, err = _run(["run", "--duration", "0.1", "--quiet", "--out", str(out)], capsys)
        assert code == 2
        _one_error(err, "in use: process 4242")
        assert not (out / "summary.json").exists()
    finally:
        os.close(fd)
    assert main(["run", "--duration", "0.1", "--quiet", "--out", str(out)]) == 0  # released: accepted


def test_two_processes_into_one_folder(tmp_path):
    """Two real runs started together: one writes, the other is refused (exit 2); never mixed files."""
    out = tmp_path / "r"
    cmd = [
        sys.executable,
        "-m",
        "bioform_mj.cli",
        "run",
        "--duration",
        "60",
        "--quiet",
        "--set",
        "sim.log_dt=0.05",
        "--out",
        str(out),
    ]
    procs = [subprocess.Popen(cmd, env=ENV, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    res = [(p.wait(timeout=120), p.stderr.read()) for p in procs]
    codes = sorted(r[0] for r in res)
    assert codes == [0, 2], res
    refused = next(e for c, e in res if c == 2)
    assert "in use" in refused or "holds another run's files" in refused
    with np.load(out / "log.npz") as z:
        assert z["pose"].shape[0] == 1200


def test_lock_is_released_and_removed(tmp_path):
    out = tmp_path / "r"
    assert main(["run", "--duration", "0.1", "--quiet", "--out", str(out)]) == 0
    assert not (out / ".bioform.lock").exists()


def test_failed_start_leaves_no_folder(tmp_path, capsys, monkeypatch):
    """An error after the folder was claimed but before anything was written removes the folder again."""
    import bioform_mj.run.simulate as sim
    from bioform_mj.core.errors import InputError

    monkeypatch.setattr(sim, "simulate", lambda *a, **k: (_ for _ in ()).throw(InputError("plant could not be built")))
    out = tmp_path / "a" / "b"
    code, err = _run(["run", "--duration", "0.1", "--quiet", "--out", str(out)], capsys)
    assert code == 2 and "plant could not be built" in err
    assert not (tmp_path / "a").exists()


# ---- the output name stays under runs/ ----------------------------------------------------------


@pytest.mark.parametrize(
    "name,needle",
    [
        ('"../../x"', "plain file name"),
        ('"/etc/x"', "plain file name"),
        ('"a/b"', "plain file name"),
        ('""', "is empty"),
        ('"  "', "is empty"),
        ('"a\\u0000b"', "plain file name"),
        ('".hidden"', "starts with '.'"),
        ('"tab\\there"', "control character"),
        ('"' + "x" * 200 + '"', "longer than"),
    ],
)
def test_scenario_name_must_be_a_plain_file_name(name, needle, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    f = tmp_path / "s.toml"
    f.write_text(f"name = {name}\n")
    code, err = _run(["run", str(f), "--duration", "0.05", "--quiet"], capsys)
    assert code == 2
    _one_error(err, needle)
    assert list(tmp_path.iterdir()) == [f]  # nothing written anywhere (no runs/, nothing outside)


def test_default_output_is_under_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--duration", "0.05", "--quiet", "--set", 'name="my run"']) == 0
    (folder,) = (tmp_path / "runs").iterdir()  # --duration changed the configuration: its hash is in the name
    assert folder.name.startswith("my run-ideal-bioinspired-learning-") and (folder / "summary.json").exists()
    assert main(["run", "paper", "--quiet", "--set", 'name="named"', "--set", "sim.duration=0.05"]) == 0
    names = sorted(p.name for p in (tmp_path / "runs").iterdir())
    assert len(names) == 2 and re.fullmatch(r"named-ideal-bioinspired-learning-[0-9a-f]{8}", names[1]), names


# ---- bad paths, up front -------------------------------------------------------------------------


def _dangling(tmp_path):
    link = tmp_path / "dangling"
    link.symlink_to(tmp_path / "nowhere")
    return link


@pytest.mark.parametrize(
    "make,needle",
    [
        (lambda t: Path("/proc/bioform-out"), "special file system"),
        (lambda t: Path("/sys/bioform-out"), "special file system"),
        (lambda t: _dangling(t), "dangling symlink"),
        (lambda t: _dangling(t) / "sub", "dangling symlink"),
        (lambda t: (t / "f").write_text("x") and t / "f", "not a directory"),
        (lambda t: (t / "g").write_text("x") and t / "g" / "sub", "not a directory"),
    ],
)
def test_bad_out_dir(make, needle, tmp_path, capsys):
    out = make(tmp_path)
    t0 = time.perf_counter()
    code, err = _run(["run", "--duration", "50", "--quiet", "--out", str(out)], capsys)
    assert code == 2
    _one_error(err, needle)
    assert time.perf_counter() - t0 < 5  # before the work, not after a 50 s run


def test_nul_in_out_is_refused(capsys):
    code, err = _run(["run", "--duration", "0.05", "--quiet", "--out", "a\x00b"], capsys)
    assert code == 2
    _one_error(err, "NUL")


def test_read_only_out_dir(tmp_path, capsys, monkeypatch):
    """Root passes os.access checks, so the check creates and removes a probe; simulate a refusal."""
    import tempfile

    def refuse(*a, **k):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "mkdtemp", refuse)
    code, err = _run(["run", "--duration", "0.05", "--quiet", "--out", str(tmp_path / "ro")], capsys)
    assert code == 2
    _one_error(err, "not writable")


@pytest.mark.parametrize(
    "target,needle",
    [
        ("/proc/bench.json", "special file system"),
        ("DANGLING", "dangling symlink"),
        ("DIR", "not a regular file"),
        ("/dev/null", "special file system"),
    ],
)
def test_bench_json_checked_before_the_work(target, needle, tmp_path, capsys, monkeypatch):
    import bioform_mj.jobs.bench as bench

    monkeypatch.setattr(bench, "bench_case", lambda *a, **k: pytest.fail("the benchmark ran before the check"))
    target = {"DANGLING": str(_dangling(tmp_path)), "DIR": str(tmp_path)}.get(target, target)
    code, err = _run(["bench", "--sizes", "3", "--json", target], capsys)
    assert code == 2
    _one_error(err, needle)


def test_bench_in_a_folder_without_runs_writes_its_json(tmp_path, capsys, monkeypatch):
    import bioform_mj.jobs.bench as bench

    monkeypatch.chdir(tmp_path)
    row = {
        "n": 3,
        "ratio": 1.0,
        "us_per_robot_step": 1.0,
        "realtime_factor": 1.0,
        "solver_iters_per_step": 1.0,
        "constant_torque_solver_iters_per_step": 1.0,
        "physics_dt_s": 0.001,
        "bare_steps_per_s": 1.0,
        "loop_steps_per_s": 1.0,
        "ideal_us_per_robot_step": 1.0,
        "ratio_cpu": 1.0,
        "ratio_pairs": [1.0],
        "replay_max_abs_dqpos": 0.0,
        "us_per_robot_step_cpu": 1.0,
        "realtime_factor_cpu": 1.0,
        "load_avg": [1.0, 1.0],
    }
    monkeypatch.setattr(bench, "bench_case", lambda *a, **k: dict(row))
    assert main(["bench", "--sizes", "3"]) == 0
    assert json.loads((tmp_path / "runs" / "bench.json").read_text())["rows"][0]["n"] == 3


@pytest.mark.parametrize(
    "target,needle",
    [("/proc/id.json", "special file system"), ("DANGLING", "dangling symlink"), ("FILEDIR", "not a directory")],
)
def test_identify_out_checked_before_the_work(target, needle, tmp_path, capsys, monkeypatch):
    import bioform_mj.assess.identify as identify

    monkeypatch.setattr(identify, "identify_main", lambda *a, **k: pytest.fail("identified before the check"))
    if target == "FILEDIR":
        (tmp_path / "f").write_text("x")
    target = {"DANGLING": str(_dangling(tmp_path)), "FILEDIR": str(tmp_path / "f" / "id.json")}.get(target, target)
    code, err = _run(["identify", "paper", "--out", target], capsys)
    assert code == 2
    _one_error(err, needle)


# ---- signals --------------------------------------------------------------------------------------


def _wait_for(cond, proc, timeout=60.0):
    deadline = time.time() + timeout
    while time.time() < deadline:
        if cond():
            return True
        if proc.poll() is not None:
            return False
        time.sleep(0.02)
    return False


def _check_interrupted_folder(out: Path, err: str) -> None:
    """What the message claims is there, and complete; never a temporary file."""
    assert not _tmp_files(out), _tmp_files(out)
    assert not (out / ".bioform.lock").exists()
    if "log so far kept" in err:
        s = json.loads((out / "summary.json").read_text())
        assert s["interrupted"]["signal"] in ("SIGTERM", "SIGINT") and 0 < s["sim_time_s"] < 400
        with np.load(out / "log.npz") as z:
            assert z["pose"].shape[0] >= 1 and np.all(np.isfinite(z["pose"]))
    else:  # nothing kept: no folder (it was created by this run) or an empty one
        assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize(
    "sig,code,engine,duration", [(signal.SIGTERM, 143, "compiled", "400"), (signal.SIGINT, 130, "stepwise", "10")]
)
def test_signal_mid_run(sig, code, engine, duration, tmp_path):
    """The signal lands while the loop steps: the progress bar (on a pseudo-terminal) shows >= 2 %.
    (compiled: between two compiled chunks; stepwise: anywhere in the Python loop)."""
    import fcntl
    import struct
    import termios

    out = tmp_path / "r"
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # tqdm draws nothing at width 0
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "bioform_mj.cli",
            "run",
            "--duration",
            duration,
            "--engine",
            engine,
            "--set",
            "sim.log_dt=0.05",
            "--out",
            str(out),
        ],
        env=ENV,
        stdout=subprocess.DEVNULL,
        stderr=slave,
        stdin=subprocess.DEVNULL,
    )
    os.close(slave)
    seen = b""
    deadline = time.time() + 90
    try:
        while time.time() < deadline and proc.poll() is None:
            r, _, _ = select.select([master], [], [], 0.1)
            if r:
                try:
                    seen += os.read(master, 4096)
                except OSError:
                    break
            pcts = [int(x) for x in __import__("re").findall(rb"\|\s*(\d+)%", seen)]
            if pcts and 2 <= max(pcts) < 90:
                break
        assert proc.poll() is None, "the run ended before the signal: " + seen.decode(errors="replace")[-300:]
        proc.send_signal(sig)
        rc = proc.wait(timeout=60)
        while True:
            r, _, _ = select.select([master], [], [], 0.2)
            if not r:
                break
            try:
                chunk = os.read(master, 4096)
            except OSError:
                break
            if not chunk:
                break
            seen += chunk
    finally:
        if proc.poll() is None:
            proc.kill()
        os.close(master)
    err = seen.decode(errors="replace")
    assert rc == code, err[-500:]
    assert f"interrupted by {signal.Signals(sig).name}" in err and "Traceback" not in err
    assert "log so far kept" in err, err[-500:]  # simulate returns the run so far (RunResult.interrupted)
    _check_interrupted_folder(out, err)


def test_sigterm_while_rendering_the_video_leaves_no_temporary_file(tmp_path):
    """The signal lands while video.mp4 is being written (its temporary file exists): the run's
    summary and log are complete, no video and no temporary file."""
    out = tmp_path / "r"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "bioform_mj.cli",
            "run",
            "--duration",
            "12",
            "--quiet",
            "--video",
            "--width",
            "320",
            "--height",
            "240",
            "--out",
            str(out),
        ],
        env=ENV,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert _wait_for(lambda: bool(list(out.glob(".video.mp4.*.tmp"))), proc, 90), proc.stderr.read()
        time.sleep(0.3)
        proc.send_signal(signal.SIGTERM)
        rc = proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    err = proc.stderr.read()
    assert rc == 143, err
    assert "interrupted by SIGTERM" in err and "summary.json and log.npz" in err and "Traceback" not in err
    assert not _tmp_files(out) and not (out / "video.mp4").exists()
    assert json.loads((out / "summary.json").read_text())["sim_time_s"] == pytest.approx(12)
    with np.load(out / "log.npz") as z:
        assert z["pose"].shape[0] == 1200


def test_interrupt_carrying_a_result_is_kept(tmp_path, capsys, monkeypatch):
    """A KeyboardInterrupt that carries ``.result`` (simulate's alternative to returning a result with
    ``interrupted`` set) is written like a divergence (summary marked ``interrupted``), exit 128 + signum."""
    import bioform_mj.run.simulate as sim
    from bioform_mj.core.errors import Interrupted

    real = sim.simulate

    def partial(sc, **kw):
        res = real(sc)
        exc = Interrupted(signal.SIGTERM)
        exc.result = res
        raise exc

    monkeypatch.setattr(sim, "simulate", partial)
    out = tmp_path / "r"
    code, err = _run(["run", "--duration", "0.3", "--quiet", "--out", str(out)], capsys)
    assert code == 143
    _one_error(err, "interrupted by SIGTERM")
    assert "log so far kept" in err
    _check_interrupted_folder(out, err)


def test_interrupt_without_result_leaves_no_folder(tmp_path, capsys, monkeypatch):
    import bioform_mj.run.simulate as sim

    def stop(sc, **kw):
        raise KeyboardInterrupt

    monkeypatch.setattr(sim, "simulate", stop)
    out = tmp_path / "r"
    code, err = _run(["run", "--duration", "0.3", "--quiet", "--out", str(out)], capsys)
    assert code == 130
    _one_error(err, "interrupted by SIGINT")
    assert not out.exists()


# ---- MuJoCo's own log ----------------------------------------------------------------------------


def test_mujoco_warnings_go_to_the_run_folder_not_the_cwd(tmp_path, monkeypatch, capsys):
    """A MuJoCo warning raised during a run (here: from the plant's first step) lands in
    DIR/MUJOCO_LOG.TXT and on stderr as a warning line; the working directory stays clean."""
    import mujoco

    import bioform_mj.run.simulate as sim

    real = sim.simulate

    def noisy(sc, **kw):
        m = mujoco.MjModel.from_xml_string(
            "<mujoco><worldbody><body><freejoint/><geom size='.1'/></body></worldbody></mujoco>"
        )
        d = mujoco.MjData(m)
        d.qvel[:] = 1e20
        mujoco.mj_step(m, d)  # "Nan, Inf or huge value in QVEL": MuJoCo's default handler writes ./MUJOCO_LOG.TXT
        return real(sc, **kw)

    monkeypatch.setattr(sim, "simulate", noisy)
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "r"
    code, err = _run(["run", "--duration", "0.05", "--quiet", "--out", str(out)], capsys)
    assert code == 0, err
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
    assert "QVEL" in (out / "MUJOCO_LOG.TXT").read_text()
    assert "warning: MuJoCo:" in err
    # MuJoCo's own handler is back afterwards (the CLI does not leak its hook into a library user)
    from bioform_mj.outputs import mjlog

    assert mujoco.get_mju_user_warning() is None or not isinstance(
        getattr(mujoco.get_mju_user_warning(), "__self__", None), mjlog.MujocoLog
    )


def test_mujoco_warnings_of_the_compiled_loop_are_captured(tmp_path):
    """The compiled loop calls mj_step from numba without the GIL: the handler still gets the message."""
    import mujoco

    from bioform_mj.outputs.mjlog import MujocoLog
    from bioform_mj.plants.mujoco import kernels as mk

    numba = pytest.importorskip("numba")
    if getattr(mk, "_mj_step", None) is None:
        pytest.skip("no compiled mj_step")

    @numba.njit(nogil=True)
    def step(mp, dp):
        mk._mj_step(mp, dp)

    m = mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body><freejoint/><geom size='.1'/></body></worldbody></mujoco>"
    )
    d = mujoco.MjData(m)
    d.qvel[:] = 1e20
    with MujocoLog(echo=False) as log:
        step(m._address, d._address)
    assert log.messages and "QVEL" in log.messages[0][1]
    assert log.write(tmp_path) == tmp_path / "MUJOCO_LOG.TXT"


# ---- the progress bar says what it is doing -------------------------------------------------------


def test_progress_phase_is_shown_and_ends_when_stepping_starts():
    import io

    from bioform_mj.outputs.progress import progress_bar

    class Tty(io.StringIO):
        def isatty(self):
            return True

    tty = Tty()
    with progress_bar("paper run", stream=tty) as cb:
        cb(0, 100)
        cb.phase("compiling numba kernels (first run only)")
        time.sleep(0.05)
        for k in range(1, 101):
            cb(k, 100)
    text = tty.getvalue()
    assert "paper run — compiling numba kernels (first run only)" in text
    tail = text[text.rindex("compiling") :]
    assert "100%" in tail and "compiling" not in tail[len("compiling") :]  # the phase ended with the stepping


# ---- presets and table1 ---------------------------------------------------------------------------


def test_presets_have_descriptions(capsys):
    from bioform_mj.scenario.loader import load, preset_descriptions, preset_names

    desc = preset_descriptions()
    assert set(desc) == set(preset_names())
    for name, text in desc.items():
        assert len(text) > 10 and "\n" not in text, name
        assert load(name).description.split()[:3] == text.split()[:3]
    assert main(["presets"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == len(desc)
    for line in lines:
        name, text = line.split(None, 1)
        assert text == desc[name]


def _table(diverged=None, outcome=None):
    f = {"total_velocity_error": 1.0, "final_formation_error_m": 0.1, "max_abs_v_cmd": 1.0, "saturation_fraction": 0.0}
    methods = {}
    for m in ("backstepping", "bioinspired", "backstepping-learning", "bioinspired-learning"):
        fs = [dict(f, id=i + 1) for i in range(3)]
        if outcome and m == outcome[0]:
            fs[outcome[1]]["outcome"] = outcome[2]
        for ff in fs:
            ff.setdefault("outcome", "ok") if outcome else None
        methods[m] = {
            "followers": fs,
            "diverged": (
                {"message": "follower 2: speed 120 m/s", "time_s": 3.2, "step": 3200} if m == diverged else None
            ),
        }
    return {"plant": "mujoco", "scenario": "paper", "methods": methods, "ordering_holds": True}


def test_table1_marks_diverged_methods():
    from bioform_mj.jobs.table1 import markdown

    md = markdown(_table(diverged="backstepping"))
    rows = [line for line in md.splitlines() if line.startswith("| 1 |")]
    assert "1.00 (20.6) [diverged]" in rows[0] and "[diverged]" not in rows[0].split("|")[3]
    assert "backstepping diverged** at t = 3.2 s" in md and "not valid" in md
    assert "| backstepping [diverged] |" in md
    clean = markdown(_table())
    assert "diverged" not in clean and "Failed runs" not in clean


def test_table1_marks_failed_outcomes_and_handles_their_absence():
    from bioform_mj.jobs.table1 import markdown

    md = markdown(_table(outcome=("bioinspired", 1, "tipped")))
    row2 = next(line for line in md.splitlines() if line.startswith("| 2 |"))
    assert "[tipped]" in row2 and md.count("[tipped]") == 2  # Table I cell and the formation-error cell
    assert "follower 2 tipped" in md
    assert "[ok]" not in md
    assert not [line for line in markdown(_table()).splitlines() if line.startswith("|") and "[" in line]


def test_sigterm_stops_table1_after_the_method_in_progress(tmp_path):
    """simulate() returns the run so far on SIGTERM; table1 must not go on to the next method."""
    out = tmp_path / "t"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "bioform_mj.cli",
            "table1",
            "--duration",
            "400",
            "--set",
            "sim.log_dt=0.05",
            "--out",
            str(out),
        ],
        env=ENV,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        lines = []
        while proc.poll() is None:
            line = proc.stderr.readline()
            lines.append(line)
            if "backstepping: done" in line:
                break
        assert proc.poll() is None, "".join(lines)
        time.sleep(0.3)  # into the second method
        t0 = time.time()
        proc.send_signal(signal.SIGTERM)
        rc = proc.wait(timeout=60)
        stopped_in = time.time() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
    err = "".join(lines) + proc.stderr.read()
    assert rc == 143, err
    assert "interrupted by SIGTERM" in err and "no table written" in err and "Traceback" not in err
    assert "bioinspired-learning: done" not in err and stopped_in < 5
    assert not out.exists()

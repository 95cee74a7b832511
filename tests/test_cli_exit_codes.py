"""Issue 19, items 4-7 as tests (design §17): exit codes through closed pipes and full disks, the
Python API's failures, the MuJoCo distributions, and the minor silent cases."""

from __future__ import annotations

import errno
import json
import os
import re
import resource
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import bioform_mj
from bioform_mj.cli.main import main
from bioform_mj.core.errors import ControllerError, WriteFailed
from bioform_mj.run.simulate import simulate
from bioform_mj.scenario.loader import load

SRC = str(Path(bioform_mj.__file__).resolve().parents[1])
CLI = f"{sys.executable} -m bioform_mj.cli"


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": SRC, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}


def _bash(script: str, cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", "-c", script], cwd=cwd, env=_env(), capture_output=True, text=True, timeout=timeout)


def _tmp_files(folder: Path) -> list[Path]:
    return [p for p in folder.rglob(".*.tmp")] if folder.exists() else []


# ----------------------------------------------------------------------------------- pipes
# `| true` closes the pipe at once (the reader is gone before the interpreter has started), so
# every write of the command meets a closed pipe; `| head -1` is the battery's own form.


def test_closed_pipe_keeps_a_diverged_runs_exit_code_and_log(tmp_path):
    r = _bash(
        f"{CLI} run --set limits.speed=0.5 --duration 3 --out div 2>&1 | true; echo ${{PIPESTATUS[0]}}\n"
        f"{CLI} run --set limits.speed=0.5 --duration 3 --out div2 2>&1 | head -1 >/dev/null; echo ${{PIPESTATUS[0]}}",
        tmp_path,
    )
    assert r.stdout.split() == ["3", "3"], r.stdout + r.stderr  # was 0 through `| true`
    for d in ("div", "div2"):
        s = json.loads((tmp_path / d / "summary.json").read_text())
        assert s["diverged"]["time_s"] < 3 and (tmp_path / d / "log.npz").is_file()


def test_closed_pipe_before_the_run_still_writes_its_files(tmp_path):
    """tb3 in the paper scenario prints robot warnings on stderr before the run: with the pipe
    closed, the run used to end there (BrokenPipeError, exit 0, nothing written)."""
    r = _bash(
        f"{CLI} run --plant mujoco --set 'plant.robots=[\"tb3\"]' --duration 0.1 --out w 2>&1 | true; "
        "echo ${PIPESTATUS[0]}",
        tmp_path,
    )
    assert r.stdout.split() == ["0"], r.stdout + r.stderr
    s = json.loads((tmp_path / "w" / "summary.json").read_text())
    assert s["sim_time_s"] == pytest.approx(0.1) and s["feasibility_warnings"]
    assert (tmp_path / "w" / "log.npz").is_file() and not _tmp_files(tmp_path / "w")


def test_closed_or_full_standard_streams_keep_the_exit_code(tmp_path):
    """stdout closed (`>&-`: Python's sys.stdout is None), both closed, stdout on a full device
    (/dev/full: ENOSPC on the flush, said on stderr as a warning); the runs' codes and files stay."""
    r = _bash(
        f"{CLI} run --duration 0.5 --out a >&-; echo $?; "
        f"{CLI} run --duration 0.5 --set limits.speed=0.5 --out b >&- 2>&-; echo $?; "
        f"{CLI} run --duration 0.5 --out c >/dev/full 2>c.err; echo $?",
        tmp_path,
    )
    assert r.stdout.split() == ["0", "3", "0"], r.stdout + r.stderr
    for d in "abc":
        assert (tmp_path / d / "summary.json").is_file() and (tmp_path / d / "log.npz").is_file()
    err = (tmp_path / "c.err").read_text().strip().splitlines()
    assert err == ["warning: stdout could not be written (No space left on device); its output was dropped"]


class _Closed:
    """A stream whose reader has gone: every write and flush raises BrokenPipeError."""

    def __init__(self) -> None:
        self.tries = 0

    def write(self, text: str) -> int:
        self.tries += 1
        raise BrokenPipeError(errno.EPIPE, "Broken pipe")

    def flush(self) -> None:
        raise BrokenPipeError(errno.EPIPE, "Broken pipe")

    def isatty(self) -> bool:
        return False


@pytest.mark.parametrize("diverge,code", [(False, 0), (True, 3)])
def test_broken_stdout_and_stderr_in_process(tmp_path, monkeypatch, diverge, code):
    out, err = _Closed(), _Closed()
    monkeypatch.setattr(sys, "stdout", out)
    monkeypatch.setattr(sys, "stderr", err)
    argv = ["run", "--duration", "1", "--out", str(tmp_path / "r")] + (["--set", "limits.speed=0.5"] if diverge else [])
    assert main(argv) == code
    assert (tmp_path / "r" / "summary.json").is_file() and (tmp_path / "r" / "log.npz").is_file()
    assert (
        out.tries <= 1 and err.tries <= 1 and out.tries + err.tries >= 1
    )  # per stream: one failed write, then silence
    assert sys.stdout is out and sys.stderr is err  # main restored the streams


# ------------------------------------------------------------------------- full disks, limits
def _fsize_limit(nbytes: int):
    def pre() -> None:  # the interpreter ignores SIGXFSZ itself: the write fails with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, nbytes))

    return pre


@pytest.mark.parametrize("limit,name", [(20 * 1024, "log.npz"), (0, ".bioform.lock")])
def test_file_size_limit_mid_run_is_an_error_line_naming_the_file(tmp_path, limit, name):
    """`ulimit -f 20` (20 KiB): log.npz of a 5 s run (~60 KiB) cannot be written; `ulimit -f 0`:
    not even the folder's lock (its pid) can."""
    r = subprocess.run(
        [sys.executable, "-m", "bioform_mj.cli", "run", "--duration", "5", "--out", "big", "--quiet"],
        cwd=tmp_path,
        env=_env(),
        capture_output=True,
        text=True,
        preexec_fn=_fsize_limit(limit),
        timeout=300,
    )
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 1, r.stderr
    assert len(lines) == 1 and lines[0].startswith(f"error: cannot write 'big/{name}'"), r.stderr
    assert "File too large" in lines[0] and "nothing kept" in lines[0]
    assert "internal error" not in r.stderr and "Traceback" not in r.stderr
    assert not _tmp_files(tmp_path)


def test_file_size_limit_mid_sweep_keeps_the_rows_and_says_so(tmp_path):
    """A limit between the size of a row file and of stats.json: the three rows are written, then
    the tables fail; the error names the table and the rows kept (a rerun resumes them)."""
    args = [sys.executable, "-m", "bioform_mj.cli", "sweep", "--duration", "0.3", "--workers", "1", "--quiet"]
    args += ["--vary", "kinematic.k1=1,2,3"]
    free = subprocess.run(args + ["--out", "free"], cwd=tmp_path, env=_env(), capture_output=True, timeout=300)
    assert free.returncode == 0, free.stderr
    rows = max(p.stat().st_size for p in (tmp_path / "free" / "runs").glob("*.json"))
    biggest = max(p.stat().st_size for p in (tmp_path / "free").glob("*.*"))
    limit = (rows + biggest) // 2
    assert rows < limit < biggest
    r = subprocess.run(
        args + ["--out", "lim"],
        cwd=tmp_path,
        env=_env(),
        capture_output=True,
        text=True,
        preexec_fn=_fsize_limit(limit),
        timeout=300,
    )
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 1 and len(lines) == 1, r.stderr
    assert lines[0].startswith("error: cannot write 'lim/") and "File too large" in lines[0]
    assert "3 finished row(s) kept in lim/runs/" in lines[0] and "resume" in lines[0]
    assert len(list((tmp_path / "lim" / "runs").glob("*.json"))) == 3
    assert "internal error" not in r.stderr and not _tmp_files(tmp_path / "lim")


@pytest.mark.parametrize(
    "target,code,what",
    [("summary.json", errno.EROFS, "Read-only file system"), ("log.npz", errno.ENOSPC, "No space left on device")],
)
def test_read_only_or_full_disk_mid_run(tmp_path, monkeypatch, capsys, target, code, what):
    """A read-only folder and a full disk, simulated at the rename (tests run as root here, which
    chmod cannot stop; a real limit is the ulimit test above). log.npz is written before
    summary.json, so a failing summary keeps the log."""
    import bioform_mj.outputs.files as files

    real = os.replace

    def replace(src, dst):
        if Path(dst).name == target:
            raise OSError(code, os.strerror(code), str(src))
        return real(src, dst)

    monkeypatch.setattr(files.os, "replace", replace)
    out = tmp_path / "r"
    assert main(["run", "--duration", "0.5", "--out", str(out), "--quiet"]) == 1
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: cannot write '{out / target}': {what}"), lines
    kept = "kept in" if target == "summary.json" else "nothing kept"
    assert kept in lines[0] and ("log.npz" in lines[0].split(";")[1]) == (target == "summary.json")
    assert not (out / target).exists() and not _tmp_files(tmp_path)


def test_write_failed_is_an_oserror_naming_the_path():
    e = WriteFailed("a/b.json", OSError(errno.ENOSPC, "No space left on device"))
    assert isinstance(e, OSError) and e.errno == errno.ENOSPC and e.path == "a/b.json"
    assert str(e) == "cannot write 'a/b.json': No space left on device"


# ------------------------------------------------------------------------------ Python API
SC = load("paper", ["sim.duration=1"], plant="ideal")  # log_dt 0.01 s, control_dt 1 ms


class Wrapped:
    """The paper's stack, spoiled after ``k_bad`` steps: NaN for follower 2, a raise, a wrong shape."""

    def __init__(self, mode: str, k_bad: int = 50) -> None:
        from bioform_mj.control.params import stack_params
        from bioform_mj.control.stack import ControlStack

        self.inner = ControlStack(SC.build_graph(), stack_params(SC, np.array(SC.plant.c_true)))
        self.n, self.k, self.k_bad, self.mode = SC.n, 0, k_bad, mode

    def reset(self, est_pose0, vel0):
        self.inner.reset(est_pose0, vel0)

    def step(self, *a):
        tau = self.inner.step(*a)
        self.k += 1
        if self.k > self.k_bad:
            if self.mode == "nan":
                tau = tau.copy()
                tau[1, 0] = np.nan
            elif self.mode == "raise":
                raise ValueError("boom")
            elif self.mode == "shape":
                return tau[:2]
        return tau

    def signals(self):
        return self.inner.signals()


def test_nonfinite_torques_name_the_controller_in_the_outcome():
    r = simulate(SC, controller=Wrapped("nan"))
    assert r.diverged is not None and r.summary["diverged"]["step"] == 50
    assert "Wrapped.step" in str(r.diverged) and "follower 2" in str(r.diverged)
    f = r.summary["followers"]
    assert [x["outcome"] for x in f] == ["ok", "controller_nonfinite", "ok"]
    assert "Wrapped.step" in f[1]["outcome_detail"] and "t = 0.0500 s" in f[1]["outcome_detail"]
    assert f[1]["outcomes"][0] == {"kind": "controller_nonfinite", "detail": f[1]["outcome_detail"], "t": 0.05}
    assert len(r.log["t"]) == 5 and r.log["t"][-1] == pytest.approx(0.04)  # rows up to the last good step
    assert np.all(np.isfinite(r.log["tau"]))


@pytest.mark.parametrize("mode,exc", [("raise", ValueError), ("shape", ControllerError)])
def test_a_controller_that_fails_mid_run_keeps_the_log_and_is_named(mode, exc):
    with pytest.raises(exc) as info:
        simulate(SC, controller=Wrapped(mode))
    e = info.value
    notes = " ".join(getattr(e, "__notes__", []))
    assert "controller Wrapped.step" in notes and "t = 0.0500 s" in notes and ".result" in notes
    assert len(e.result.log["t"]) == 5 and e.result.summary["raised"]["by"] == "controller Wrapped.step"
    assert e.result.summary["raised"]["step"] == 50 and e.result.summary["steps"] == 50
    if mode == "shape":
        assert "(2, 2)" in str(e) and "(n, 2) = (3, 2)" in str(e) and "Wrapped.step" in str(e)


def test_an_observer_that_raises_mid_run_keeps_the_log():
    finished = []

    class Probe:
        period = 0.1

        def start(self, run):
            pass

        def sample(self, run):
            if run.t > 0.55:
                raise RuntimeError("disk gone")

        def finish(self, run):
            finished.append(run.t)

    class Other(Probe):
        def sample(self, run):
            pass

    with pytest.raises(RuntimeError, match="disk gone") as info:
        simulate(SC, observers=[Probe(), Other()])
    e = info.value
    assert "observer Probe.sample" in " ".join(e.__notes__)
    assert e.result.summary["raised"]["time_s"] == pytest.approx(0.6)
    assert len(e.result.log["t"]) == 61  # rows 0 .. 0.6 s: the row of step 600 was logged before the sample
    assert finished == [pytest.approx(0.6)]  # the other observer finished, the failing one not


@pytest.mark.parametrize("missing", ["reset", "step", "signals"])
def test_a_missing_protocol_method_is_named_before_any_step(missing):
    calls = []

    class Partial:
        n = 3

        def reset(self, est_pose0, vel0):
            calls.append("reset")

        def step(self, *a):
            calls.append("step")
            return np.zeros((3, 2))

        def signals(self):
            return {}

    setattr(Partial, missing, None)
    with pytest.raises(ControllerError, match=rf"controller Partial has no {missing}\(\) method"):
        simulate(SC, controller=Partial())
    assert calls == []


def test_an_observer_without_a_period_is_refused_before_any_step():
    class NoPeriod:
        def start(self, run): ...
        def sample(self, run): ...
        def finish(self, run): ...

    with pytest.raises(ControllerError, match="observer NoPeriod: period"):
        simulate(SC, observers=[NoPeriod()])


# ---------------------------------------------------------------------------- dependencies
def test_installed_mujoco_distributions_are_one_release():
    from importlib import metadata

    from bioform_mj.core.deps import MUJOCO_RELEASE, installed_versions, mujoco_distribution_problem

    v = installed_versions()
    assert mujoco_distribution_problem() is None, v
    assert v["mujoco"] == MUJOCO_RELEASE
    if "mujoco-core" in v:
        assert v["mujoco-core"] == v["mujoco"]
    import mujoco

    assert mujoco.__version__ == v["mujoco"]  # the package imported is the one the metadata names
    assert metadata.version("mujoco") == mujoco.__version__


def test_mixed_mujoco_releases_are_refused_with_the_fix(monkeypatch, capsys):
    from bioform_mj.core import deps

    msg = deps.mujoco_distribution_problem({"mujoco": "3.17.0", "mujoco-core": "4.0.1"})
    assert "mujoco 3.17.0, mujoco-core 4.0.1" in msg and "pip uninstall -y mujoco mujoco-core" in msg
    assert f"pip install 'mujoco=={deps.MUJOCO_RELEASE}'" in msg
    assert (
        deps.mujoco_distribution_problem({"mujoco": "4.0.0", "mujoco-core": "4.0.0", "mujoco-studio": "4.0.0"}) is None
    )
    assert deps.mujoco_distribution_problem({"mujoco": "3.17.0"}) is None
    monkeypatch.setattr(deps, "installed_versions", lambda: {"mujoco": "3.17.0", "mujoco-core": "4.0.1"})
    assert main(["presets"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: the installed MuJoCo is inconsistent")


def test_pyproject_pins_the_mujoco_metapackage_not_mujoco_core():
    import tomllib

    root = Path(SRC).parent
    deps = tomllib.loads((root / "pyproject.toml").read_text())["project"]
    core = deps["dependencies"]
    assert "mujoco==4.0.0" in core and not any(d.startswith("mujoco-core") for d in core)
    assert all(not d.startswith("mujoco-core") for d in deps["optional-dependencies"]["gpu"])


def _composed(robots: list[str]):
    from bioform_mj.robots.entries import resolve_robot
    from bioform_mj.robots.scene import build_scene, compile_scene

    n = len(robots)
    poses = np.column_stack([np.arange(n) * 1.5, np.zeros(n), np.zeros(n)])
    spec = build_scene([resolve_robot(r) for r in robots], poses, slots=False)
    return compile_scene(spec)[0]


@pytest.mark.parametrize("robots", [["paper"] * 8, ["paper", "tb3", "stretch", "lab"] * 2])
def test_sparse_newton_path_of_mujoco_4_0_0_matches_dense_on_our_scenes(robots):
    """MuJoCo 4.0.0's sparse Cholesky merged rows with different descendants into one supernode:
    the Newton solver got a wrong Hessian factor when the constraint Jacobian is sparse (fixed in
    4.0.1, commit 9ae9bad, issue #3767). Our scenes take that path from nv >= 60 (8 robots:
    jacobian "auto" is sparse there). A wrong factor shows as other accelerations or more solver
    iterations than the dense path (which has no supernodes): over 600 steps of driven, turning
    robots both agree to 1e-9 m/s² with the same iteration counts (measured: 1e-11, equal)."""
    import mujoco

    m = _composed(robots)
    assert m.opt.solver == mujoco.mjtSolver.mjSOL_NEWTON and m.opt.jacobian == mujoco.mjtJacobian.mjJAC_AUTO
    assert m.nv >= 60 and mujoco.mj_isSparse(m)  # the affected path
    rng = np.random.default_rng(1)
    ctrls = rng.uniform(-0.3, 0.3, (6, m.nu))
    runs = {}
    for jac in (mujoco.mjtJacobian.mjJAC_DENSE, mujoco.mjtJacobian.mjJAC_SPARSE):
        m.opt.jacobian = jac
        d = mujoco.MjData(m)
        qacc, iters = [], []
        for k in range(600):
            d.ctrl[:] = ctrls[k // 100]
            mujoco.mj_step(m, d)
            qacc.append(d.qacc.copy())
            iters.append(int(d.solver_niter[0]))
        runs[int(jac)] = (np.array(qacc), np.array(iters), d.nefc)
    (qa_d, it_d, nefc), (qa_s, it_s, _) = (
        runs[int(mujoco.mjtJacobian.mjJAC_DENSE)],
        runs[int(mujoco.mjtJacobian.mjJAC_SPARSE)],
    )
    assert nefc > 0  # wheels and casters in contact: the solver works
    scale = max(1.0, float(np.abs(qa_d).max()))
    assert np.abs(qa_s - qa_d).max() <= 1e-9 * scale
    assert np.array_equal(it_s, it_d)


def test_reading_video_needs_no_vsync(tmp_path, monkeypatch):
    """ffmpeg 9 (bundled by imageio-ffmpeg 0.8) removed -vsync, which mediapy 1.2.7's reader
    passes: read_video must not go through mediapy."""
    import mediapy

    from bioform_mj.outputs.video import read_video, set_ffmpeg

    def refuse(*a, **k):
        raise AssertionError("mediapy's reader (-vsync) was used")

    monkeypatch.setattr(mediapy, "read_video", refuse)
    monkeypatch.setattr(mediapy, "VideoReader", refuse)
    set_ffmpeg()
    frames = np.zeros((5, 32, 48, 3), np.uint8)
    for k in range(5):
        frames[k, :, : 8 * (k + 1)] = (200, 40, 40)
    path = tmp_path / "v.mp4"
    with mediapy.VideoWriter(path, shape=(32, 48), fps=10, codec="h264", crf=0) as w:
        for f in frames:
            w.add_image(f)
    got = read_video(path)
    assert got.shape == (5, 32, 48, 3) and got.dtype == np.uint8
    assert np.abs(got.astype(int) - frames.astype(int)).mean() < 6  # lossless-ish h264 (crf 0), yuv420


# --------------------------------------------------------------------------- minor silent cases
def _one_error(capsys) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:"), lines
    return lines[0]


@pytest.mark.parametrize(
    "override,needle",
    [
        ('plant.robots=[{model="paper", driver="voltage"}]', "driver = 'voltage' applies only with motor = \"dc\""),
        ('plant.robots=[{model="paper", motor="ideal", driver="current"}]', "applies only with motor"),
        ('plant.robots=[{model="paper", tau_max=inf}]', "plant.robots[0].tau_max': expected a finite number"),
        ('plant.robots=[{model="paper", wheel_radius=nan}]', "wheel_radius': expected a finite number"),
        ('events=[{kind="payload", follower=1, time=2.0, mass=1.0}]', "never be applied; use a time <= 1.999 s"),
        ('events=[{kind="payload", follower=1, time=1.9995, mass=1.0}]', "events[0].time"),
    ],
)
def test_silent_cases_are_refused(tmp_path, capsys, override, needle):
    out = tmp_path / "never"
    assert main(["run", "--plant", "mujoco", "--duration", "2", "--set", override, "--out", str(out)]) == 2
    assert needle in _one_error(capsys)
    assert not out.exists()


def test_an_event_at_the_last_control_step_is_applied():
    sc = load("paper", ["sim.duration=0.5", 'events=[{kind="payload", follower=1, time=0.499, mass=5.0, inertia=0.1}]'])
    r = simulate(sc)
    assert r.summary["followers"][0]["c_true"] != r.summary["followers"][1]["c_true"]  # the payload changed c


def test_vary_values_in_quotes_are_labelled_without_them():
    from bioform_mj.core.errors import InputError
    from bioform_mj.jobs.sweep import expand, unquote

    specs = expand(
        "paper", 1, ["bioinspired"], ["estimator.init='zero',\"self\"", "kinematic.k1=2"], ["sim.duration=0.1"]
    )
    assert [sp.vary for sp in specs] == [
        (("estimator.init", "zero"), ("kinematic.k1", "2")),
        (("estimator.init", "self"), ("kinematic.k1", "2")),
    ]
    assert [sp.scenario.estimator.init for sp in specs] == ["zero", "self"]
    assert unquote("\"a'") == "\"a'" and unquote('"') == '"' and unquote(" 'x' ") == "x"
    with pytest.raises(InputError, match="methods come from --methods"):  # was overridden by --methods, silently
        expand("paper", 1, ["bioinspired"], ['method="backstepping"'], ["sim.duration=0.1"])


def test_figures_of_a_one_step_run_print_no_matplotlib_warning(tmp_path):
    from bioform_mj.outputs.figures import run_figures

    r = simulate(load("paper", ["sim.duration=0.001"]))
    assert len(r.log["t"]) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        figs = run_figures(r, tmp_path / "figures")
    assert len(figs) >= 6 and all(p.stat().st_size > 1000 for p in figs)


def test_base_world_names_the_file(capsys):
    assert main(["robot", "check", "paper", "--base", "world"]) == 2
    line = _one_error(capsys)
    assert "paper_robot.xml" in line and "world body" in line


def test_warp_is_silenced():
    wp = pytest.importorskip("warp")
    from bioform_mj.batch.backend import quiet_warp

    old = wp.config.log_level
    try:
        wp.config.log_level = wp.LOG_INFO
        quiet_warp()
        assert wp.config.log_level >= wp.LOG_WARNING  # no greeting, no "Module ... load" lines
    finally:
        wp.config.log_level = old


def test_cli_run_whose_observer_raises_keeps_the_log_and_names_it(tmp_path, monkeypatch, capsys):
    """An observer of the CLI (video capture, live viewer) that raises mid-run: the log so far is
    written and the error line names the observer and the time (exit 1, not an internal error)."""
    import bioform_mj.run.simulate as sim

    real = sim.simulate

    class Flaky:
        period = 0.1

        def start(self, run): ...
        def sample(self, run):
            if run.t > 0.25:
                raise OSError("viewer gone")

        def finish(self, run): ...

    monkeypatch.setattr(sim, "simulate", lambda sc, observers=(), **kw: real(sc, [*observers, Flaky()], **kw))
    out = tmp_path / "r"
    assert main(["run", "--duration", "1", "--out", str(out), "--quiet"]) == 1
    line = _one_error(capsys)
    assert "observer Flaky.sample raised OSError: viewer gone" in line and "t = 0.3 s" in line and str(out) in line
    s = json.loads((out / "summary.json").read_text())
    assert s["raised"]["by"] == "observer Flaky.sample" and s["sim_time_s"] == pytest.approx(0.3)
    with np.load(out / "log.npz") as z:
        assert len(z["t"]) == 31


def test_building_a_scene_checks_the_mujoco_distributions(monkeypatch):
    """The Python API's startup check: compile_scene refuses a mixed installation (once per process)."""
    from bioform_mj.core import deps
    from bioform_mj.core.errors import InputError

    monkeypatch.setattr(deps, "installed_versions", lambda: {"mujoco": "3.17.0", "mujoco-core": "4.0.1"})
    deps.check_mujoco_once.cache_clear()
    try:
        with pytest.raises(InputError, match="installed MuJoCo is inconsistent"):
            _composed(["paper"])
    finally:
        monkeypatch.undo()
        deps.check_mujoco_once.cache_clear()
    assert _composed(["paper"]).nv == 8  # and a consistent one builds (nv = 6 free + 2 wheels)


def test_a_controller_without_set_tau_max_under_known_actuator_faults_is_refused_before_any_step():
    sc = load("paper", ["sim.duration=0.5", "faults.actuator=[[1, 0.1, 0.3, 0.5]]", "faults.actuator_known=true"])
    stepped = []

    class NoLimit(Wrapped):
        def step(self, *a):
            stepped.append(1)
            return super().step(*a)

    ctrl = NoLimit("none")
    with pytest.raises(ControllerError, match="NoLimit has no set_tau_max"):
        simulate(sc, controller=ctrl)
    assert stepped == []
    ok = load("paper", ["sim.duration=0.5", "faults.actuator=[[1, 0.1, 0.3, 0.5]]", "faults.actuator_known=false"])
    r = simulate(ok, controller=NoLimit("none"))  # not told: set_tau_max is never called
    assert r.diverged is None and r.summary["steps"] == 500


def test_a_sweep_of_many_configurations_says_how_long_checking_them_takes(capsys, monkeypatch):
    """Each configuration of a sweep is loaded and checked before any run (~15 ms each): from
    10 x ``CHECK_SAMPLE`` configurations on, one note says how many and how long the rest take, measured on the
    first ``CHECK_SAMPLE`` (trust4: 15,000 values were checked for minutes in silence); below that, no note."""
    import time

    from bioform_mj.jobs import sweep as sweep_module

    monkeypatch.setattr(sweep_module, "CHECK_SAMPLE", 2)
    vary = ["kinematic.k1=" + ",".join(str(1 + i / 100) for i in range(20))]
    t0 = time.monotonic()
    specs = sweep_module.expand("paper", 1, ["bioinspired"], vary, plant="ideal")
    spent = time.monotonic() - t0
    notes = [line for line in capsys.readouterr().err.splitlines() if line.startswith("note: checking")]
    assert len(specs) == 20 and len(notes) == 1, notes
    m = re.fullmatch(
        r"note: checking 20 configurations before any run: about ([0-9.]+) s more \(measured on the first 2\)", notes[0]
    )
    assert m and 0.0 < float(m.group(1)) < 10 * spent, (notes, spent)
    sweep_module.expand("paper", 1, ["bioinspired"], [vary[0].rsplit(",", 1)[0]], plant="ideal")  # 19: silent
    assert "note: checking" not in capsys.readouterr().err

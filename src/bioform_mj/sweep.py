"""Monte Carlo sweeps: every combination of methods × varied keys × seeds, on forked workers or Ray.

Each run is identified by a key hashed from the *content* of its resolved scenario
(``Scenario.to_dict()`` as canonical JSON, the overrides, the robot model files it uses
and the package version), not from the scenario's file path: an edited scenario runs
again. Its result row is written atomically to ``DIR/runs/<key>.json`` as soon as it
finishes, so an interrupted sweep resumes by skipping keys already there; a row file that
cannot be read is reported (``warning:`` on stderr) and its run redone. At the end the rows
are collected into ``DIR/runs.csv`` (one row per run: settings, seed, status, outcome,
metrics) and aggregated per group, method × every ``--vary`` value, into ``DIR/stats.json``
and ``DIR/stats.md``.

Processes (``backend="local"``): with more than one worker, every run is a process forked
from this one after it has loaded the compiled kernels, so a worker starts in milliseconds
with the kernels in memory. A worker that dies (SIGKILL, the OOM killer) fails only its
own row (``status = failed``, the reason in ``error``, ``worker_died = true``; a resume runs
it again) and the sweep goes on. SIGINT/SIGTERM stop the sweep: running workers are
terminated (SIGTERM, then SIGKILL after a grace period; they also die with the sweep via
``PR_SET_PDEATHSIG`` if it is killed), finished rows are kept, the tables are written for
them and :class:`SweepInterrupted` is raised. One worker (and, off Linux, every sweep) runs in
this process, where a signal abandons the run in progress.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import hashlib
import io
import itertools
import json
import os
import select
import signal
import sys
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from .errors import BioformError, InputError
from .outputs.files import write_json, write_text
from .scenario import Scenario, load

#: Per-follower metrics of ``summary.json`` that a sweep row carries (mean and max over followers).
METRICS = (
    "total_velocity_error",
    "final_formation_error_m",
    "rms_formation_error_m",
    "final_estimation_error_m",
    "max_abs_v_cmd",
    "peak_abs_torque",
    "saturation_fraction",
)

#: Seconds a terminated worker gets to exit before it is killed.
GRACE_S = 2.0


class SweepInterrupted(BioformError):
    """SIGINT/SIGTERM stopped the sweep; finished rows are kept (``done`` of ``total``)."""

    def __init__(self, signum: int, done: int, total: int) -> None:
        self.signum, self.done, self.total = signum, done, total
        super().__init__(f"interrupted ({signal.Signals(signum).name}): {done} of {total} runs done")


@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep: scenario source, overrides (``KEY=VALUE`` strings), method, seed.

    :func:`expand` also sets ``scenario`` (the resolved scenario the run uses) and ``digest``
    (its content hash, the run's key); a spec made without them loads its scenario when it
    runs and is keyed by its settings.
    """

    source: str
    overrides: tuple[str, ...]
    method: str
    seed: int
    plant: str | None
    vary: tuple[tuple[str, str], ...]  # the varied (key, raw value) pairs, for the table
    digest: str = ""
    scenario: Scenario | None = field(default=None, compare=False, hash=False, repr=False)

    @property
    def key(self) -> str:
        """Stable identifier of the run, used as file name: the content hash when known."""
        if self.digest:
            return self.digest
        text = json.dumps([self.source, self.overrides, self.method, self.seed, self.plant], sort_keys=True)
        return hashlib.sha1(text.encode()).hexdigest()[:16]


def content_key(sc: Scenario, overrides: Sequence[str] = ()) -> str:
    """Hash of what a run computes: the resolved scenario, the overrides, robot model files, package version."""
    models: dict[str, str] = {}
    if sc.plant.kind == "mujoco":
        from .robots import resolve_robot

        for r in sc.plant.robots:
            with contextlib.suppress(BioformError, OSError):
                path = resolve_robot(r).model  # a RobotRef (model file + mapping; the mapping is in to_dict)
                models[path] = hashlib.sha1(Path(path).read_bytes()).hexdigest()
    doc = {"scenario": sc.to_dict(), "overrides": list(overrides), "models": models, "version": __version__}
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"), default=repr)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def randomness(sc: Scenario) -> list[str]:
    """The scenario keys through which ``sim.seed`` changes a run (empty: every seed gives the same run).

    The seed draws the initial-pose jitter and, inside the fault window, sensor noise and packet loss.
    """
    out = []
    if sc.formation.init_jitter > 0:
        out.append("formation.init_jitter")
    f = sc.faults
    w0, w1 = f.window if f.window else (-np.inf, np.inf)
    if w0 < min(w1, sc.sim.duration):  # the noise/loss window overlaps the run
        if f.packet_loss > 0:
            out.append("faults.packet_loss")
        if any(v > 0 for v in f.noise_pose):
            out.append("faults.noise_pose")
        if any(v > 0 for v in f.noise_vel):
            out.append("faults.noise_vel")
    return out


def _warn(msg: str) -> None:
    print(f"warning: {msg}", file=sys.stderr, flush=True)


def expand(
    source: str,
    seeds: int,
    methods: Sequence[str],
    vary: Sequence[str],
    overrides: Sequence[str] = (),
    plant: str | None = None,
    seed0: int = 0,
    warn: Callable[[str], None] | None = _warn,
) -> list[RunSpec]:
    """All combinations; ``vary`` items are ``KEY=V1,V2,...`` (values as in ``--set``).

    Arrays in a value list must not contain commas at the top level; use ``;`` to
    separate array values instead (``estimator.phi=[0,0];[0.1,0.1]``). Every configuration
    is loaded and validated here, so bad input fails before any run starts. ``warn`` is
    told when ``seeds > 1`` is asked of configurations that have no randomness.
    """
    if seeds < 1:
        raise InputError(f"--seeds must be >= 1, got {seeds}")
    axes: list[list[tuple[str, str]]] = []
    for item in vary:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip() or not raw.strip():
            raise InputError(f"--vary '{item}': expected KEY=V1,V2,... e.g. kinematic.k1=1,2,3")
        values = raw.split(";") if ";" in raw else raw.split(",")
        axes.append([(key.strip(), v.strip()) for v in values])
    specs = []
    no_random: list[str] = []
    n_configs = 0
    for method in methods:
        for combo in itertools.product(*axes) if axes else [()]:
            ov = tuple(overrides) + tuple(f"{k}={v}" for k, v in combo)
            base = load(source, list(ov) + [f"sim.seed={seed0}"], method=method, plant=plant)
            n_configs += 1
            if not randomness(base):
                no_random.append(", ".join([method] + [f"{k}={v}" for k, v in combo]))
            for s in range(seed0, seed0 + seeds):
                # the seed is the only difference between a configuration's runs (seed0 was validated)
                sc = dataclasses.replace(base, sim=dataclasses.replace(base.sim, seed=s))
                run_ov = ov + (f"sim.seed={s}",)
                specs.append(RunSpec(source, run_ov, method, s, plant, tuple(combo), content_key(sc, run_ov), sc))
    if seeds > 1 and no_random and warn is not None:
        if len(no_random) == n_configs:
            which, its = "the scenario has", "its"
        else:
            more = "; …" if len(no_random) > 3 else ""
            which = f"{len(no_random)} of {n_configs} configurations ({'; '.join(no_random[:3])}{more}) have"
            its = "their"
        warn(
            f"--seeds {seeds}: {which} no randomness (no formation.init_jitter, faults.noise_pose/noise_vel "
            f"or faults.packet_loss), so {its} {seeds} seeds give identical runs"
        )
    return specs


# ------------------------------------------------------------------------------------------
# One run


def _base_row(spec: RunSpec) -> dict[str, Any]:
    row: dict[str, Any] = {"key": spec.key, "method": spec.method, "seed": spec.seed}
    row.update({k: v for k, v in spec.vary})
    return row


def run_one(spec: RunSpec) -> dict[str, Any]:
    """Run one spec; never raises: a failure becomes a row with ``status = failed`` and the error."""
    row = _base_row(spec)
    try:
        from .sim import simulate

        sc = (
            spec.scenario
            if spec.scenario is not None
            else load(spec.source, list(spec.overrides), method=spec.method, plant=spec.plant)
        )
        res = simulate(sc)
        s = res.summary
        row["plant"] = s["plant"]
        div = s.get("diverged")
        row["status"] = "diverged" if div is not None else "ok"
        row["error"] = div["message"] if div is not None else ""
        row["diverged_at_s"] = div["time_s"] if div is not None else None
        fo = [f.get("outcome") for f in s["followers"]]
        if all(o is not None for o in fo):
            row["follower_outcomes"] = ";".join(str(o) for o in fo)
        bad = sorted({str(o) for o in fo if o is not None and o != "ok"})
        row["outcome"] = "diverged" if div is not None else (",".join(bad) if bad else "ok")
        row["sim_time_s"] = s["sim_time_s"]
        row["wall_time_s"] = s["wall_time_s"]
        for m in METRICS:
            vals = np.array([f[m] for f in s["followers"]], dtype=float)
            row[f"{m}_mean"] = float(np.mean(vals))
            row[f"{m}_max"] = float(np.max(vals))
        ch = np.array([f["c_hat_rel_error"] for f in s["followers"]], dtype=float)
        row["c_hat_abs_rel_error_max"] = float(np.max(np.abs(ch)))
        _contact_columns(row, s["followers"])
    except Exception as exc:  # noqa: BLE001 - a failed run must not sink the sweep
        row["status"] = "failed"
        row["outcome"] = "failed"
        row["error"] = f"{type(exc).__name__}: {exc}"
    return row


def _contact_columns(row: dict[str, Any], followers: list[dict[str, Any]]) -> None:
    """Design §19 (MuJoCo runs): ``min_separation_m`` (the least over followers; empty when no robot
    came within range), ``collisions`` (contact events with robots and obstacles, summed over
    followers: a robot–robot touch counts for both) and ``collided`` (followers that touched)."""
    if not followers or "robot_contacts" not in followers[0]:
        return
    seps = [f["min_separation_m"] for f in followers if f.get("min_separation_m") is not None]
    row["min_separation_m"] = float(min(seps)) if seps else None
    row["collisions"] = int(sum(f["robot_contacts"] + f["obstacle_contacts"] for f in followers))
    row["collided"] = int(sum(1 for f in followers if f["robot_contacts"] + f["obstacle_contacts"] > 0))


def _died_row(spec: RunSpec, reason: str) -> dict[str, Any]:
    """The row of a run whose worker process died; a resume runs it again."""
    row = _base_row(spec)
    row.update(status="failed", outcome="failed", error=f"worker died: {reason}", worker_died=True)
    return row


def _exit_reason(status: int) -> str:
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        try:
            name = signal.Signals(sig).name
        except ValueError:
            name = f"signal {sig}"
        hint = " (out of memory? the kernel's OOM killer sends SIGKILL)" if sig == signal.SIGKILL else ""
        return f"killed by {name}{hint}"
    return f"exited with code {os.waitstatus_to_exitcode(status)} without a result"


# ------------------------------------------------------------------------------------------
# Signals


class _Stop(BaseException):
    """Raised by the signal handler to abandon the in-process run (not an Exception: run_one lets it through)."""


class _Signals:
    """SIGINT/SIGTERM → ``signum`` set (first one wins); while ``raising``, also raise :class:`_Stop`."""

    def __init__(self) -> None:
        self.signum: int | None = None
        self.raising = False
        self._old: dict[int, Any] = {}

    def _handler(self, signum: int, frame: Any) -> None:
        if self.signum is None:
            self.signum = signum
        if self.raising:
            self.raising = False
            raise _Stop()

    def __enter__(self) -> _Signals:
        for s in (signal.SIGINT, signal.SIGTERM):
            try:
                self._old[s] = signal.signal(s, self._handler)
            except ValueError:  # not the main thread: leave signals to the caller
                break
        return self

    def reinstall(self) -> None:
        """Take the signals back from a library that installed its own handlers (ray.init does, for SIGTERM)."""
        for s in self._old:
            signal.signal(s, self._handler)

    def __exit__(self, *exc: Any) -> None:
        for s, h in self._old.items():
            signal.signal(s, h)


@contextlib.contextmanager
def _raising(sig: _Signals) -> Iterator[None]:
    """Let a signal abandon what runs inside (checked on entry too)."""
    if sig.signum is not None:
        raise _Stop()
    sig.raising = True
    try:
        yield
    finally:
        sig.raising = False


# ------------------------------------------------------------------------------------------
# Backends


def _load_kernels() -> None:
    """Run both compiled loops for a moment, so that numba's cached machine code is loaded
    in this process (and inherited by forked workers instead of loaded once per worker)."""
    from .scenario import load
    from .sim import simulate

    for plant in ("ideal", "mujoco"):
        simulate(load("paper", plant=plant, overrides=["sim.duration=0.01"]))


def _die_with_parent(parent: int) -> None:
    """In a worker: SIGKILL when the sweep process dies, however it dies (Linux)."""
    with contextlib.suppress(Exception):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    if os.getppid() != parent:  # the sweep died before prctl
        os._exit(1)


def _read_exact(fd: int, n: int) -> bytes | None:
    buf = b""
    while len(buf) < n:
        chunk = os.read(fd, n - len(buf))
        if not chunk:
            return None
        buf += chunk
    return buf


def _worker(todo: list[RunSpec], task_r: int, result_w: int, parent: int) -> None:
    """Body of a forked worker: read run indices (4 bytes each) from ``task_r`` until EOF, write each
    run's row to ``result_w`` as length-prefixed JSON. Never returns."""
    code = 1
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole process group; the sweep decides
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        _die_with_parent(parent)
        while True:
            msg = _read_exact(task_r, 4)
            if msg is None:
                break
            row = run_one(todo[int.from_bytes(msg, "little")])
            data = json.dumps(row, default=lambda o: o.item() if hasattr(o, "item") else str(o)).encode()
            out = len(data).to_bytes(8, "little") + data
            while out:
                out = out[os.write(result_w, out) :]
        code = 0
    except BaseException:  # noqa: BLE001 - report and exit; never run the parent's code
        with contextlib.suppress(Exception):
            traceback.print_exc()
    finally:
        os._exit(code)


def _run_serial(todo: list[RunSpec], sig: _Signals, done: Callable[[dict], None]) -> None:
    for sp in todo:
        try:
            with _raising(sig):
                row = run_one(sp)
        except _Stop:
            return
        done(row)


@dataclass
class _Proc:
    """A forked worker as the sweep sees it."""

    pid: int
    task_w: int
    result_r: int
    current: int | None = None  # index of the run it is doing
    buf: bytearray = field(default_factory=bytearray)


def _run_forked(todo: list[RunSpec], workers: int, sig: _Signals, done: Callable[[dict], None]) -> None:
    """Runs on ``workers`` processes forked from this one after it loaded the compiled kernels, one run at a
    time each; a worker that dies fails the run it was doing and is replaced."""
    _load_kernels()  # before forking: workers inherit the loaded kernels (start in ms, not ~1 s each)
    parent = os.getpid()
    queue = list(range(len(todo) - 1, -1, -1))  # popped from the end: todo order
    procs: dict[int, _Proc] = {}  # by result fd

    def start() -> None:
        task_r, task_w = os.pipe()
        result_r, result_w = os.pipe()
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:  # pragma: no cover - runs in the worker
            for fd in [task_w, result_r] + [fd for p in procs.values() for fd in (p.task_w, p.result_r)]:
                os.close(fd)
            _worker(todo, task_r, result_w, parent)
        os.close(task_r)
        os.close(result_w)
        procs[result_r] = _Proc(pid, task_w, result_r)

    def close_task(p: _Proc) -> None:
        """EOF on its task pipe: an idle worker exits."""
        if p.task_w >= 0:
            with contextlib.suppress(OSError):
                os.close(p.task_w)
            p.task_w = -1

    def close(p: _Proc) -> None:
        del procs[p.result_r]
        close_task(p)
        with contextlib.suppress(OSError):
            os.close(p.result_r)

    def assign(p: _Proc) -> None:
        """Give an idle worker the next run, or tell it to exit (EOF) when there is none."""
        if queue and sig.signum is None:
            i = queue.pop()
            try:
                os.write(p.task_w, i.to_bytes(4, "little"))
                p.current = i
            except OSError:  # it died idle: the run never started, someone else does it
                queue.append(i)
        else:
            close_task(p)

    try:
        while sig.signum is None and (queue or any(p.current is not None for p in procs.values())):
            while queue and len(procs) < workers and sig.signum is None:
                start()
            for p in list(procs.values()):
                if p.current is None and p.task_w >= 0:
                    assign(p)
            ready, _, _ = select.select(list(procs), [], [], 0.25)
            for fd in ready:
                p = procs[fd]
                chunk = os.read(fd, 1 << 16)
                if not chunk:  # EOF: the worker exited or died
                    close(p)
                    _, status = os.waitpid(p.pid, 0)
                    if p.current is not None and sig.signum is None:
                        done(_died_row(todo[p.current], _exit_reason(status)))
                    continue
                p.buf += chunk
                while len(p.buf) >= 8 and len(p.buf) >= 8 + int.from_bytes(p.buf[:8], "little"):
                    n = int.from_bytes(p.buf[:8], "little")
                    row = json.loads(bytes(p.buf[8 : 8 + n]).decode())
                    del p.buf[: 8 + n]
                    p.current = None
                    done(row)
    finally:
        for p in list(procs.values()):
            close_task(p)
        _reap([p.pid for p in procs.values()], wait_first=sig.signum is None)
        for p in list(procs.values()):
            close(p)


def _reap(pids: list[int], wait_first: bool = False) -> None:
    """End worker processes: SIGTERM (after :data:`GRACE_S` for them to exit on their own when
    ``wait_first``), then SIGKILL those still alive after another :data:`GRACE_S`."""
    left = set(pids)
    if wait_first:
        _wait_gone(left, time.monotonic() + GRACE_S)
    for pid in left:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGTERM)
    _wait_gone(left, time.monotonic() + GRACE_S)
    for pid in left:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    for pid in left:
        with contextlib.suppress(ChildProcessError):
            os.waitpid(pid, 0)


def _wait_gone(left: set[int], deadline: float) -> None:
    """Reap the processes of ``left`` that exit before ``deadline`` (removing them from it)."""
    while left and time.monotonic() < deadline:
        for pid in list(left):
            try:
                if os.waitpid(pid, os.WNOHANG)[0] != 0:
                    left.discard(pid)
            except ChildProcessError:
                left.discard(pid)
        if left:
            time.sleep(0.005)


def _run_local(todo: list[RunSpec], workers: int, sig: _Signals, done: Callable[[dict], None]) -> None:
    if workers <= 1 or not sys.platform.startswith("linux"):  # forking a process that loaded MuJoCo: Linux only
        _run_serial(todo, sig, done)
    else:
        _run_forked(todo, workers, sig, done)


#: Ray errors meaning the process running the task died (the run did not fail on its own).
_RAY_DIED = {"WorkerCrashedError", "OutOfMemoryError", "NodeDiedError", "ObjectLostError", "LocalRayletDiedError"}


def _run_ray(
    todo: list[RunSpec], workers: int, address: str | None, sig: _Signals, done: Callable[[dict], None]
) -> None:
    try:
        import ray
    except ImportError:
        raise InputError("--backend ray needs Ray: pip install 'bioform-mj[ray]'") from None
    started = False
    try:
        with _raising(sig):
            if not ray.is_initialized():
                kwargs: dict[str, Any] = {"address": address, "include_dashboard": False, "log_to_driver": False}
                if address is None:
                    kwargs["num_cpus"] = workers
                ray.init(**kwargs)
                started = True
        sig.reinstall()
    except _Stop:
        if started:
            ray.shutdown()
        return
    pending: dict[Any, RunSpec] = {}
    try:
        # no retries: a run whose worker dies is recorded as failed, like the local backend does
        remote = ray.remote(num_cpus=1, max_retries=0)(run_one)
        pending = {remote.remote(sp): sp for sp in todo}
        while pending and sig.signum is None:
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=0.25)
            for r in ready:
                sp = pending.pop(r)
                try:
                    row = ray.get(r)
                except Exception as exc:  # noqa: BLE001 - WorkerCrashedError, OutOfMemoryError, ...
                    msg = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
                    if type(exc).__name__ in _RAY_DIED:
                        row = _died_row(sp, msg)
                    else:
                        row = {**_base_row(sp), "status": "failed", "outcome": "failed", "error": msg}
                done(row)
    finally:
        if pending and sig.signum is not None:
            for r in pending:
                with contextlib.suppress(Exception):
                    ray.cancel(r, force=True)
        if started:
            ray.shutdown()


# ------------------------------------------------------------------------------------------
# The sweep


def _read_row(
    path: Path, spec: RunSpec, warn: Callable[[str], None] | None, redo: Callable[[dict], str | None] | None = None
) -> dict[str, Any] | None:
    """A finished row from an earlier invocation, or None when the run must be done (again):
    missing, unreadable or damaged, its worker died, or ``redo(row)`` gives a reason (said on stderr)."""
    try:
        text = path.read_bytes()
    except FileNotFoundError:
        return None
    except OSError as exc:
        problem = f"cannot be read ({exc.strerror or exc})"
    else:
        try:
            row = json.loads(text)
        except ValueError as exc:
            problem = f"is damaged ({exc})"
        else:
            if isinstance(row, dict) and row.get("key") == spec.key and "status" in row:
                if row.get("worker_died"):
                    return None
                why = redo(row) if redo is not None else None
                if why is None:
                    return row
                if warn is not None:
                    warn(f"row file '{path}': {why}; its run is redone")
                return None
            problem = "is damaged (not a row of this run)"
    if warn is not None:
        warn(f"row file '{path}' {problem}; its run is redone")
    return None


def _run_warp(
    todo: list[RunSpec], groups: Any, device: str, sig: _Signals, done: Callable[[dict], None], capacity: dict
) -> None:
    """The runs as worlds of MuJoCo Warp batches (:mod:`bioform_mj.batch.backend`), one batch per scene;
    ``capacity``: ``nconmax``/``njmax`` per world (None: the batch engine's defaults)."""
    from .batch.backend import run_warp

    def failed(sp: RunSpec, msg: str) -> dict[str, Any]:
        return {**_base_row(sp), "status": "failed", "outcome": "failed", "error": msg}

    try:
        with _raising(sig):
            run_warp(
                groups,
                device,
                _base_row,
                METRICS,
                done,
                stop=lambda: sig.signum is not None,
                failed_row=failed,
                **capacity,
            )
    except _Stop:
        return


def sweep(
    specs: list[RunSpec],
    out: Path,
    backend: str = "local",
    workers: int | None = None,
    ray_address: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    warn: Callable[[str], None] | None = _warn,
    device: str | None = None,
    nconmax: int | None = None,
    njmax: int | None = None,
) -> dict[str, Any]:
    """Run ``specs`` (skipping those already in ``out/runs``), then write the table and statistics.

    ``backend="warp"`` runs them as worlds of MuJoCo Warp batches on ``device`` (default: the
    GPU if there is one); every spec is checked first (feature support, device memory); ``nconmax``,
    ``njmax``: MuJoCo Warp's contact / constraint-row capacity per world (None: the defaults).
    Raises :class:`SweepInterrupted` after SIGINT/SIGTERM, with the finished rows kept and
    the tables written for them.
    """
    if backend not in ("local", "ray", "warp"):
        raise InputError(f"unknown backend '{backend}' (expected local, ray or warp)")
    if backend == "warp":
        from .batch.backend import require_warp, resolve_device

        require_warp()
        device = resolve_device(device)
    runs_dir = out / "runs"

    def redo(row: dict) -> str | None:  # a row stopped on MuJoCo Warp's capacity, resumed with other capacities
        from .batch.backend import capacity_redo

        return capacity_redo(row, backend, nconmax, njmax)

    rows: dict[str, dict[str, Any]] = {}
    todo: list[RunSpec] = []
    keys = list(dict.fromkeys(sp.key for sp in specs))  # identical runs (same content) run once
    seen: set[str] = set()
    for sp in specs:
        if sp.key in seen:
            continue
        seen.add(sp.key)
        row = _read_row(runs_dir / f"{sp.key}.json", sp, warn, redo)
        if row is None:
            todo.append(sp)
        else:
            rows[sp.key] = row
    groups = None
    if backend == "warp":
        from .batch.backend import plan

        groups = plan(todo, device)  # InputError before any work: unsupported feature, memory
        workers = 1
    runs_dir.mkdir(parents=True, exist_ok=True)
    workers = workers or os.cpu_count() or 1
    skipped = len(rows)

    def done(row: dict) -> None:
        write_json(runs_dir / f"{row['key']}.json", row)
        rows[row["key"]] = row
        if progress is not None:
            progress(len(rows), len(keys))

    if progress is not None:
        progress(len(rows), len(keys))
    t0 = time.perf_counter()
    with _Signals() as sig:
        if backend == "local":
            _run_local(todo, workers, sig, done)
        elif backend == "warp":
            _run_warp(todo, groups, device, sig, done, {"nconmax": nconmax, "njmax": njmax})
        else:
            _run_ray(todo, workers, ray_address, sig, done)
        wall = time.perf_counter() - t0
        ran = len(rows) - skipped
        interrupted = sig.signum
        # the tables are written before the handlers are restored: a second signal cannot cut them short
        got = [rows[k] for k in keys if k in rows]
        group_by = ["method"] + list(dict.fromkeys(k for sp in specs for k, _ in sp.vary))
        timing = {
            "backend": backend,
            "workers": workers,
            **({"device": device} if backend == "warp" else {}),
            "ran": ran,
            "skipped": skipped,
            "wall_s": wall,
            "runs_per_s": ran / wall if ran and wall > 0 else None,
            "runs": len(keys),
            "done": len(got),
            "complete": len(got) == len(keys),
            "interrupted": None if interrupted is None else signal.Signals(interrupted).name,
            "workers_died": sum(1 for r in got if r.get("worker_died")),
        }
        write_json(out / "sweep.json", timing)
        write_text(out / "runs.csv", to_csv(got))
        stats = aggregate(got, group_by)
        write_json(out / "stats.json", stats)
        note = (
            ""
            if len(got) == len(keys)
            else f"\n**Incomplete: {len(got)} of {len(keys)} runs done** (rerun the sweep to resume).\n"
        )
        write_text(out / "stats.md", stats_markdown(stats) + note)
    if interrupted is not None:
        raise SweepInterrupted(interrupted, len(got), len(keys))
    return {"rows": got, "stats": stats, "ran": ran, "skipped": skipped, "timing": timing}


def to_csv(rows: list[dict[str, Any]]) -> str:
    """Rows → CSV text with the union of their columns (pandas/polars ``read_csv`` open it)."""
    cols: list[str] = []
    for r in rows:
        cols += [c for c in r if c not in cols]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols)
    w.writeheader()
    for r in rows:
        w.writerow({c: "" if r.get(c) is None else r.get(c) for c in cols})
    return buf.getvalue()


def aggregate(rows: list[dict[str, Any]], group_by: Sequence[str] = ("method",)) -> dict[str, Any]:
    """Per group (one per distinct value of ``group_by``, e.g. method and every varied key): run counts
    by status and by outcome, and mean/std/p5/p50/p95 of every metric column over runs that finished
    (``status = ok``, whatever their outcome)."""
    group_by = list(group_by)
    order: dict[tuple, list[dict[str, Any]]] = {}
    for r in rows:
        order.setdefault(tuple(str(r.get(k, "")) for k in group_by), []).append(r)
    groups = []
    for gkey, rs in order.items():
        ok = [r for r in rs if r.get("status") == "ok"]
        outcomes: dict[str, int] = {}
        for r in rs:
            o = r.get("outcome") or r.get("status", "?")
            outcomes[o] = outcomes.get(o, 0) + 1
        entry: dict[str, Any] = dict(zip(group_by, gkey))
        entry.update(
            {
                "runs": len(rs),
                "ok": len(ok),
                "diverged": sum(r.get("status") == "diverged" for r in rs),
                "failed": sum(r.get("status") == "failed" for r in rs),
                "outcomes": outcomes,
                "metrics": {},
            }
        )
        cols = [c for c in (ok[0] if ok else {}) if c.endswith(("_mean", "_max"))]
        for c in cols:
            v = np.array([r[c] for r in ok], dtype=float)
            entry["metrics"][c] = {
                "mean": float(v.mean()),
                "std": float(v.std(ddof=1)) if len(v) > 1 else 0.0,
                "p5": float(np.percentile(v, 5)),
                "p50": float(np.percentile(v, 50)),
                "p95": float(np.percentile(v, 95)),
            }
        groups.append(entry)
    return {"group_by": group_by, "groups": groups}


def stats_markdown(stats: dict[str, Any]) -> str:
    """The headline statistics as a Markdown table, one row per group."""
    gb = stats["group_by"]
    head = [
        *gb,
        "runs (ok/diverged/failed)",
        "outcomes",
        "total velocity error, mean ± std",
        "final formation error max [m], p50 (p95)",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for e in stats["groups"]:
        tv = e["metrics"].get("total_velocity_error_mean")
        fe = e["metrics"].get("final_formation_error_m_max")
        tv_s = f"{tv['mean']:.3g} ± {tv['std']:.2g}" if tv else "–"
        fe_s = f"{fe['p50']:.3g} ({fe['p95']:.3g})" if fe else "–"
        oc = ", ".join(f"{k} {v}" for k, v in sorted(e["outcomes"].items(), key=lambda kv: (kv[0] != "ok", kv[0])))
        cells = [str(e[k]) for k in gb] + [f"{e['runs']} ({e['ok']}/{e['diverged']}/{e['failed']})", oc, tv_s, fe_s]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"

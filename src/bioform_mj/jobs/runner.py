"""The runner of long jobs (design §16): work items on processes forked from this one, stopped cleanly.

:func:`run_local` calls ``fn(item)`` for every item, in this process (one worker) or on worker
processes forked after the compiled kernels are loaded (:func:`load_kernels`), and hands each
result to ``done`` as it arrives. Workers ignore SIGINT (Ctrl-C reaches the whole process group;
the parent decides) and die with the parent (``PR_SET_PDEATHSIG``). :class:`Signals` records
SIGINT/SIGTERM: the runner stops handing out work, terminates the workers (SIGTERM, then SIGKILL
after :data:`GRACE_S`) and returns; in this process a signal abandons the item in progress
(:class:`Stop`). A worker that dies fails only its own item (``died(item, reason)``).
``sweep`` runs its runs and ``calibrate`` its evaluations through it.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import signal
import sys
import time
import traceback
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

#: Seconds a terminated worker gets to exit before it is killed.
GRACE_S = 2.0
#: forked workers per CPU of this machine at most (a run is CPU-bound: more only queue; each is a process, and
#: ``--workers 100000`` was taken and forked until the machine stalled)
WORKERS_PER_CPU = 8


def check_workers(workers: int | None, local: bool) -> None:
    """``workers`` at least 1 and, for forked workers on this machine (``local``), at most :data:`WORKERS_PER_CPU`
    per CPU (at least 16): else :class:`~bioform_mj.core.errors.InputError`, before any work."""
    from bioform_mj.core.errors import InputError

    if workers is None:
        return
    cap = max(16, WORKERS_PER_CPU * (os.cpu_count() or 1))
    if workers < 1 or (local and workers > cap):
        raise InputError(
            f"--workers must be 1 to {cap} on this machine ({os.cpu_count()} CPUs; runs are CPU-bound), got {workers}"
        )


def exit_reason(status: int) -> str:
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        try:
            name = signal.Signals(sig).name
        except ValueError:
            name = f"signal {sig}"
        hint = " (out of memory? the kernel's OOM killer sends SIGKILL)" if sig == signal.SIGKILL else ""
        return f"killed by {name}{hint}"
    return f"exited with code {os.waitstatus_to_exitcode(status)} without a result"


class Stop(BaseException):
    """Raised by the signal handler to abandon the in-process run (not an Exception: run_one lets it through)."""


class Signals:
    """SIGINT/SIGTERM → ``signum`` set (first one wins); while ``raising``, also raise :class:`Stop`."""

    def __init__(self) -> None:
        self.signum: int | None = None
        self.raising = False
        self._old: dict[int, Any] = {}

    def _handler(self, signum: int, frame: Any) -> None:
        if self.signum is None:
            self.signum = signum
        if self.raising:
            self.raising = False
            raise Stop()

    def __enter__(self) -> Signals:
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
def raising(sig: Signals) -> Iterator[None]:
    """Let a signal abandon what runs inside (checked on entry too)."""
    if sig.signum is not None:
        raise Stop()
    sig.raising = True
    try:
        yield
    finally:
        sig.raising = False


_KERNELS: list[bool] = []


def load_kernels() -> None:
    """Run both compiled loops for a moment, so that numba's cached machine code is loaded
    in this process (and inherited by forked workers instead of loaded once per worker); once per process."""
    if _KERNELS:
        return
    from bioform_mj.core.errors import quiet_outcomes
    from bioform_mj.run.simulate import simulate
    from bioform_mj.scenario.loader import load

    for plant in ("ideal", "mujoco"):
        with quiet_outcomes():  # a 0.01 s warm-up: its outcomes (c_hat_off) mean nothing
            simulate(load("paper", plant=plant, overrides=["sim.duration=0.01"]))
    _KERNELS.append(True)


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


def _worker(todo: list[Any], task_r: int, result_w: int, parent: int, fn: Callable[[Any], dict]) -> None:
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
            row = fn(todo[int.from_bytes(msg, "little")])
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


def _run_serial(todo: list[Any], sig: Signals, done: Callable[[dict], None], fn: Callable[[Any], dict]) -> None:
    for sp in todo:
        try:
            with raising(sig):
                row = fn(sp)
        except Stop:
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


def _run_forked(
    todo: list[Any],
    workers: int,
    sig: Signals,
    done: Callable[[dict], None],
    fn: Callable[[Any], dict],
    died: Callable[[Any, str], dict],
) -> None:
    """Runs on ``workers`` processes forked from this one after it loaded the compiled kernels, one run at a
    time each; a worker that dies fails the run it was doing and is replaced."""
    load_kernels()  # before forking: workers inherit the loaded kernels (start in ms, not ~1 s each)
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
            _worker(todo, task_r, result_w, parent, fn)
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
            busy = sum(p.current is not None for p in procs.values())
            while queue and len(procs) < min(workers, len(queue) + busy) and sig.signum is None:
                start()  # never more workers than runs to do (--workers 100000 forked 100000 for 2 runs)
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
                        done(died(todo[p.current], exit_reason(status)))
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


def run_local(
    todo: list[Any],
    workers: int,
    sig: Signals,
    done: Callable[[dict], None],
    fn: Callable[[Any], dict],
    died: Callable[[Any, str], dict],
) -> None:
    """``done(fn(item))`` for every item of ``todo``, in this process or on ``workers`` forked ones
    (``died(item, reason)``: the row of an item whose worker died); stops when ``sig`` records a signal."""
    if workers <= 1 or not sys.platform.startswith("linux"):  # forking a process that loaded MuJoCo: Linux only
        _run_serial(todo, sig, done, fn)
    else:
        _run_forked(todo, workers, sig, done, fn, died)

"""``bioform sweep --backend ray``: the runs as Ray tasks, with a connection that fails fast (design §16).

:func:`check_ray_address` probes the address's port (nothing there: InputError, exit 2, in < 1 s,
naming the address and what to check, token authentication included); :func:`run_ray` connects
with a deadline (``ray.init`` in a thread: SIGINT/SIGTERM stop the wait), then probes the
cluster's GCS port during the sweep and returns why when the head is lost.
"""

from __future__ import annotations

import contextlib
import gc
import signal
import threading
import time
from collections.abc import Callable
from typing import Any

from bioform_mj.core.errors import InputError
from bioform_mj.jobs.runner import Signals, Stop, raising

#: Ray errors meaning the process running the task died (the run did not fail on its own).
_RAY_DIED = {"WorkerCrashedError", "OutOfMemoryError", "NodeDiedError", "ObjectLostError", "LocalRayletDiedError"}


#: seconds a Ray connection may take (``ray.init`` against a cluster), and between probes of its GCS
#: port during a sweep; the head counts as lost after :data:`RAY_LOST_PROBES` failed probes in a row
RAY_CONNECT_TIMEOUT_S = 30.0
RAY_PROBE_EVERY_S = 2.0
RAY_LOST_PROBES = 3

_RAY_HELP = (
    "check that the Ray head runs there (`ray status --address ADDR`; `ray start --head` prints the address, "
    "GCS port 6379 by default) and that no firewall blocks the port; a cluster started with `ray start --head` "
    "(Ray >= 2.52) uses token authentication: set RAY_AUTH_MODE=token (and RAY_AUTH_TOKEN, or the token in "
    "~/.ray/auth_token) in the sweep's environment too"
)


def _host_port(address: str) -> tuple[str, int] | None:
    """``(host, port)`` of a Ray address ``HOST:PORT`` or ``ray://HOST:PORT`` (None: ``auto``/``local``)."""
    a = address.split("://", 1)[1] if "://" in address else address
    host, sep, port = a.rpartition(":")
    if not sep or not port.isdigit():
        return None
    return host.strip("[]") or "127.0.0.1", int(port)


def _probe(host: str, port: int, timeout: float = 2.0) -> str | None:
    """None when something accepts TCP connections at ``host:port``, else why not."""
    import socket

    try:
        with socket.create_connection((host, port), timeout=timeout):
            return None
    except OSError as exc:
        return (
            exc.strerror or type(exc).__name__ if not isinstance(exc, TimeoutError) else f"no answer in {timeout:g} s"
        )


def _ray_temp_dir() -> str:
    """The folder where ``ray start`` records its cluster (Ray's rule: ``$RAY_TMPDIR``, else ``$TMPDIR``
    on Linux, else ``/tmp``; then ``ray/``)."""
    import os
    import sys
    import tempfile

    base = os.environ.get("RAY_TMPDIR") or (os.environ.get("TMPDIR") if sys.platform.startswith("linux") else None)
    if not base:
        base = "/tmp" if sys.platform.startswith(("linux", "darwin")) else tempfile.gettempdir()
    return os.path.join(base, "ray")


def local_cluster() -> tuple[str, str | None]:
    """How a sweep without ``--ray-address`` gets its cluster: ``("env", ADDR)`` to join ``$RAY_ADDRESS``
    (Ray's own convention), ``("local", None)`` to start a local cluster of the sweep's own.

    ``ray.init()`` without an address joins whatever cluster ``ray start`` recorded in
    ``/tmp/ray/ray_current_cluster`` (and then refuses ``num_cpus``), or waits on a stale record of a dead
    one. A live recorded cluster is an :class:`InputError` naming it and the two ways on (join it with
    ``--ray-address``, or stop it); a stale record is ignored (``address="local"``)."""
    import os

    env = os.environ.get("RAY_ADDRESS", "").strip()
    if env:
        return "env", env
    path = os.path.join(_ray_temp_dir(), "ray_current_cluster")
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            recorded = f.read(4096).strip()
    except OSError:
        return "local", None
    hp = _host_port(recorded) if recorded else None
    if hp is not None and _probe(*hp, timeout=1.0) is None:
        raise InputError(
            f"--backend ray without --ray-address: a Ray cluster runs on this machine at {recorded} (recorded in "
            f"{path}); join it with --ray-address {recorded}, or stop it (`ray stop`) so that the sweep starts a "
            "local cluster of its own"
        )
    return "local", None


def check_ray_address(address: str | None) -> None:
    """InputError (exit 2) within seconds when nothing listens at ``--ray-address`` (or ``$RAY_ADDRESS``),
    naming it and what to check; without either, when a cluster ``ray start`` left runs (:func:`local_cluster`)."""
    flag = "--ray-address"
    if address is None:
        how, address = local_cluster()
        if how == "local" or address is None:
            return
        flag = "RAY_ADDRESS"
    hp = _host_port(address)
    if address not in ("auto", "local") and hp is None:
        raise InputError(f"{flag} '{address}': expected HOST:PORT (e.g. 127.0.0.1:6379), ray://HOST:PORT or auto")
    if hp is None:
        return
    why = _probe(*hp)
    if why is not None:
        raise InputError(f"{flag} {address}: cannot connect ({why}); {_RAY_HELP.replace('ADDR', address)}")


def _in_thread(fn: Callable[[], Any], seconds: float, sig: Signals) -> tuple[str, Any]:
    """Run ``fn`` in a daemon thread: ``("ok", value)``, ``("error", exc)``, ``("timeout", None)`` after
    ``seconds``, or ``("signal", None)`` as soon as ``sig`` records SIGINT/SIGTERM."""
    import threading

    box: dict[str, Any] = {}

    def body() -> None:
        try:
            box["ok"] = fn()
        except BaseException as exc:  # noqa: BLE001 - handed to the caller
            box["error"] = exc

    t = threading.Thread(target=body, daemon=True)
    t.start()
    deadline = time.monotonic() + seconds
    while t.is_alive():
        if sig.signum is not None:
            return "signal", None
        if time.monotonic() > deadline:
            return "timeout", None
        t.join(0.05)
    return ("error", box["error"]) if "error" in box else ("ok", box.get("ok"))


class _HeadWatch(threading.Thread):
    """Probes the Ray head's GCS port every :data:`RAY_PROBE_EVERY_S` in its own thread, so that a Ray
    call blocked on a lost head cannot hide the loss (Ray's core ends the process 60 s after it loses
    the GCS, and Python cannot catch that): after :data:`RAY_LOST_PROBES` failures in a row ``lost``
    says why; if the sweep's loop has not stopped :data:`RAY_PROBE_EVERY_S` later, the main thread is
    interrupted (:class:`~bioform_mj.jobs.runner.Stop` raised in it), so the tables of the finished rows get
    written and the ``error:`` line said (design §16)."""

    def __init__(self, gcs: tuple[str, int], sig: Signals) -> None:
        super().__init__(daemon=True, name="bioform-ray-head-watch")
        self.gcs, self.sig = gcs, sig
        self.lost: str | None = None
        self.done = threading.Event()

    def run(self) -> None:
        import _thread

        failed = 0
        while not self.done.wait(RAY_PROBE_EVERY_S):
            why = _probe(*self.gcs, timeout=1.0)
            failed = failed + 1 if why is not None else 0
            if failed >= RAY_LOST_PROBES:
                self.lost = f"the Ray head at {self.gcs[0]}:{self.gcs[1]} was lost ({why}, {failed} probes in a row)"
                if not self.done.wait(RAY_PROBE_EVERY_S):  # the loop did not notice: a Ray call is blocked
                    self.sig.raising = True
                    _thread.interrupt_main(signal.SIGINT)
                return


def run_ray(
    todo: list[Any],
    workers: int,
    address: str | None,
    sig: Signals,
    done: Callable[[dict], None],
    fn: Callable[[Any], dict],
    died_row: Callable[[Any, str], dict],
    failed_row: Callable[[Any, str], dict],
) -> str | None:
    """The runs as Ray tasks; returns None, or why the sweep could not go on (its head was lost).

    ``ray.init`` runs in a thread with a deadline (:data:`RAY_CONNECT_TIMEOUT_S`), so that a signal or a
    cluster that does not answer stops it in seconds; during the sweep the cluster's GCS port is probed
    every :data:`RAY_PROBE_EVERY_S` (design §16)."""
    import logging

    try:
        import ray
    except ImportError:
        raise InputError("--backend ray needs Ray: pip install 'bioform-mj[ray]'") from None
    started = False
    if not ray.is_initialized():
        if address is None:  # $RAY_ADDRESS, or a local cluster of the sweep's own (never one left on the machine)
            how, address = local_cluster()
        kwargs: dict[str, Any] = {"address": address, "include_dashboard": False, "log_to_driver": False}
        if address is None:
            kwargs["address"] = "local"
            kwargs["num_cpus"] = workers
        wlog = logging.getLogger("ray._private.worker")
        level = wlog.level
        wlog.setLevel(logging.ERROR)  # "SIGTERM handler is not set ...": ours stays, as wanted
        try:
            if address is None:  # a local cluster starts from the main thread (its GCS does not come up otherwise)
                try:
                    with raising(sig):
                        how, val = "ok", ray.init(**kwargs)
                except Stop:
                    how, val = "signal", None
                    if ray.is_initialized():
                        ray.shutdown()
                except Exception as exc:  # noqa: BLE001 - reported below
                    how, val = "error", exc
            else:
                how, val = _in_thread(lambda: ray.init(**kwargs), RAY_CONNECT_TIMEOUT_S, sig)
        finally:
            wlog.setLevel(level)
        where = address or "a local Ray"
        if how == "signal":
            return None
        if how == "timeout":
            raise InputError(
                f"--ray-address {where}: no connection in {RAY_CONNECT_TIMEOUT_S:g} s; "
                f"{_RAY_HELP.replace('ADDR', str(address))}"
            )
        if how == "error":
            msg = str(val).splitlines()[0] if str(val) else type(val).__name__
            raise InputError(
                f"--ray-address {where}: ray.init failed ({type(val).__name__}: {msg[:300]}); "
                f"{_RAY_HELP.replace('ADDR', str(address))}"
            )
        started = True
    sig.reinstall()
    gcs = None
    with contextlib.suppress(Exception):
        gcs = _host_port(ray.get_runtime_context().gcs_address)
    if gcs is None and address:  # the address the user gave is the GCS's too
        gcs = _host_port(address)
    pending: dict[Any, Any] = {}
    ready: list[Any] = []
    rest: list[Any] = []
    r = remote = None
    lost: str | None = None
    watch = _HeadWatch(gcs, sig) if gcs is not None else None
    try:
        # no retries: a run whose worker dies is recorded as failed, like the local backend does
        remote = ray.remote(num_cpus=1, max_retries=0)(fn)
        pending = {remote.remote(sp): sp for sp in todo}
        if watch is not None:
            watch.start()
        while pending and sig.signum is None:
            if watch is not None and watch.lost:
                lost = watch.lost
                break
            try:
                ready, rest = ray.wait(list(pending), num_returns=1, timeout=0.25)
            except Stop:  # the watch interrupted a Ray call that did not return (design §16)
                if watch is None or not watch.lost:
                    raise
                lost, sig.signum = watch.lost, None  # not the user's Ctrl-C: the head's loss
                break
            except Exception as exc:  # noqa: BLE001 - the cluster went away under us
                lost = f"Ray failed mid-sweep ({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})"
                break
            for r in ready:
                sp = pending.pop(r)
                try:
                    row = ray.get(r)
                except Exception as exc:  # noqa: BLE001 - WorkerCrashedError, OutOfMemoryError, ...
                    msg = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
                    if type(exc).__name__ in _RAY_DIED:
                        row = died_row(sp, msg)
                    else:
                        row = failed_row(sp, msg)
                done(row)
    finally:
        if watch is not None:
            watch.done.set()
        if pending and (sig.signum is not None or lost is None):
            for r in pending:
                with contextlib.suppress(Exception):
                    ray.cancel(r, force=True)
        # no ObjectRef may outlive the shutdown: its destructor would call into the core worker, which then
        # ends the process ("The core worker has already been shutdown"), before the tables and the error
        # line are written (seen once in four runs of the head-loss test)
        pending.clear()
        ready = rest = r = remote = None  # noqa: F841 - ray.wait's lists hold ObjectRefs too
        gc.collect()
        if started:  # a lost head can make shutdown wait: bounded
            _in_thread(ray.shutdown, 5.0, Signals())
    return lost

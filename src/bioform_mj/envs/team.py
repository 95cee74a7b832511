"""Persistent threads released and joined by compiled code (design §20; issue 30, item 6).

At a 1 ms control period the CPU-vectorised environment (``envs/vector.py``) hands every period to its threads:
with a ``ThreadPoolExecutor`` that is, per thread and period, a Python ``submit``, a wake-up of a sleeping thread,
its taking the GIL to unbox the call's arguments, and the same back through the ``Future`` (two threads, 32 worlds:
0.54 of ``mujoco.rollout`` on a quiet machine against 0.77 with one thread). Here the worker threads never leave
compiled code between periods: each runs :func:`wait_change` on a generation counter in a small ``int32`` control
array, which the calling thread bumps (:func:`bump`; :func:`publish` for the stop); each waits by spinning (atomic
loads, ``pause``) for up to ``spin_ns`` nanoseconds, then sleeps on a Linux futex (no GIL taken either way), as
OpenMP's and ``mujoco.rollout``'s thread pools spin before they sleep.

The control array's layout (int32, one 64-byte line per slot): slot 0 the "go" generation (:data:`GO`), its
sleepers' count (``GO + 1``) and the stop flag (:data:`STOP`); slot 1 (index ``SLOT``, ``envs.worlds.ALL``) the
count of "a thread finished its claims", which each worker bumps (:func:`bump`) after its share of a period, and
its sleepers' count (the calling thread, waiting for the count of worlds done).
Generations and counts wrap at 2³¹ (compared for inequality only). Loads and stores of the counters are
sequentially consistent (LLVM atomics); what a thread wrote before a ``bump`` or ``publish`` is seen by the thread
whose ``wait_change`` returned its value.

:data:`HAVE_TEAM`: Linux on x86-64 or aarch64 with numba's JIT on (elsewhere ``envs.vector`` uses a thread pool).
"""

from __future__ import annotations

import platform
import sys

import numpy as np

from bioform_mj.core.equations import HAVE_NUMBA, njit

#: int32 entries a slot of the control array takes (64 bytes: one cache line, no false sharing)
SLOT = 16
#: the "go" generation's index; ``GO + 1``: how many threads sleep on it; :data:`STOP`: the stop flag
GO, STOP = 0, 2
#: ``syscall(2)`` number of ``futex`` by machine (Linux)
SYS_FUTEX = {"x86_64": 202, "amd64": 202, "aarch64": 98, "arm64": 98}.get(platform.machine().lower())
#: ``FUTEX_WAIT_PRIVATE``, ``FUTEX_WAKE_PRIVATE``, ``CLOCK_MONOTONIC``
_WAIT, _WAKE, _MONOTONIC = 128, 129, 1
_X86 = platform.machine().lower() in ("x86_64", "amd64")

HAVE_TEAM = False
if HAVE_NUMBA:
    import numba
    from llvmlite import ir
    from numba.core import cgutils
    from numba.core import types as _t
    from numba.core.extending import intrinsic

    HAVE_TEAM = (
        not numba.config.DISABLE_JIT and sys.platform.startswith("linux") and SYS_FUTEX is not None
        and np.dtype(np.intp).itemsize == 8
    )  # fmt: skip

    def _ptr(context, builder, aryty, ary, idx):
        a = context.make_array(aryty)(context, builder, ary)
        return cgutils.get_item_pointer(context, builder, aryty, a, [idx], wraparound=False)

    @intrinsic
    def atomic_load(typingctx, a, i):
        """``a[i]`` loaded with sequential consistency (``a`` an int32 array)."""

        def codegen(context, builder, sig, args):
            return builder.load_atomic(_ptr(context, builder, sig.args[0], args[0], args[1]), "seq_cst", 4)

        return a.dtype(a, i), codegen

    @intrinsic
    def atomic_store(typingctx, a, i, v):
        """``a[i] = v`` stored with sequential consistency (``a`` an int32 array, ``v`` an int32)."""

        def codegen(context, builder, sig, args):
            builder.store_atomic(args[2], _ptr(context, builder, sig.args[0], args[0], args[1]), "seq_cst", 4)
            return context.get_dummy_value()

        return _t.none(a, i, _t.int32), codegen

    @intrinsic
    def atomic_add(typingctx, a, i, v):
        """``a[i] += v`` as one sequentially consistent read-modify-write; returns the old value."""

        def codegen(context, builder, sig, args):
            return builder.atomic_rmw("add", _ptr(context, builder, sig.args[0], args[0], args[1]), args[2],
                                      "seq_cst")  # fmt: skip

        return _t.int32(a, i, _t.int32), codegen

    @intrinsic
    def cpu_relax(typingctx):
        """The spin-wait hint (x86's ``pause``; nothing elsewhere)."""

        def codegen(context, builder, sig, args):
            if _X86:
                fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), []),
                                                    "llvm.x86.sse2.pause")  # fmt: skip
                builder.call(fn, [])
            return context.get_dummy_value()

        return _t.none(), codegen

    # ``long syscall(long number, ...)`` (the futex's six arguments) and ``clock_gettime``, by symbol from libc
    _syscall = numba.types.ExternalFunction(
        "syscall", _t.intp(_t.intp, _t.intp, _t.intp, _t.intp, _t.intp, _t.intp, _t.intp)
    )
    _clock_gettime = numba.types.ExternalFunction("clock_gettime", _t.int32(_t.int32, _t.intp))
    _FUTEX = SYS_FUTEX if SYS_FUTEX is not None else -1


@njit
def now_ns(ts):
    """``CLOCK_MONOTONIC`` in ns (``ts``: an int64 (2,) scratch array)."""
    _clock_gettime(np.int32(_MONOTONIC), ts.ctypes.data)
    return ts[0] * 1_000_000_000 + ts[1]


@njit
def wait_change(ctl, i, old, spin_ns, ts):
    """Wait until ``ctl[i] != old`` and return it: spin (atomic loads) for up to ``spin_ns`` ns, then sleep on
    the futex at ``ctl[i]``, counting this thread in ``ctl[i + 1]`` while it sleeps (:func:`publish` and
    :func:`bump` wake sleepers only)."""
    v = atomic_load(ctl, i)
    if v != old:
        return v
    if spin_ns > 0:
        t0 = now_ns(ts)
        while True:
            for _ in range(64):
                cpu_relax()
                v = atomic_load(ctl, i)
                if v != old:
                    return v
            if now_ns(ts) - t0 > spin_ns:
                break
    addr = ctl.ctypes.data + 4 * i
    while True:
        atomic_add(ctl, i + 1, np.int32(1))
        if atomic_load(ctl, i) == old:  # the kernel checks again: a publish in between returns at once
            _syscall(_FUTEX, addr, _WAIT, old, 0, 0, 0)
        atomic_add(ctl, i + 1, np.int32(-1))
        v = atomic_load(ctl, i)
        if v != old:
            return v


@njit
def publish(ctl, i, v):
    """``ctl[i] = v`` and wake the threads sleeping on it (:func:`wait_change`)."""
    atomic_store(ctl, i, np.int32(v))
    if atomic_load(ctl, i + 1) > 0:
        _syscall(_FUTEX, ctl.ctypes.data + 4 * i, _WAKE, 0x7FFFFFFF, 0, 0, 0)


@njit
def bump(ctl, i):
    """``ctl[i] += 1`` (one atomic add: the value changes whoever else bumps it at the same time; wrapping at
    2³¹) and wake the threads sleeping on it (:func:`wait_change`)."""
    atomic_add(ctl, i, np.int32(1))
    if atomic_load(ctl, i + 1) > 0:
        _syscall(_FUTEX, ctl.ctypes.data + 4 * i, _WAKE, 0x7FFFFFFF, 0, 0, 0)


@njit
def next_gen(g):
    """The generation after ``g`` (wrapping at 2³¹)."""
    return np.int32((np.int64(g) + 1) & 0x7FFFFFFF)


@njit
def stop(ctl):
    """Tell the workers to return (:data:`STOP`) and wake them."""
    atomic_store(ctl, STOP, np.int32(1))
    publish(ctl, GO, next_gen(atomic_load(ctl, GO)))


def control() -> np.ndarray:
    """A zeroed control array: its two slots (the module docstring), whatever the number of threads."""
    return np.zeros(2 * SLOT, dtype=np.int32)

"""The compiled pass of the bulk rosbag writer (issue 29; docs/design.md §9, a run as a ROS 2 bag).

:func:`place` writes a chunk's numbers — every message's stamps and fields, every message index's log times —
into the chunk's bytes in one pass per field over the chunk's samples. Each number is a 64-bit word (float64
bits, or an integer whose low 4 or 8 bytes are the field's) read where it lies: in the log's own arrays (no
copy of them) or in the writer's few converted values, by its byte address. It is written little-endian
byte by byte: the bytes ``np.asarray(values, dtype).tobytes()`` gives for ``<f8``, ``<u8``, ``<i4`` and
``<u4``, wherever they lie (MCAP records are not aligned). :mod:`bioform_mj.outputs.rosbag_write` builds
the field tables (``number_sources``, ``Numbers``: they also hold the arrays the addresses lie in) and calls
it once per chunk.

This module holds nothing but the kernel: it is one of the numba cache's keyed sources
(``core/codehash.py: KERNEL_SOURCES``), and any change of its text recompiles every kernel once.
"""

from __future__ import annotations

import numpy as np

from bioform_mj.core.equations import HAVE_NUMBA, njit

__all__ = ["place"]

_1, _2, _3, _4, _5, _6, _7 = (np.uint64(k) for k in range(1, 8))

if HAVE_NUMBA:
    from llvmlite import ir
    from numba import types
    from numba.extending import intrinsic

    @intrinsic
    def _word(typingctx, addr):  # noqa: ARG001 - numba's intrinsic signature
        """The 64-bit word (int64) at the byte address ``addr`` (uint64), of any alignment."""
        if not isinstance(addr, types.Integer):
            return None

        def codegen(context, builder, sig, args):  # noqa: ARG001
            ptr = builder.inttoptr(args[0], ir.IntType(64).as_pointer())
            return builder.load(ptr, align=1)

        return types.int64(addr), codegen

else:  # pragma: no cover - plain Python: the word read through ctypes

    def _word(addr: int) -> int:
        import ctypes

        return ctypes.c_int64.from_address(int(addr)).value


@njit
def place(
    buf: np.ndarray,
    addr: np.ndarray,
    step: np.ndarray,
    dst: np.ndarray,
    dst_step: np.ndarray,
    wide: np.ndarray,
    j0: int,
    n: int,
) -> None:
    """Write samples ``j0 … j0 + n − 1``'s numbers into ``buf`` (uint8, C-contiguous).

    For each field ``f`` and sample ``j = j0 + r``: the 64-bit word at byte address
    ``addr[f] + j * step[f]`` goes little-endian to the bytes from ``dst[f] + r * dst_step[f]`` of ``buf``:
    all 8 of them where ``wide[f]`` (a ``<f8`` or ``<u8``), else the low 4 (a ``<i4`` or ``<u4``: the value
    modulo 2³², as numpy casts). ``addr``, ``step``, ``dst``, ``dst_step``: uint64 (F,) (bytes, bytes per
    sample, bytes, bytes per sample); ``wide``: bool (F,). The caller keeps every address valid (the
    arrays alive) and every index in range (nothing is checked here)."""
    F = addr.shape[0]
    for f in range(F):
        a, s = addr[f] + np.uint64(j0) * step[f], step[f]
        d, ds = dst[f], dst_step[f]
        # unsigned indices: no negative-index wrap-around, so the byte stores merge into one store
        if wide[f]:
            for r in range(n):
                ru = np.uint64(r)
                v = _word(a + ru * s)
                p = d + ru * ds
                buf[p] = v & 0xFF
                buf[p + _1] = (v >> 8) & 0xFF
                buf[p + _2] = (v >> 16) & 0xFF
                buf[p + _3] = (v >> 24) & 0xFF
                buf[p + _4] = (v >> 32) & 0xFF
                buf[p + _5] = (v >> 40) & 0xFF
                buf[p + _6] = (v >> 48) & 0xFF
                buf[p + _7] = (v >> 56) & 0xFF
        else:
            for r in range(n):
                ru = np.uint64(r)
                v = _word(a + ru * s)
                p = d + ru * ds
                buf[p] = v & 0xFF
                buf[p + _1] = (v >> 8) & 0xFF
                buf[p + _2] = (v >> 16) & 0xFF
                buf[p + _3] = (v >> 24) & 0xFF

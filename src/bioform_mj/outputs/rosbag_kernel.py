"""The compiled pass of the bulk rosbag writer (issue 29; docs/design.md §9, a run as a ROS 2 bag).

:func:`place` writes a chunk's numbers — every message's stamps and fields, every message index's log times —
into the chunk's bytes in one pass over its samples, sample after sample (each sample's bytes are
written in the order they lie in the buffer). Its numbers are 64-bit words of one ``pool`` (float64 bits,
or integers whose low 4 or 8 bytes are the field's), written little-endian byte by byte: the bytes
``np.asarray(values, dtype).tobytes()`` gives for ``<f8``, ``<u8``, ``<i4`` and ``<u4``, wherever they lie
(MCAP records are not aligned). :mod:`bioform_mj.outputs.rosbag_write` builds the pool and the field
tables (``number_pool``, ``Numbers``) and calls it once per chunk.

This module holds nothing but the kernel: it is one of the numba cache's keyed sources
(``core/codehash.py: KERNEL_SOURCES``), and any change of its text recompiles every kernel once.
"""

from __future__ import annotations

import numpy as np

from bioform_mj.core.equations import njit

__all__ = ["place"]

_1, _2, _3, _4, _5, _6, _7 = (np.uint64(k) for k in range(1, 8))


@njit
def place(
    buf: np.ndarray,
    pool: np.ndarray,
    src: np.ndarray,
    src_step: np.ndarray,
    dst: np.ndarray,
    dst_step: np.ndarray,
    wide: np.ndarray,
    j0: int,
    n: int,
) -> None:
    """Write samples ``j0 … j0 + n − 1``'s numbers into ``buf`` (uint8, C-contiguous).

    For each sample ``j = j0 + r`` and field ``f`` (in the tables' order): the 64-bit word
    ``pool[src[f] + j * src_step[f]]`` (``pool``: int64) goes little-endian to the bytes from
    ``dst[f] + r * dst_step[f]`` of ``buf``: all 8 of them where ``wide[f]`` (a ``<f8`` or ``<u8``), else
    the low 4 (a ``<i4`` or ``<u4``: the value modulo 2³², as numpy casts). ``src``, ``src_step``,
    ``dst``, ``dst_step``: uint64 (F,) (words, words per sample, bytes, bytes per sample); ``wide``:
    bool (F,). The caller keeps every index in range (nothing is checked here)."""
    F = src.shape[0]
    for r in range(n):
        j = np.uint64(j0 + r)
        ru = np.uint64(r)
        for f in range(F):
            # unsigned indices: no negative-index wrap-around, so the byte stores merge into one store
            v = pool[src[f] + j * src_step[f]]
            p = dst[f] + ru * dst_step[f]
            if wide[f]:
                buf[p] = v & 0xFF
                buf[p + _1] = (v >> 8) & 0xFF
                buf[p + _2] = (v >> 16) & 0xFF
                buf[p + _3] = (v >> 24) & 0xFF
                buf[p + _4] = (v >> 32) & 0xFF
                buf[p + _5] = (v >> 40) & 0xFF
                buf[p + _6] = (v >> 48) & 0xFF
                buf[p + _7] = (v >> 56) & 0xFF
            else:
                buf[p] = v & 0xFF
                buf[p + _1] = (v >> 8) & 0xFF
                buf[p + _2] = (v >> 16) & 0xFF
                buf[p + _3] = (v >> 24) & 0xFF

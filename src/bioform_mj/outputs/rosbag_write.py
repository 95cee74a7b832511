"""The bulk rosbag2 writer of :mod:`bioform_mj.outputs.rosbag` (issue 29; a run as a ROS 2 bag).

``rosbags``' own writer takes one message at a time and, at the end, emits its YAML three ways; here a
run's messages go into the MCAP file in whole chunks (``(samples, bytes)`` matrices, filled with numpy by
:class:`bioform_mj.outputs.rosbag` topics) and the metadata — each connection's QoS, ``metadata.yaml`` and
the MCAP's copy of it — is emitted once by :mod:`bioform_mj.outputs.rosbag_yaml`, a block-style YAML writer
for the plain data it holds. The message definitions and type hashes are made once per process and type store
(:func:`msgdef`); what a layout's bags share (templates, the chunk buffer, connection records) once per layout
(:class:`ChunkPlan`).
"""

from __future__ import annotations

import functools
import struct
from typing import Any

import numpy as np

from bioform_mj.outputs.rosbag_yaml import metadata_text, qos_text, yaml_text

__all__ = [
    "CHUNK_BYTES",
    "ChunkPlan",
    "MSG_HEAD",
    "FullChunk",
    "Numbers",
    "bulk_writer",
    "mcap_head",
    "msgdef",
    "record",
    "writer_classes",
    "yaml_text",
]

#: bytes of records per MCAP chunk (as ``rosbags``' own writer: 1 MiB)
CHUNK_BYTES = 1 << 20
MSG_HEAD = 1 + 8 + 2 + 4 + 8 + 8  # opcode, record length, channel id, sequence, log time, publish time


class Numbers:
    """Where a chunk's numbers come from and go (the tables of :func:`~bioform_mj.outputs.rosbag_kernel.place`):
    per field ``addr`` (the byte address of its sample 0's 64-bit word) and ``step`` (bytes per sample),
    ``dst`` and ``dst_step`` (bytes in the buffer, and per sample), ``wide`` (8 bytes, else 4), each an (F,)
    array; ``keep``: the arrays those words lie in (:func:`number_sources`; held here, so that every address
    stays valid while the numbers are used); ``stamp``: ``(addr, step)`` of the samples' stamps (ns).
    :meth:`fill` writes samples ``j0 … j0 + n − 1`` of every field."""

    def __init__(
        self, keep: list[np.ndarray], addr, step, dst, dst_step, wide, stamp: tuple[int, int] = (0, 0)
    ) -> None:
        self.keep, self.stamp = keep, stamp
        order = np.lexsort((np.asarray(dst), np.asarray(dst_step)))
        self.addr, self.step, self.dst, self.dst_step = (
            np.asarray(c, np.uint64)[order] for c in (addr, step, dst, dst_step)
        )
        self.wide = np.asarray(wide, np.bool_)[order]

    def shifted(self, by: int) -> Numbers:
        """The same numbers written ``by`` bytes further into the buffer."""
        return Numbers(self.keep, self.addr, self.step, self.dst + np.uint64(by), self.dst_step, self.wide, self.stamp)

    def plus(self, addr, step, dst, dst_step, wide) -> Numbers:
        """These numbers and those of the fields ``addr … wide`` (words of the arrays in :attr:`keep`)."""
        cat = np.concatenate
        return Numbers(
            self.keep,
            cat([self.addr, np.asarray(addr, np.uint64)]),
            cat([self.step, np.asarray(step, np.uint64)]),
            cat([self.dst, np.asarray(dst, np.uint64)]),
            cat([self.dst_step, np.asarray(dst_step, np.uint64)]),
            cat([self.wide, np.asarray(wide, np.bool_)]),
            self.stamp,
        )

    def fill(self, buf: np.ndarray, j0: int, n: int) -> None:
        """Write samples ``j0 … j0 + n − 1`` into ``buf`` (uint8, C-contiguous, large enough)."""
        from bioform_mj.outputs.rosbag_kernel import place

        place(buf, self.addr, self.step, self.dst, self.dst_step, self.wide, j0, n)


def number_sources(
    dtypes: list[str], values: list[np.ndarray], sources: list[tuple[np.ndarray, tuple]], K: int
) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """Where the numbers of fields ``k`` lie as 64-bit words (``dtypes[k]``: ``<f8``, ``<u8``, ``<i4`` or
    ``<u4``; ``values[k]`` (≥ K,), the selection ``a[idx]`` of ``sources[k] = (a, idx)``, or ``a`` without
    ``idx``): ``(keep, addr, step)``, the arrays they lie in and each field's byte address of sample 0 and
    bytes per sample ((F,) uint64 each). Values selected by integers and one slice from a C-contiguous
    native array of 8-byte numbers of their kind (float64 for ``<f8``, 64-bit integers for the others: a log
    channel, the stamps) are read where they lie, in that array (no copy: the log's 1.6 MB of the paper
    scenario's ideal-plant bag were copied into one pool before, ~400 fresh pages); any other is converted
    to its dtype and widened to 64 bits (4-byte integers: the low 4 bytes are the dtype's), as
    ``np.asarray(values, dtype)`` gives them, into one array of such copies."""
    keep: dict[int, tuple[np.ndarray, int]] = {}  # id(a) → (a, its data's address), each array read in place
    copies: list[np.ndarray] = []
    at = 0  # words of copies so far
    addr: list[int] = []
    step: list[int] = []
    copied: list[tuple[int, int]] = []  # (field, its first word in the copies)
    for k, (dt, vals, (a, idx)) in enumerate(zip(dtypes, values, sources)):
        word = None
        kind = a.dtype.kind if isinstance(a, np.ndarray) and a.dtype.itemsize == 8 else ""
        if ((kind == "f") if dt == "<f8" else (kind in ("i", "u"))) and a.flags.c_contiguous and a.dtype.isnative:
            word = _selection(a, idx or (slice(None),), K)
            if word is not None:
                if id(a) not in keep:
                    keep[id(a)] = (a, a.ctypes.data)
                addr.append(keep[id(a)][1] + 8 * word[0])
                step.append(8 * word[1])
        if word is None:  # a copy, widened to 64 bits
            w = np.ascontiguousarray(vals[:K], dtype=dt)
            w = w.view(np.int64) if w.dtype.itemsize == 8 else w.astype(np.int64)
            copies.append(w)
            copied.append((k, at))
            addr.append(0)
            step.append(8)
            at += w.size
    held = [a for a, _ in keep.values()]
    if copies:
        pool = np.concatenate(copies)
        held.append(pool)
        for k, first in copied:
            addr[k] = pool.ctypes.data + 8 * first
    return held, np.array(addr, np.uint64), np.array(step, np.uint64)


def _selection(c: np.ndarray, idx: tuple, K: int) -> tuple[int, int] | None:
    """``(word of element 0, words per element)`` of ``c[idx]`` in the words of ``c`` (C-contiguous, 8-byte
    items), for ``idx`` of integers and one slice (a 1-D selection of at least ``K`` elements), else None."""
    shape, strides = c.shape, c.strides
    if len(idx) != len(shape):
        return None
    off, step = 0, None
    for ix, n, st in zip(idx, shape, strides):
        if type(ix) is slice:
            if step is not None:
                return None
            start, stop, by = ix.indices(n)
            if by <= 0 or len(range(start, stop, by)) < K:
                return None
            off += start * st
            step = by * st
        elif (type(ix) is int or isinstance(ix, np.integer)) and -n <= ix < n:
            off += (int(ix) % n) * st
        else:
            return None
    return None if step is None else (off // 8, step // 8)


def _chunk_row(topics: list[Any], cids: list[int], cols: list[int], B: int, stamps: np.ndarray) -> tuple:
    """One sample's bytes, numbers aside ((B,) uint8: every topic's message record side by side, at
    ``cols``, header and template), and its numbers' ``dtypes``, ``values``, ``sources`` and ``dst``
    (bytes from the row's start): the stamps ``stamps`` (K,) ns first, then each record's log and publish
    time and its marked fields (:class:`ChunkPlan`)."""
    row = np.empty(B, np.uint8)  # one sample's bytes, numbers aside
    dts, values, sources, dst = ["<u8"], [stamps], [(stamps, ())], [0]  # the stamps first: the indexes' times
    for tp, cid, col in zip(topics, cids, cols):
        L = tp.template.size
        row[col : col + MSG_HEAD] = np.frombuffer(struct.pack("<BQHIQQ", 0x05, 22 + L, cid, 0, 0, 0), np.uint8)
        row[col + MSG_HEAD : col + MSG_HEAD + L] = tp.template
        for at in (col + 15, col + 23):  # log time, publish time
            dts.append("<u8")
            values.append(stamps)
            sources.append(sources[0])
            dst.append(at)
        for off, dt, vals, src in tp.fields:
            dts.append(dt)
            values.append(vals)
            sources.append(src)
            dst.append(col + MSG_HEAD + off)
    assert all(dt in ("<f8", "<u8", "<i4", "<u4") for dt in dts)
    return row, dts, values, sources, dst


class ChunkPlan:
    """What :meth:`BulkWriter.write_samples` makes of one layout of samples (the same topics, templates,
    field sources and chunk size: a sweep's bags, a process's later runs, a run after
    :func:`~bioform_mj.outputs.rosbag.warm_up` of its scenario), kept for the next bag of it
    (:data:`PLANS`): the chunk buffer (:class:`FullChunk`, or a matrix of its own) with every record's
    constant bytes written, and where the numbers lie relative to their arrays. A bag then writes only
    its numbers into it (no fresh pages, no template copies, no address searches).

    :meth:`numbers` gives a bag's :class:`Numbers`: from the cached relative addresses where the bag's
    arrays are laid out as the first bag's were (same shape but the rows, strides, dtype, C order: where
    :func:`number_sources` reads a number relative to its array's start; as many rows beyond the ``K``
    read, where each number is read row after row, else the same rows), else by it afresh."""

    def __init__(
        self, topics: list[Any], cids: list[int], cols: list[int], B: int, per: int, full: bool, stamps: np.ndarray
    ) -> None:
        """The plan of ``topics`` (at ``cids``, ``cols``; ``B`` bytes a sample) in chunks of ``per`` samples
        (``full``: in a :class:`FullChunk`), made with the first bag's samples ``stamps`` (K,) ns:
        :attr:`first` holds its :class:`Numbers`."""
        self.B = B
        self.full = FullChunk(per, B, cids, cols) if full else None
        self.M = np.empty((per, B), np.uint8) if self.full is None else self.full.M
        row, self.dts, values, sources, self.dst = _chunk_row(topics, cids, cols, B, stamps)
        self.M[:] = row
        self.wide = [dt in ("<f8", "<u8") for dt in self.dts[1:]]
        #: (slots, byte offsets, steps, each array's form) where every number is read in place, else None
        self.rel: tuple | None = None
        self.first: Numbers | None = self._found(number_sources(self.dts, values, sources, len(stamps)), topics, stamps)

    def _found(self, found: tuple, topics: list[Any], stamps: np.ndarray) -> Numbers:
        """The :class:`Numbers` of ``found = number_sources(…)``, its addresses kept relative to their
        arrays where every number is read in place (no copy)."""
        keep, addr, step = found
        arrays, slots, forms = self._arrays(topics, stamps)
        held = {id(a) for a in keep}
        base = np.array([a.ctypes.data for a in arrays], np.uint64)[slots]
        ends = base + np.array([a.nbytes for a in arrays], np.uint64)[slots]
        inside = all(id(a) in held for a in arrays) and bool(np.all(addr >= base) and np.all(addr < ends))
        # rows read one after another from each array's row 0 on (every step one row): another K reads the
        # same words of its rows where each array has as many rows beyond K; else only arrays of one shape
        ahead = all(s == arrays[j].strides[0] for j, s in zip(slots, step.tolist())) and bool(np.all(addr >= base))
        spare = tuple(a.shape[0] - len(stamps) for a in arrays) if ahead else None
        self.rel = (slots, addr - base, step, forms, spare, [a.shape for a in arrays]) if inside else None
        return self._numbers(keep, addr, step)

    def _numbers(self, keep: list[np.ndarray], addr: np.ndarray, step: np.ndarray) -> Numbers:
        wide, stamp = self.wide, (int(addr[0]), int(step[0]))
        return Numbers(keep, addr[1:], step[1:], self.dst[1:], np.full(len(wide), self.B), wide, stamp)

    def numbers(self, topics: list[Any], cids: list[int], cols: list[int], stamps: np.ndarray) -> Numbers:
        """The :class:`Numbers` of a bag's samples ``stamps`` (K,) in :attr:`M` (the first bag's: made
        with the plan)."""
        if self.first is not None:
            first, self.first = self.first, None
            return first
        arrays, slots, forms = self._arrays(topics, stamps)
        rel = self.rel
        if (
            rel is not None
            and rel[0] == slots
            and rel[3] == forms
            and (tuple(a.shape[0] - len(stamps) for a in arrays) == rel[4] or [a.shape for a in arrays] == rel[5])
        ):
            base = np.array([a.ctypes.data for a in arrays], np.uint64)
            return self._numbers(arrays, base[self.rel[0]] + self.rel[1], self.rel[2])
        _, _, values, sources, _ = _chunk_row(topics, cids, cols, self.B, stamps)
        return self._found(number_sources(self.dts, values, sources, len(stamps)), topics, stamps)

    @staticmethod
    def _arrays(topics: list[Any], stamps: np.ndarray) -> tuple[list[np.ndarray], list[int], list[tuple]]:
        """The distinct arrays the numbers come from (the stamps first), each number's (its index) and
        each array's form (its shape but the rows, strides, dtype, C order: where a word of a row lies
        relative to the array's start; its rows: :meth:`numbers`)."""
        arrays, seen, slots = [stamps], {id(stamps): 0}, [0]
        for tp in topics:
            slots += (0, 0)  # log and publish time
            for _, _, _, (a, _) in tp.fields:
                j = seen.setdefault(id(a), len(seen))
                if j == len(arrays):
                    arrays.append(a)
                slots.append(j)
        return arrays, slots, [(a.shape[1:], a.strides, a.dtype.str, a.flags.c_contiguous) for a in arrays]


#: :class:`ChunkPlan` of the layouts written lately, by layout; taken out while a bag is written with it
#: (a writer in another thread then makes its own), most recent last
PLANS: dict[tuple, ChunkPlan] = {}
PLANS_KEPT = 4


class FullChunk:
    """An MCAP chunk of ``rows`` whole samples (``B`` bytes each: every topic's message record side by side,
    topic ``cids[k]`` at ``cols[k]``) with nothing before or after them in it, and its message index
    records: all in one byte buffer, written with one ``write`` call. Everything but the samples' numbers
    and the chunk's times is the same for every such chunk and is written once: the chunk record's header,
    the records' constant bytes (:class:`ChunkPlan` fills :attr:`M`, the samples' ``(rows, B)`` matrix,
    a view into the buffer) and each message index's offsets (``sample * B + col``, the chunk's records
    start at 0). The bytes are those ``write_chunk`` writes for the same records. :meth:`numbers` says where
    the numbers of a chunk go in :attr:`buf`: the matrix's and every message index's log times."""

    HEAD = 1 + 8 + 8 + 8 + 8 + 4 + 4 + 8  # opcode, length, start/end time, size, CRC (0), "" (no compression), size

    def __init__(self, rows: int, B: int, cids: list[int], cols: list[int]) -> None:
        self.rows, self.size = rows, rows * B
        order = sorted(range(len(cids)), key=lambda k: cids[k])
        self.cids = [cids[k] for k in order]
        self.index_len = 1 + 8 + 2 + 4 + 16 * rows  # one message index record: (log time, offset) pairs
        H, C = self.HEAD, len(cids)
        # every byte is written below, by ChunkPlan (the matrix) or by the numbers: no zeroed pages
        self.buf = np.empty(H + self.size + C * self.index_len, np.uint8)
        struct.pack_into("<BQQQQIIQ", self.buf, 0, 0x06, H - 9 + self.size, 0, 0, self.size, 0, 0, self.size)
        #: the samples' byte matrix, (rows, B) uint8
        self.M = self.buf[H : H + self.size].reshape(rows, B)
        self.index_at = [H + self.size + k * self.index_len for k in range(C)]
        for at, k in zip(self.index_at, order):
            struct.pack_into("<BQHI", self.buf, at, 0x07, 2 + 4 + 16 * rows, cids[k], 16 * rows)
            pairs = np.ndarray((rows, 2), "<u8", buffer=self.buf, offset=at + 15)
            pairs[:, 1] = np.arange(rows, dtype=np.uint64) * B + cols[k]
        self.summary = struct.Struct("<QQQQI" + "HQ" * C + "QIQQ")  # the chunk index record (summary section)

    def numbers(self, matrix: Numbers) -> Numbers:
        """The :class:`Numbers` of a chunk in :attr:`buf`: ``matrix``'s (those of :attr:`M`) and each message
        index's log times (the samples' stamps, one ``(time, offset)`` pair of 16 bytes per sample)."""
        s, ss = matrix.stamp
        C = len(self.index_at)
        times = np.array(self.index_at, np.int64) + 15
        return matrix.shifted(self.HEAD).plus(np.full(C, s), np.full(C, ss), times, np.full(C, 16), np.ones(C, bool))

    def write(self, storage: Any, t_start: int, t_end: int) -> None:
        """Write the chunk (:attr:`buf` filled by :meth:`numbers`) of samples from ``t_start`` to ``t_end``
        ns to ``storage`` (``BulkMcap``), with its chunk index and message counts as ``write_chunk`` keeps
        them."""
        from io import BytesIO

        struct.pack_into("<QQ", self.buf, 9, t_start, t_end)
        start = storage.bio.tell()
        storage.bio.write(self.buf)
        where = [v for cid, at in zip(self.cids, self.index_at) for v in (cid, start + at)]
        n = len(self.cids) * self.index_len
        rec = BytesIO()
        rec.write(
            self.summary.pack(
                t_start, t_end, start, self.HEAD + self.size, len(self.cids) * 10, *where, n, 0, self.size, self.size
            )
        )
        storage.chunks.append(rec)
        for cid in self.cids:
            storage.channel_stats[cid] += self.rows
        storage.message_start_time = min(storage.message_start_time, t_start)
        storage.message_end_time = max(storage.message_end_time, t_end)


@functools.cache
def _fallocate() -> Any:
    """libc's ``fallocate`` (Linux), else None."""
    import ctypes
    import sys

    if not sys.platform.startswith("linux"):  # its mode flags are Linux's
        return None
    try:
        libc = ctypes.CDLL(None, use_errno=True)
    except (OSError, TypeError):  # pragma: no cover - no C library to load by name (Windows: TypeError)
        return None
    fn = getattr(libc, "fallocate64", None) or getattr(libc, "fallocate", None)
    if fn is not None:
        fn.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int64, ctypes.c_int64]
        fn.restype = ctypes.c_int
    return fn


def reserve(bio: Any, nbytes: int) -> None:
    """Allocate the disk blocks of the ``nbytes`` bytes to be written from ``bio``'s position (a binary
    file) in one call, its size unchanged (``fallocate`` with ``FALLOC_FL_KEEP_SIZE``, Linux; nothing
    elsewhere, or where the file system refuses: the writes then allocate as they go, and report any
    error themselves). The writes that follow then find their blocks: writing the 13 MB of the
    paper scenario's ideal-plant bag into the page cache took about 0.75 ms less CPU (3.0 → 2.3 ms of
    13 MiB in 1 MiB writes on ext4, 30 alternated trials; docs/guide/rosbag.md)."""
    fn = _fallocate()
    if fn is not None and nbytes > 0:
        fn(bio.fileno(), 1, bio.tell(), nbytes)  # 1: FALLOC_FL_KEEP_SIZE; a refusal (-1) changes nothing


@functools.cache
def mcap_head() -> bytes:
    """The MCAP file's magic and header record as ``rosbags``' ``McapWriter`` writes them (its profile
    ``ros2``, library ``rosbags-<version>``)."""
    from importlib.metadata import version
    from io import BytesIO

    from rosbags.rosbag2.storage_mcap import write_record, write_string

    out, rec = BytesIO(), BytesIO()
    out.write(b"\x89MCAP\x30\r\n")
    write_string(rec, "ros2")
    write_string(rec, f"rosbags-{version('rosbags')}")
    write_record(out, 0x01, rec)
    return out.getvalue()


def record(cid: int, stamp: int, data: bytes) -> bytes:
    return struct.pack("<BQHIQQ", 0x05, 2 + 4 + 8 + 8 + len(data), cid, 0, stamp, stamp) + data


@functools.cache
def writer_classes():
    """``(_BulkWriter, _BulkMcap)``: rosbags' writer with a storage that takes whole chunks at once."""
    from collections import defaultdict
    from io import BytesIO
    from pathlib import Path

    from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
    from rosbags.rosbag2.storage_mcap import McapWriter, PendingChunk

    class BulkMcap(McapWriter):
        """``rosbags``' MCAP storage (rosbags 0.11.9) plus :meth:`write_chunk`: one chunk of ready records.
        ``name``: the MCAP file's name without ``.mcap`` (default: the folder's, as ``rosbags``), so that a
        bag is written in a temporary folder under its final file name."""

        def __init__(self, path: Path, compression: Any, name: str | None = None) -> None:
            """``McapWriter.__init__`` without compression (the bulk writer's metadata states none) and
            with the file's magic and header record made once per process (:func:`mcap_head`: ``rosbags``
            reads its own version from the package metadata for every file, a few ms)."""
            from rosbags.rosbag2 import CompressionMode

            if compression != CompressionMode.NONE:
                raise ValueError("rosbag: the bulk writer writes uncompressed bags only")
            self.path = path / f"{name or path.name}.mcap"
            self.bio = self.path.open("xb")
            self.bio.write(mcap_head())
            self.schemas, self.channels, self.chunks = [], [], []
            self.chunk = PendingChunk(2**63 - 1, 0, BytesIO(), defaultdict(list))
            self.compression = ""
            self.compressor = lambda x: x
            self.message_start_time = 2**63 - 1
            self.message_end_time = 0
            self.channel_stats = {}

        def close(self, version: int, metadata: str) -> None:
            """``McapWriter.close`` (rosbags 0.11.9): the metadata record, data end, then the summary (schemas,
            channels, chunk indexes, metadata index, statistics, summary offsets, footer, magic) — the same
            records, built in memory and written with one ``write`` (``rosbags`` writes each field of each
            record to the file, a few hundred calls)."""
            if self.chunk.bio.tell():
                self.close_chunk()
            out = BytesIO()
            base = self.bio.tell()

            def put(op: int, body: bytes) -> None:
                out.write(struct.pack("<BQ", op, len(body)))
                out.write(body)

            def text(x: str) -> bytes:
                b = x.encode()
                return struct.pack("<I", len(b)) + b

            sub = text("serialized_metadata") + text(metadata)
            put(0x0C, text("rosbag2") + struct.pack("<I", len(sub)) + sub)
            metadata_end = base + out.tell()
            put(0x0F, struct.pack("<I", 0))
            schema_start = base + out.tell()
            ids = {}
            for sc in self.schemas:
                ids.setdefault(sc.name, sc.id)
                put(0x03, struct.pack("<H", sc.id) + text(sc.name) + text(sc.encoding) + text(sc.data))
            channel_start = base + out.tell()
            for ch in self.channels:
                head = struct.pack("<HH", ch.id, ids[ch.schema]) + text(ch.topic) + text(ch.message_encoding)
                put(0x04, head + struct.pack("<I", len(ch.metadata)) + ch.metadata)
            chunk_start = base + out.tell()
            for chunk in self.chunks:
                put(0x08, chunk.getvalue())
            index_start = base + out.tell()
            put(0x0D, struct.pack("<QQ", base, metadata_end - base) + text("rosbag2"))
            stats_start = base + out.tell()
            stats = sorted(self.channel_stats.items())
            put(
                0x0B,
                struct.pack(
                    "<QHIIIIQQI" + "HQ" * len(stats),
                    sum(self.channel_stats.values()),
                    len(self.schemas),
                    len(self.channels),
                    0,  # attachments
                    1,  # metadata
                    len(self.chunks),
                    self.message_start_time,
                    self.message_end_time,
                    len(stats) * 10,
                    *(v for kv in stats for v in kv),
                ),
            )
            offsets_start = base + out.tell()
            for op, a, b in (
                (0x03, schema_start, channel_start),
                (0x04, channel_start, chunk_start),
                (0x08, chunk_start, index_start),
            ):
                if a != b:
                    put(0x0E, struct.pack("<BQQ", op, a, b - a))
            put(0x0E, struct.pack("<BQQ", 0x0D, index_start, stats_start - index_start))
            put(0x0E, struct.pack("<BQQ", 0x0B, stats_start, offsets_start - stats_start))
            put(0x02, struct.pack("<QQI", schema_start, offsets_start, 0))
            out.write(b"\x89MCAP\x30\r\n")
            self.bio.write(out.getbuffer())
            self.bio.close()

        def write_chunk(
            self, pieces: list[Any], index: dict[int, tuple[np.ndarray, np.ndarray]], times: tuple | None = None
        ) -> None:
            """Write the message records ``pieces`` (bytes or contiguous uint8 arrays, in time order) as
            one chunk; ``index``: channel id → (log times, offsets of its records in the pieces); ``times``:
            the least and greatest of those log times, where the caller knows them. The schema and channel
            records ``rosbags`` keeps pending go first."""
            pending = self.chunk.bio.getvalue()
            self.chunk = PendingChunk(2**63 - 1, 0, BytesIO(), defaultdict(list))
            if not index:
                return
            pieces = [pending, *pieces]
            size = sum(len(p) if isinstance(p, bytes) else p.nbytes for p in pieces)
            t_start, t_end = times or (
                min(int(t.min()) for t, _ in index.values()),
                max(int(t.max()) for t, _ in index.values()),
            )
            if self.compression:
                pieces = [self.compressor(b"".join(bytes(p) for p in pieces))]
            comp_size = sum(len(p) if isinstance(p, bytes) else p.nbytes for p in pieces)
            cname = self.compression.encode()
            head = struct.pack("<QQQI", t_start, t_end, size, 0) + struct.pack("<I", len(cname)) + cname
            body = head + struct.pack("<Q", comp_size)
            chunk_start = self.bio.tell()
            self.bio.write(struct.pack("<BQ", 0x06, len(body) + comp_size))
            self.bio.write(body)
            for p in pieces:
                self.bio.write(p if isinstance(p, bytes) else memoryview(p))
            chunk_end = self.bio.tell()
            # the message index records, one buffer: per channel its header and (log time, offset) pairs
            order = sorted(index)
            recs = np.empty(sum(15 + 16 * len(index[cid][0]) for cid in order), np.uint8)
            offsets, at = [], 0
            for cid in order:
                t, off = index[cid]
                offsets.append((cid, chunk_end + at))
                struct.pack_into("<BQHI", recs, at, 0x07, 2 + 4 + 16 * len(t), cid, 16 * len(t))
                pairs = np.ndarray((len(t), 2), "<u8", buffer=recs, offset=at + 15)
                pairs[:, 0], pairs[:, 1] = t, off + len(pending)
                at += 15 + 16 * len(t)
                self.channel_stats[cid] += len(t)
            self.bio.write(memoryview(recs))
            rec = BytesIO()
            rec.write(struct.pack("<QQQQ", t_start, t_end, chunk_start, chunk_end - chunk_start))
            rec.write(struct.pack("<I", len(offsets) * 10))
            for cid, o in offsets:
                rec.write(struct.pack("<HQ", cid, o))
            rec.write(struct.pack("<Q", self.bio.tell() - chunk_end))
            rec.write(struct.pack("<I", len(cname)) + cname)
            rec.write(struct.pack("<QQ", comp_size, size))
            self.chunks.append(rec)
            self.message_start_time = min(self.message_start_time, t_start)
            self.message_end_time = max(self.message_end_time, t_end)

    class BulkWriter(Writer):
        """``rosbags``' rosbag2 writer whose MCAP storage takes a run's messages in whole chunks, and whose
        metadata (each connection's QoS, ``metadata.yaml`` and the MCAP's copy of it) is written once by
        :func:`yaml_text`: ``rosbags`` 0.11.9 runs its YAML emitter once per connection and twice at the end,
        as long as filling all the messages of an ideal-plant run."""

        STORAGE_PLUGINS = {StoragePlugin.MCAP: BulkMcap}

        def __init__(self, path: Any, *, name: str | None = None, **kwargs: Any) -> None:
            """``Writer(path, **kwargs)``; ``name``: the MCAP file's name without ``.mcap`` (default: the
            folder's name, as ``rosbags``)."""
            super().__init__(path, **kwargs)
            self.mcap_name = name

        def open(self) -> None:
            """``Writer.open``: the folder (it must not exist), then the MCAP storage named ``name``."""
            try:
                self.path.mkdir(mode=0o755, parents=True)
            except FileExistsError:
                raise WriterError(f"{self.path} exists already, not overwriting.") from None
            self.storage = BulkMcap(self.path, self.compression_mode, self.mcap_name)

        def add_connection(
            self, topic: str, msgtype: str, *, typestore: Any, offered_qos_profiles: list[Any] = ()
        ) -> Any:
            """``Writer.add_connection`` for a type of ``typestore`` (its definition and hash made once per
            process: :func:`_msgdef`), the QoS written by :func:`yaml_text`."""
            from rosbags.interfaces import Connection, ConnectionExtRosbag2, MessageDefinition

            assert self.storage and self.version >= 9
            fmt, text, rihs01 = msgdef(typestore, msgtype)
            qos = list(offered_qos_profiles)
            conn = Connection(
                id=len(self.connections) + 1,
                topic=topic,
                msgtype=msgtype,
                msgdef=MessageDefinition(fmt, text),
                digest=rihs01,
                msgcount=0,
                ext=ConnectionExtRosbag2(serialization_format="cdr", offered_qos_profiles=qos),
                owner=self,
            )
            if any(c.topic == topic for c in self.connections):
                raise ValueError(f"rosbag: topic {topic} added twice")
            st, new = self.storage, msgtype not in self.added_types
            # its schema (where new) and channel records, made once per process: the same for the same
            # topic, type, QoS, channel id and schema id
            sid = len(st.schemas) + 1 if new else next(x.id for x in st.schemas if x.name == msgtype)
            key = (id(typestore), topic, msgtype, tuple(qos), conn.id, new, sid)
            made = CONNECTION_RECORDS.get(key)
            if made is None:
                at, before = st.chunk.bio.tell(), len(st.schemas)
                if new:
                    st.add_msgtype(conn)
                st.add_connection(conn, qos_text(tuple(qos)))
                made = (st.schemas[before:], st.channels[-1], bytes(st.chunk.bio.getbuffer()[at:]), typestore)
                if len(CONNECTION_RECORDS) >= 512:
                    CONNECTION_RECORDS.clear()
                CONNECTION_RECORDS[key] = made
            else:
                st.schemas += made[0]
                st.channels.append(made[1])
                st.channel_stats[conn.id] = 0
                st.chunk.bio.write(made[2])
            self.added_types.add(msgtype)
            self.connections.append(conn)
            self.counts[conn.id] = 0
            return conn

        def close(self) -> None:
            """``Writer.close`` (no compression): the MCAP's summary, then ``metadata.yaml``, the same
            fields, each emitted once by :func:`~bioform_mj.outputs.rosbag_yaml.metadata_text`."""
            assert self.storage
            path = self.storage.path
            duration = max(0, self.max_timestamp - self.min_timestamp)
            start, count = self.min_timestamp, sum(self.counts.values())
            head = {
                "version": self.version,
                "storage_identifier": self.storage_plugin.name.lower(),
                "relative_file_paths": [path.name],
                "duration": {"nanoseconds": duration},
                "starting_time": {"nanoseconds_since_epoch": start},
                "message_count": count,
            }
            topics = [
                (c.topic, c.msgtype, c.ext.serialization_format, tuple(c.ext.offered_qos_profiles), c.digest)
                + (self.counts[c.id],)
                for c in self.connections
            ]
            tail = {
                "compression_format": "",
                "compression_mode": "",
                "files": [
                    {
                        "path": path.name,
                        "starting_time": {"nanoseconds_since_epoch": start},
                        "duration": {"nanoseconds": duration},
                        "message_count": count,
                    }
                ],
                "custom_data": self.custom_data or None,
                "ros_distro": "rosbags",
            }
            inner = metadata_text(head, topics, tail)
            self.storage.close(self.version, inner)
            self.storage = None
            body = "".join(f"  {ln}\n" for ln in inner.splitlines())
            self.metapath.write_text(f"rosbag2_bagfile_information:\n{body}", "utf8")

        def write_samples(self, c_static: Any, static: bytes, topics: list[Any], conns: dict, stamps) -> None:
            """``/tf_static`` at the first stamp, then every sample's messages in topic order, in chunks of
            whole samples of about :data:`CHUNK_BYTES`. Every topic has a message at each of the first
            ``K`` samples (the log rows, all of one layout: a chunk is a ``(samples, B)`` byte matrix,
            :class:`ChunkPlan`, refilled for each chunk: memory stays at one chunk); the last sample (the
            end of the run) holds the state topics' messages only."""
            S = len(stamps)
            K = S - 1
            cids = [conns[tp.name].id for tp in topics]
            cols, c = [], 0
            for tp in topics:
                cols.append(c)
                c += tp.width
            B = c
            tail, tail_idx = [], []  # the last sample: (cid, record bytes)
            for tp, cid in zip(topics, cids):
                full = len(tp.rows) == S
                if full:  # the state topics: one more message, at the end of the run
                    tail.append(tp.record_at(cid, int(stamps[K]), K))
                    tail_idx.append(cid)
                for row, data in tp.extra:
                    assert row == K, "only the last sample has messages of another layout"
                    tail.append(record(cid, int(stamps[row]), data))
                    tail_idx.append(cid)
            first = record(c_static.id, int(stamps[0]), static)
            per = max(1, min(K, CHUNK_BYTES // max(B, 1)))
            bounds = [(j0, min(K, j0 + per)) for j0 in range(0, max(K, 1), per)]
            # the chunks between the first (schemas, channels, /tf_static) and the last (the end of the run):
            # all of ``per`` samples, written from one buffer whose matrix the slots fill
            has_full = any(0 < j0 and j1 < K for j0, j1 in bounds)
            layout = getattr(topics[0], "layout", None) if topics else None
            key = None if layout is None else (layout, B, per, has_full, tuple(cids), tuple(cols))
            plan = None if key is None else PLANS.pop(key, None)
            if plan is None:
                plan = ChunkPlan(topics, cids, cols, B, per, has_full, stamps[:K])
            full, M = plan.full, plan.M
            numbers = plan.numbers(topics, cids, cols, stamps[:K])
            in_full = None if full is None else full.numbers(numbers)
            storage = self.storage
            # the disk blocks of the samples' records, in one call (fewer bytes than follow: the index records)
            reserve(storage.bio, K * B)
            if full is not None:  # each chunk's least and greatest stamp, two passes in all
                starts = np.array([j0 for j0, _ in bounds], np.intp)
                lows, highs = np.minimum.reduceat(stamps[:K], starts), np.maximum.reduceat(stamps[:K], starts)
            for c, (j0, j1) in enumerate(bounds):
                if full is not None and 0 < j0 and j1 < K:  # this chunk's numbers into its one buffer, then out
                    in_full.fill(full.buf, j0, j1 - j0)
                    full.write(storage, int(lows[c]), int(highs[c]))
                    for cid in cids:
                        self.counts[cid] += per
                    continue
                numbers.fill(M.reshape(-1), j0, j1 - j0)
                parts = [first] if j0 == 0 else []
                at = len(first) if j0 == 0 else 0
                index: dict[int, tuple[np.ndarray, np.ndarray]] = {}
                if j0 == 0:
                    index[c_static.id] = (stamps[:1], np.zeros(1, np.int64))
                seg, rel = stamps[j0:j1], at + np.arange(j1 - j0) * B  # every topic's times, offsets less col
                for cid, col in zip(cids, cols):
                    index[cid] = (seg, rel + col)
                parts.append(M[: j1 - j0].reshape(-1))
                at += (j1 - j0) * B
                if j1 == K:  # the last chunk: the end of the run's messages too
                    for cid, rec in zip(tail_idx, tail):
                        t_old, o_old = index.get(cid, (np.zeros(0, np.int64), np.zeros(0, np.int64)))
                        index[cid] = (np.append(t_old, stamps[K]), np.append(o_old, at))
                        parts.append(rec)
                        at += len(rec)
                ts = [stamps[:1]] if j0 == 0 else []  # the chunk's times: /tf_static's, the samples', the end's
                ts += [seg] if j1 > j0 else []
                ts += [stamps[K:S]] if j1 == K and tail else []
                times = (min(int(t.min()) for t in ts), max(int(t.max()) for t in ts)) if ts else None
                storage.write_chunk(parts, {k: v for k, v in index.items() if len(v[0])}, times)
                for cid, (t, _) in index.items():
                    self.counts[cid] += len(t)
            if key is not None:  # kept for the next bag of this layout
                PLANS[key] = plan
                while len(PLANS) > PLANS_KEPT:
                    PLANS.pop(next(iter(PLANS)), None)
            if S:
                self.min_timestamp = min(self.min_timestamp, int(stamps.min()))
                self.max_timestamp = max(self.max_timestamp, int(stamps.max()))

    return BulkWriter, BulkMcap


MSGDEFS_MADE: dict[tuple[int, str], tuple[Any, str, str]] = {}
#: the schema and channel records of a connection (BulkWriter.add_connection), with its type store (held:
#: its id is in the key)
CONNECTION_RECORDS: dict[tuple, tuple[list[Any], Any, bytes, Any]] = {}


def msgdef(store: Any, msgtype: str) -> tuple[Any, str, str]:
    """``(format, definition, RIHS01 hash)`` of ``msgtype`` in the type store ``store`` (made once per
    process and store: ``rosbags`` generates them from its type tables each time, 4 ms a type)."""
    key = (id(store), msgtype)
    if key not in MSGDEFS_MADE:
        from rosbags.interfaces import MessageDefinitionFormat

        text, _ = store.generate_msgdef(msgtype, ros_version=2)
        idl = text.startswith("=" * 80 + "\nIDL: ")
        fmt = MessageDefinitionFormat.IDL if idl else MessageDefinitionFormat.MSG
        MSGDEFS_MADE[key] = (fmt, text, store.hash_rihs01(msgtype))
    return MSGDEFS_MADE[key]


def bulk_writer(*args: Any, **kwargs: Any) -> Any:
    return writer_classes()[0](*args, **kwargs)

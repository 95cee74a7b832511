"""Write output files completely or not at all: write a temporary file beside the target, then rename."""

from __future__ import annotations

import contextlib
import errno
import json
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

_UMASK = os.umask(0)
os.umask(_UMASK)


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path in the target's directory; on success rename it onto ``path``.

    On any exception the temporary file is removed and ``path`` is untouched, so a
    reader never sees a half-written file (SIGKILL leaves at most a hidden ``.tmp``).
    An ``OSError`` on the way (disk full, read-only file system, a file-size limit) becomes a
    :class:`~bioform_mj.core.errors.WriteFailed` naming ``path`` (design §17).
    """
    from bioform_mj.core.errors import WriteFailed

    path = Path(path)
    tmp: str | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)  # checked up front (check_out_file); made only now
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        os.close(fd)
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; give the file the usual permissions
        os.replace(tmp, path)
    except BaseException as exc:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        if isinstance(exc, OSError) and not isinstance(exc, WriteFailed):
            raise WriteFailed(str(path), exc) from exc
        raise


def write_json(path: str | Path, obj: Any) -> None:
    """Atomically write ``obj`` as indented JSON (NaN written as null)."""
    text = json.dumps(_clean(obj), indent=2, allow_nan=False)
    with atomic_path(path) as tmp:
        tmp.write_text(text + "\n", encoding="utf-8")


def write_text(path: str | Path, text: str) -> None:
    """Atomically write a text file."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")  # a C or Latin-1 locale: '²' was an internal error


def rows_to_arrow(rows: list[dict[str, Any]]) -> Any:
    """Rows → a ``pyarrow.Table`` with the union of their columns, as ``sweep.to_csv`` (``runs.parquet``).

    A column whose values are all booleans is boolean, all integers int64, all numbers float64 (missing
    values null); any other column is text (lists and tables as JSON), so a column never changes type
    with the rows it happens to hold."""
    import pyarrow as pa

    cols: list[str] = []
    for r in rows:
        cols += [c for c in r if c not in cols]
    arrays = []
    for c in cols:
        vals = [r.get(c) for r in rows]
        present = [v for v in vals if v is not None]
        if present and all(isinstance(v, bool) for v in present):
            arrays.append(pa.array(vals, type=pa.bool_()))
        elif present and all(isinstance(v, int) and not isinstance(v, bool) for v in present):
            arrays.append(pa.array(vals, type=pa.int64()))
        elif present and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in present):
            arrays.append(pa.array([None if v is None else float(v) for v in vals], type=pa.float64()))
        else:
            text = [None if v is None else (v if isinstance(v, str) else json.dumps(v, default=str)) for v in vals]
            arrays.append(pa.array(text, type=pa.string()))
    return pa.Table.from_arrays(arrays, names=cols)


def write_parquet(path: str | Path, table: Any) -> None:
    """Atomically write a ``pyarrow.Table`` as Parquet."""
    import pyarrow.parquet as pq

    with atomic_path(path) as tmp:
        pq.write_table(table, str(tmp))


def write_npz(path: str | Path, arrays: dict[str, np.ndarray]) -> None:
    """Atomically write a compressed ``.npz``."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)


def _clean(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    if isinstance(obj, np.generic):
        return _clean(obj.item())
    return obj


# ---- output paths checked before any work (design §10: bad input exits 2 before anything runs) ----

#: Trees no output of ours belongs in: kernel and device file systems.
_SPECIAL_ROOTS = ("/proc", "/sys", "/dev")


def _bad(what: str, path: str, why: str) -> Exception:
    from bioform_mj.core.errors import InputError

    return InputError(f"{what} '{path}' {why}")


def _plain_checks(path: str | Path, what: str) -> Path:
    s = str(path)
    if s == "" or s.strip() == "":
        raise _bad(what, s, "is empty")
    if "\x00" in s:
        raise _bad(what, s.replace("\x00", "\\0"), "contains a NUL character")
    if any(c < " " or c == "\x7f" for c in s):  # "outputs in o\nerror: …/" forged a line (issue 28)
        shown = "".join(repr(c)[1:-1] if c < " " or c == "\x7f" else c for c in s)
        raise _bad(what, shown, "holds a control character (a newline would forge lines of bioform's output)")
    p = Path(s)
    try:
        resolved = p.resolve()
    except (OSError, RuntimeError) as exc:  # a symlink loop
        raise _bad(what, s, f"cannot be resolved: {exc}") from None
    try:  # a name over NAME_MAX (255 bytes) or PATH_MAX: Path.is_symlink() raised it (internal error, exit 1)
        os.lstat(p)
    except FileNotFoundError:
        pass
    except OSError as exc:
        if exc.errno in (errno.ENAMETOOLONG, errno.ELOOP, errno.EACCES):
            raise _bad(what, s, f"cannot be looked up ({exc.strerror or exc})") from None
    for root in _SPECIAL_ROOTS:
        if resolved == Path(root) or Path(root) in resolved.parents:
            raise _bad(what, s, f"is under {root}, a special file system, not a place for output files")
    return p


def _nearest_existing(p: Path, what: str, orig: str) -> Path:
    """The deepest existing ancestor of ``p`` (``p`` itself if it exists); a dangling symlink on
    the way is an error, and so is a file where a directory is needed."""
    probe = p
    while True:
        if probe.is_symlink() and not probe.exists():
            raise _bad(what, orig, f"cannot be created: '{probe}' is a dangling symlink (to '{os.readlink(probe)}')")
        if probe.exists():
            break
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        raise _bad(what, orig, f"cannot be created: '{probe}' is not a directory")
    return probe


def _probe_writable(d: Path, what: str, orig: str) -> None:
    """Create and remove a hidden directory in ``d``: the only reliable test (root passes every
    ``os.access`` check, read-only mounts and /proc-like trees refuse only when asked)."""
    try:
        tmp = tempfile.mkdtemp(prefix=".bioform-probe-", dir=d)
    except OSError as exc:
        raise _bad(what, orig, f"is not writable: cannot create anything in '{d}' ({exc.strerror or exc})") from None
    with contextlib.suppress(OSError):
        os.rmdir(tmp)


def check_out_dir(path: str | Path, what: str = "output directory") -> Path:
    """Check that the directory ``path`` exists or can be created, and can be written; create nothing.

    Raises :class:`~bioform_mj.core.errors.InputError` (exit 2) for an empty or NUL-containing
    name, a path under /proc, /sys or /dev, a dangling symlink, a file where a directory is
    needed, or a place the process cannot write.
    """
    orig = str(path)
    p = _plain_checks(path, what)
    if p.is_symlink() and not p.exists():
        raise _bad(what, orig, f"is a dangling symlink (to '{os.readlink(p)}')")
    if p.exists() and not p.is_dir():
        raise _bad(what, orig, "exists and is not a directory")
    _probe_writable(_nearest_existing(p, what, orig), what, orig)
    return p


def check_out_file(path: str | Path, what: str = "output file") -> Path:
    """Check that the file ``path`` can be written (its folder created if need be); create nothing.

    An existing target must be a regular file (never a directory, device or FIFO: the
    atomic rename would replace the node itself); a symlink to one is followed, and the
    resolved path is returned. Raises :class:`~bioform_mj.core.errors.InputError` (exit 2).
    """
    orig = str(path)
    p = _plain_checks(path, what)
    if p.is_symlink():
        if not p.exists():
            raise _bad(what, orig, f"is a dangling symlink (to '{os.readlink(p)}')")
        p = p.resolve()
    if p.exists() and not p.is_file():
        raise _bad(what, orig, "exists and is not a regular file")
    if orig.endswith(os.sep):
        raise _bad(what, orig, "names a directory, not a file")
    _probe_writable(_nearest_existing(p.parent, what, orig), what, orig)
    return p

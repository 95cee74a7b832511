"""numba's on-disk cache, shared by every copy of the same source (docs/design.md §2; issue 28).

numba files a cached kernel in a folder named after the *absolute path* of its source file's folder
(``numba.core.caching._CacheLocator.get_suitable_cache_subpath``) and, before numba 0.62, stamps its index with
the file's ``(mtime, size)``: a second clone of the same commit, a copy in a container, or a reinstall compiled
every kernel again (2-4 minutes) although the cache held them. :class:`PackageLocator`, registered ahead of
numba's own locators by :func:`install`, files the package's kernels by their path *relative to the package*
and stamps each index with the SHA-256 of the source file's bytes:

* the same text anywhere reuses the cache (the folder ``numba.config.CACHE_DIR`` is already keyed by the kernel
  modules' content, :func:`bioform_mj.core.codehash.kernel_hash`; ``core/equations.py`` sets it);
* a changed file misses: numba reads the stamp out of the index and treats an index whose stamp differs as
  empty, so every kernel of that file compiles again and its index is rewritten; numba's index key also holds
  the SHA-256 of the function's bytecode;
* two processes writing at once: numba writes every index and data file to a temporary name and renames it
  over the old one (``os.replace``, atomic), so a reader sees an old or a new file, never a part of one. What
  atomic files leave open is the index's read-modify-write: two processes saving *different* signatures of one
  kernel at once both read the index before either wrote it, both number their data file 1, and the index
  left can name the other signature's machine code. :class:`GuardedCache` (set on every kernel by
  :func:`guard`) saves under an exclusive lock on the kernel's index (``fcntl.flock``; where there is none, as
  numba) and refuses a loaded entry whose signature is not the one asked for (it then compiles, and saves).

Kernels of other packages keep numba's own locators.
"""

from __future__ import annotations

import functools
import hashlib
import os
import stat
import tempfile
from pathlib import Path

from bioform_mj.core.codehash import PACKAGE_ROOT

__all__ = ["GuardedCache", "PackageLocator", "cache_subpath", "guard", "install", "writable_cache_dir"]


def cache_subpath(py_file: str) -> str | None:
    """The folder (inside ``numba.config.CACHE_DIR``) of the kernels of source file ``py_file``: its folder's
    path relative to the package, ``/`` as ``.``, and numba's version (``bioform_mj.plants.mujoco-numba0.68.1``),
    or None for a file outside the package. numba treats an index written by another version as empty and
    overwrites it: without the version, two clones with two numba versions would compile over each other's
    cache on every run (Python's version is in numba's own file names)."""
    try:
        rel = Path(py_file).resolve().parent.relative_to(PACKAGE_ROOT)
    except (ValueError, OSError):
        return None
    return ".".join(("bioform_mj", *rel.parts)) + f"-numba{_NUMBA_VERSION}"


def _cannot_write(path: str) -> str:
    """Why ``path`` (created if missing) cannot hold files; "" where it can."""
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as exc:
        return exc.strerror or str(exc)
    return "" if os.access(path, os.W_OK | os.X_OK) else "not writable"


def writable_cache_dir(preferred: str, name: str) -> tuple[str | None, str]:
    """``(folder, note)``: ``preferred`` where it can be written (note ""), else ``name`` in a private folder of
    this user in the temporary folder (``$TMPDIR/bioform_mj-UID``, mode 0700, owned by the user: a folder another
    user made there is never used, numba's cache files are code), else ``(None, note)``: nothing cached. A read-only
    or foreign home made every import of the package an internal error (numba: "no locator available"; issue 28)."""
    why = _cannot_write(preferred)
    if not why:
        return preferred, ""
    uid = getattr(os, "getuid", lambda: 0)()
    private = os.path.join(tempfile.gettempdir(), f"bioform_mj-{uid}")
    try:
        os.mkdir(private, 0o700)
    except FileExistsError:
        pass
    except OSError:
        return None, f"the compiled kernels are not cached ({preferred!r}: {why}; set NUMBA_CACHE_DIR)"
    st = os.lstat(private)
    mine = stat.S_ISDIR(st.st_mode) and st.st_uid == uid and not st.st_mode & 0o077
    folder = os.path.join(private, name)
    if not mine or _cannot_write(folder):
        return None, f"the compiled kernels are not cached ({preferred!r}: {why}; set NUMBA_CACHE_DIR)"
    return folder, f"the compiled kernels are cached in {folder!r} ({preferred!r}: {why}; set NUMBA_CACHE_DIR)"


@functools.cache
def _file_sha256(path: str, mtime_ns: int, size: int) -> str:
    """SHA-256 of the file's bytes (memoised per ``(path, mtime, size)``: a file edited while the process runs
    is hashed again)."""
    with open(path, "rb") as fh:
        return hashlib.sha256(fh.read()).hexdigest()


try:  # numba is a dependency; without it nothing is cached and install() does nothing
    from numba import __version__ as _NUMBA_VERSION
    from numba.core import config as _config
    from numba.core.caching import FunctionCache as _FunctionCache
    from numba.core.caching import _CacheLocator
except ImportError:  # pragma: no cover
    _CacheLocator = _FunctionCache = object  # type: ignore[assignment,misc]
    _config = None
    _NUMBA_VERSION = ""

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: numba's own behaviour
    fcntl = None  # type: ignore[assignment]


class PackageLocator(_CacheLocator):  # type: ignore[misc,valid-type]
    """Where numba caches a kernel of this package: ``CACHE_DIR/<folder relative to the package>``, stamped with
    the SHA-256 of the source file's bytes (not its path, not its mtime)."""

    def __init__(self, py_func, py_file: str) -> None:
        self._py_file = py_file
        self._lineno = py_func.__code__.co_firstlineno
        self._cache_path = os.path.join(_config.CACHE_DIR, cache_subpath(py_file) or "")

    def get_cache_path(self) -> str:
        return self._cache_path

    def get_source_stamp(self) -> str:
        st = os.stat(self._py_file)
        return "sha256:" + _file_sha256(self._py_file, st.st_mtime_ns, st.st_size)

    def get_disambiguator(self) -> str:
        return str(self._lineno)

    @classmethod
    def from_function(cls, py_func, py_file: str):  # noqa: ANN206 - numba's protocol: an instance or None
        """An instance for a kernel of this package with a cache folder set and writable; None otherwise (numba
        then asks its own locators)."""
        if _config is None or not _config.CACHE_DIR or cache_subpath(py_file) is None or not os.path.isfile(py_file):
            return None
        self = cls(py_func, py_file)
        try:
            self.ensure_cache_path()
        except OSError:
            return None
        return self


def install() -> bool:
    """Put :class:`PackageLocator` first in numba's locator list (once; idempotent). False without numba. Must
    run before the first ``@njit(cache=True)`` of the package: numba picks a kernel's locator when it is
    decorated."""
    if _config is None:  # pragma: no cover
        return False
    from numba.core.caching import CacheImpl

    if PackageLocator not in CacheImpl._locator_classes:
        CacheImpl._locator_classes.insert(0, PackageLocator)
    return True


class GuardedCache(_FunctionCache):  # type: ignore[misc,valid-type]
    """numba's per-kernel disk cache, with its saves serialised and its loads checked (see the module's text)."""

    def load_overload(self, sig, target_context):  # noqa: ANN201 - numba's CompileResult or None
        """numba's load, or None (compile) where the entry's signature is not ``sig``'s."""
        cres = super().load_overload(sig, target_context)
        if cres is None:
            return None
        from numba.core import sigutils

        args, _ = sigutils.normalize_signature(sig)
        return cres if tuple(cres.signature.args) == tuple(args) else None

    def save_overload(self, sig, data) -> None:
        """numba's save (index read, data file numbered, both written), under an exclusive lock on the index."""
        if fcntl is None:  # pragma: no cover
            return super().save_overload(sig, data)
        lock_path = os.path.join(self.cache_path, self._impl.filename_base + ".lock")
        try:
            self._impl.locator.ensure_cache_path()
            fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError:  # a folder that cannot be written: numba's save fails alike and is ignored by numba
            return super().save_overload(sig, data)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            super().save_overload(sig, data)
        finally:
            os.close(fd)  # releases the lock


def guard(dispatcher):  # noqa: ANN001, ANN201 - a numba dispatcher, returned
    """``dispatcher`` (``numba.njit(cache=True)``) with its disk cache a :class:`GuardedCache` (same state: the
    class is swapped, the cache is not built twice); unchanged where it caches nothing or numba is absent."""
    cache = getattr(dispatcher, "_cache", None)
    if _config is not None and type(cache) is _FunctionCache:
        cache.__class__ = GuardedCache
    return dispatcher

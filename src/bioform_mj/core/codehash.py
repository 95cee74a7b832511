"""One code hash of the package (design §16): every hash of our own source is rooted here, at the package.

A module that hashed the files beside itself (``Path(__file__).parent``) would silently hash less once
it moved into a subpackage; every caller asks this module instead, and the root is the package folder.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

#: the package folder, ``…/bioform_mj``
PACKAGE_ROOT = Path(__file__).resolve().parent.parent

#: the modules that hold numba kernels, or source that numba inlines into them: the numba cache is keyed
#: by their text (numba invalidates a cached function only when its own file changes); every module with an
#: ``@njit`` is here (tests/test_core_jitcache.py): the vector environments' kernels call each other's across
#: files, and the fault kernels call the equations
KERNEL_SOURCES = (
    "control/*.py",
    "core/engine.py",
    "core/equations.py",
    "core/jitcache.py",
    "outputs/rosbag_kernel.py",
    "plants/*.py",
    "plants/**/*.py",
    "run/faults.py",
    "envs/*.py",
)


@functools.cache
def source_digest(patterns: tuple[str, ...] = ("**/*.py",)) -> bytes:
    """SHA-256 of the package's source files that match ``patterns`` (globs relative to the package),
    each file's path relative to the package and its bytes, in sorted order; ``__pycache__`` skipped."""
    files = {f for pat in patterns for f in PACKAGE_ROOT.glob(pat) if "__pycache__" not in f.parts and f.is_file()}
    h = hashlib.sha256()
    for f in sorted(files):
        h.update(str(f.relative_to(PACKAGE_ROOT)).encode())
        h.update(b"\0")
        h.update(f.read_bytes())
        h.update(b"\0")
    return h.digest()


@functools.cache
def code_hash() -> str:
    """The whole package's Python source, as 16 hex digits (provenance of results, caches of checks)."""
    return source_digest().hex()[:16]


@functools.cache
def kernel_hash() -> str:
    """The kernel modules' source (:data:`KERNEL_SOURCES`), as 16 hex digits: the numba cache's key."""
    return source_digest(KERNEL_SOURCES).hex()[:16]

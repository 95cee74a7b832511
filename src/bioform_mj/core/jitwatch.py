"""A compile, said before it happens (design §2; issue 28).

numba looks each kernel up in its on-disk cache (``numba.config.CACHE_DIR``, set by ``core/equations.py`` to
``~/.cache/bioform_mj/numba-<hash>``) and compiles only where the cache index holds no entry for the
signature it is called with: its ``"numba:compile"`` event starts exactly then, after the index lookup failed
and before any machine code is generated. :func:`watch` listens for that event and tells its callback once per
burst of compiles (the first top-level compile after ``gap_s`` without one), with an estimate of how long the
burst takes: what was measured for a first run (an empty cache folder) or for a variant (a kernel of an option
that the cache folder does not hold yet). Nothing is guessed from a terminal or a flag: no lookup miss, no call.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field

__all__ = ["COMPILE_S", "CompileBurst", "cache_dir", "cached_kernels", "watch"]

#: Seconds measured for a burst of compiles on the project's 2-core reference machine (shared, load 6-11;
#: numba 0.68, Python 3.11): ``"first"`` a whole first run of ``bioform run paper`` into an empty cache folder
#: (the ideal and the MuJoCo plant's loop and the controller's kernels), ``"variant"`` one option's kernels
#: compiled into a folder that holds the rest. Measured with ``scripts/compile_time.py``.
COMPILE_S: dict[str, float] = {"first": 90.0, "variant": 30.0}


def cache_dir() -> str:
    """The folder numba caches the kernels in (``numba.config.CACHE_DIR``), or "" without numba."""
    try:
        import numba
    except ImportError:  # pragma: no cover
        return ""
    from bioform_mj.core import equations  # noqa: F401 - sets numba.config.CACHE_DIR

    return str(numba.config.CACHE_DIR)


def cached_kernels(folder: str | None = None) -> int:
    """How many cache index files (``*.nbi``, one per compiled kernel) ``folder`` holds for THIS copy of the
    package: numba keeps each source folder's kernels in a subfolder named after that folder's absolute path
    (``numba.core.caching._CacheLocator.get_suitable_cache_subpath``), so a second checkout or a copy of the
    package compiles its own even where the content hash, and so ``folder``, is the same. 0 if none."""
    folder = cache_dir() if folder is None else folder
    if not folder:
        return 0
    from numba.core.caching import _CacheLocator

    from bioform_mj.core.codehash import KERNEL_SOURCES, PACKAGE_ROOT

    dirs = {f.parent for pat in KERNEL_SOURCES for f in PACKAGE_ROOT.glob(pat) if "__pycache__" not in f.parts}
    n = 0
    for d in dirs:
        sub = os.path.join(folder, _CacheLocator.get_suitable_cache_subpath(str(d / "x.py")))
        if os.path.isdir(sub):
            n += sum(f.endswith(".nbi") for f in os.listdir(sub))
    return n


@dataclass
class CompileBurst:
    """One burst of compiles: what started it, where it is cached, the estimate, and (once over) its length."""

    kernel: str  # module.qualname of the first top-level kernel numba found no cache entry for
    cache_dir: str
    first: bool  # the cache folder held no kernel: a first run
    estimate_s: float
    started: float = field(default_factory=time.monotonic)
    seconds: float = math.nan  # wall time from the first compile's start to the last one's end
    kernels: list[str] = field(default_factory=list)  # every top-level kernel compiled in the burst

    def line(self) -> str:
        """The one line the CLI prints on stderr."""
        what = "the loop once" if self.first else "the kernels of an option not compiled before"
        return f"compiling {what} (about {self.estimate_s:.0f} s; cached in {self.cache_dir})"


def watch(notify: Callable[[CompileBurst], None], gap_s: float = 2.0) -> Callable[[], list[CompileBurst]]:
    """Call ``notify(burst)`` at the start of every burst of numba compiles from now on; returns ``stop``,
    which ends the watch and returns the bursts seen (each with its measured ``seconds``).

    ``gap_s`` (s): a top-level compile that starts within this long after the last one ended belongs to the
    same burst (a run's warm-up compiles its kernels one after another)."""
    try:
        from numba.core import event
    except ImportError:  # pragma: no cover - without numba nothing compiles
        return lambda: []

    bursts: list[CompileBurst] = []

    class _Listener(event.Listener):
        depth = 0
        last_end = -math.inf

        def on_start(self, ev: event.Event) -> None:
            if self.depth == 0:
                fn = ev.data["dispatcher"].py_func
                name = f"{fn.__module__}.{fn.__qualname__}"
                if not bursts or time.monotonic() - self.last_end > gap_s:
                    folder = cache_dir()
                    first = cached_kernels(folder) == 0
                    bursts.append(CompileBurst(name, folder, first, COMPILE_S["first" if first else "variant"]))
                    notify(bursts[-1])
                bursts[-1].kernels.append(name)
            self.depth += 1

        def on_end(self, ev: event.Event) -> None:
            self.depth -= 1
            if self.depth == 0:
                self.last_end = time.monotonic()
                bursts[-1].seconds = self.last_end - bursts[-1].started

    listener = _Listener()
    event.register("numba:compile", listener)

    def stop() -> list[CompileBurst]:
        event.unregister("numba:compile", listener)
        return bursts

    return stop

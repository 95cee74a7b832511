"""A compile, said before it happens (design §2; issue 28).

numba looks each kernel up in its on-disk cache (``numba.config.CACHE_DIR``, set by ``core/equations.py`` to
``~/.cache/bioform_mj/numba-<hash>``) and compiles only where the cache index holds no entry for the
signature it is called with: its ``"numba:compile"`` event starts exactly then, after the index lookup failed
and before any machine code is generated. :func:`watch` listens for that event and tells its callback once per
burst of compiles (the first top-level compile after ``gap_s`` without one), with an estimate of how long the
burst takes: what ``scripts/compile_time.py`` measured for the kernel that starts it (:data:`COMPILE_S`).
Nothing is guessed from a terminal or a flag: no lookup miss, no call. :func:`precompile` compiles (or loads)
a kernel for given arguments without calling it: what a first run compiles ahead for an option a later run
would otherwise compile on its own (design §2).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field

__all__ = [
    "COMPILE_S",
    "FIRST_RUN_S",
    "CompileBurst",
    "cache_dir",
    "cached_kernels",
    "estimate_s",
    "precompile",
    "watch",
]

#: Seconds of compiling, measured by ``scripts/compile_time.py`` on the project's 2-core machine shared at load
#: 11-12 (numba 0.68.1, Python 3.11; a quieter machine takes less). A first run into an empty cache folder
#: (:data:`FIRST_RUN_S`): ``run paper --plant ideal`` 160 s (equations, controller, engine, the ideal plant's
#: chunk), ``--plant mujoco`` 226 s (all of that and the MuJoCo plant's kernels; a later ideal or odometry run
#: then compiles nothing). After an ideal first run, by the kernel that starts a burst (the longest matching
#: prefix of its ``module.qualname``): a MuJoCo run's step-by-step kernels 25 s, its chunk 76 s; the odometry
#: reset 2.3 s (now compiled with the MuJoCo chunk, :func:`precompile`).
FIRST_RUN_S: tuple[float, float] = (160.0, 226.0)
COMPILE_S: dict[str, float] = {
    "bioform_mj": 160.0,
    "bioform_mj.plants.mujoco": 25.0,
    "bioform_mj.plants.mujoco.kernels.run_chunk": 76.0,
    "bioform_mj.plants.mujoco.kernels.odometry_reset": 2.3,
}


def estimate_s(kernel: str) -> float:
    """:data:`COMPILE_S` of the longest prefix of ``kernel`` (``module.qualname``) it holds; 30 s for another
    package's kernel."""
    keys = [k for k in COMPILE_S if kernel == k or kernel.startswith(k + ".")]
    return COMPILE_S[max(keys, key=len)] if keys else 30.0


def precompile(dispatcher: Callable, *args: object) -> None:
    """Compile numba ``dispatcher`` for the types of ``args`` without calling it (loaded from the cache where
    its index has them; nothing without numba or with ``NUMBA_DISABLE_JIT``)."""
    compile_ = getattr(dispatcher, "compile", None)
    if compile_ is not None and hasattr(dispatcher, "typeof_pyval"):
        compile_(tuple(dispatcher.typeof_pyval(a) for a in args))


def cache_dir() -> str:
    """The folder numba caches the kernels in (``numba.config.CACHE_DIR``), or "" without numba."""
    try:
        import numba
    except ImportError:  # pragma: no cover
        return ""
    from bioform_mj.core import equations  # noqa: F401 - sets numba.config.CACHE_DIR

    return str(numba.config.CACHE_DIR)


def cached_kernels(folder: str | None = None) -> int:
    """How many cache index files (``*.nbi``, one per compiled kernel) ``folder`` holds for the package's kernels:
    numba keeps each source folder's kernels in a subfolder named after that folder's path relative to the
    package (:func:`bioform_mj.core.jitcache.cache_subpath`), so every copy of the same source shares them. 0 if
    none."""
    folder = cache_dir() if folder is None else folder
    if not folder:
        return 0
    from bioform_mj.core.codehash import KERNEL_SOURCES, PACKAGE_ROOT
    from bioform_mj.core.jitcache import cache_subpath

    dirs = {f.parent for pat in KERNEL_SOURCES for f in PACKAGE_ROOT.glob(pat) if "__pycache__" not in f.parts}
    n = 0
    for d in dirs:
        sub = os.path.join(folder, cache_subpath(str(d / "x.py")) or "")
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

    continued: bool = False  # a later burst of a process whose first burst was a first run's

    def line(self) -> str:
        """The one line the CLI prints on stderr."""
        if self.first:
            lo, hi = FIRST_RUN_S
            return f"compiling the loop once (about {lo:.0f}-{hi:.0f} s; cached in {self.cache_dir})"
        if self.continued:
            return "compiling, continued (within the first run's estimate)"
        return (
            f"compiling the kernels of an option not compiled before (about {self.estimate_s:.0f} s; "
            f"cached in {self.cache_dir})"
        )


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
                    continued = bool(bursts) and (bursts[0].first or bursts[0].continued)
                    est = sum(FIRST_RUN_S) / 2 if first else estimate_s(name)
                    bursts.append(CompileBurst(name, folder, first and not continued, est, continued=continued))
                    notify(bursts[-1])
                bursts[-1].kernels.append(name)
            self.depth += 1

        def on_end(self, ev: event.Event) -> None:
            if self.depth <= 0:  # a compile that started before the watch (another thread): not ours to time
                return
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

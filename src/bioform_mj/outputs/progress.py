"""Progress bars on a terminal (tqdm on stderr), silence everywhere else.

:func:`progress_bar` yields a callback ``cb(k, n)`` (the signature
:func:`bioform_mj.run.simulate.simulate` calls with ``k`` of ``n`` control steps done) when
stderr is a terminal and progress is wanted, and ``None`` otherwise, so a run piped to
a file, a test or CI prints nothing and pays nothing.

The callback also has ``cb.phase(text)``: what the run is doing before (or between) its
steps, shown beside the label, e.g. ``cb.phase("compiling numba kernels (first run only)")``.
A phase ends at ``cb.phase(None)`` or when the count next advances; either way the bar's
clock restarts, so the rate and the time left describe the stepping alone and not the
compile that came before it. ``cb.write(msg)`` prints a line above the bar.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator
from typing import TextIO

ProgressFn = Callable[[int, int], None]


def wanted(enabled: bool = True, stream: TextIO | None = None) -> bool:
    """True when ``enabled`` and ``stream`` (default stderr) is an interactive terminal."""
    stream = sys.stderr if stream is None else stream
    try:
        return bool(enabled) and stream.isatty()
    except (AttributeError, ValueError):  # closed or replaced stream
        return False


@contextlib.contextmanager
def progress_bar(
    label: str, enabled: bool = True, *, unit: str = "%", stream: TextIO | None = None
) -> Iterator[ProgressFn | None]:
    """A tqdm bar labelled ``label`` while the block runs, as a ``cb(k, n)`` callback; ``None`` when not wanted.

    ``unit="%"`` shows percent (for control steps, whose count means little); any other
    unit shows ``k/n unit``. The bar is closed (and its line finished) on leaving the block.
    """
    stream = sys.stderr if stream is None else stream
    if not wanted(enabled, stream):
        yield None
        return
    from tqdm import tqdm

    tqdm.monitor_interval = 0  # no monitor thread: `bioform sweep` forks its workers
    percent = unit == "%"
    bar = tqdm(
        total=100 if percent else 1,
        desc=label,
        file=stream,
        leave=True,
        dynamic_ncols=True,
        unit="%" if percent else unit,
        bar_format="{l_bar}{bar}| {n:.0f}% [{elapsed}<{remaining}]" if percent else None,
    )
    state: dict = {"n": 0, "phase": None}

    def restart_clock() -> None:
        """Rate and time left from now on (what went before, e.g. a compile, does not count)."""
        total, n_now = bar.total, state["n"]
        bar.reset(total=total)
        bar.initial = bar.n = bar.last_print_n = n_now
        bar.refresh()

    def phase(text: str | None) -> None:
        state["phase"] = text or None
        bar.set_description_str(f"{label} — {text}" if text else label, refresh=False)
        restart_clock()

    def cb(k: int, n: int) -> None:
        if percent:
            pos = int(100 * k / max(1, n))
        else:
            if bar.total != n:
                bar.total = n
            pos = int(k)
        if pos != state["n"]:
            if state["phase"] is not None and k < n:  # stepping has begun: the phase is over
                state["n"] = pos
                phase(None)
                return
            bar.update(pos - state["n"])
            state["n"] = pos

    cb.write = lambda msg: bar.write(msg, file=stream)  # type: ignore[attr-defined]
    cb.phase = phase  # type: ignore[attr-defined]
    try:
        yield cb
    finally:
        bar.close()

"""Progress bars on a terminal (tqdm on stderr), silence everywhere else.

:func:`progress_bar` yields a callback ``cb(k, n)`` (the signature
:func:`bioform_mj.sim.simulate` calls with ``k`` of ``n`` control steps done) when
stderr is a terminal and progress is wanted, and ``None`` otherwise, so a run piped to
a file, a test or CI prints nothing and pays nothing.
"""
from __future__ import annotations

import contextlib
import sys
from typing import Callable, Iterator, TextIO

ProgressFn = Callable[[int, int], None]


def wanted(enabled: bool = True, stream: TextIO | None = None) -> bool:
    """True when ``enabled`` and ``stream`` (default stderr) is an interactive terminal."""
    stream = sys.stderr if stream is None else stream
    try:
        return bool(enabled) and stream.isatty()
    except (AttributeError, ValueError):  # closed or replaced stream
        return False


@contextlib.contextmanager
def progress_bar(label: str, enabled: bool = True, *, unit: str = "%", stream: TextIO | None = None
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
    bar = tqdm(total=100 if percent else 1, desc=label, file=stream, leave=True, dynamic_ncols=True,
               unit="%" if percent else unit,
               bar_format="{l_bar}{bar}| {n:.0f}% [{elapsed}<{remaining}]" if percent else None)
    state = {"n": 0}

    def cb(k: int, n: int) -> None:  # (cb.write(msg) prints a line above the bar)
        if percent:
            pos = int(100 * k / max(1, n))
        else:
            if bar.total != n:
                bar.total = n
            pos = int(k)
        if pos != state["n"]:
            bar.update(pos - state["n"])
            state["n"] = pos

    cb.write = lambda msg: bar.write(msg, file=stream)  # type: ignore[attr-defined]
    try:
        yield cb
    finally:
        bar.close()

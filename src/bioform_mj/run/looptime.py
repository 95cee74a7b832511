"""Timing a closed loop, shared by ``jobs/bench.py`` (the CPU benchmark) and ``batch/bench.py`` (the CPU engine
beside the batch engine), below both so that neither imports the other."""

from __future__ import annotations

from typing import Any


def stop_if_interrupted(result: Any) -> Any:
    """``result``, or its interrupt raised again: :func:`simulate` returns the run so far when
    SIGINT/SIGTERM arrives (``RunResult.interrupted``); a caller with more runs to do must stop."""
    exc = getattr(result, "interrupted", None)
    if exc is not None:
        exc.result = result
        raise exc
    return result


def loop_time(sc: Any, reps: int, engine: str = "auto") -> tuple[float, dict]:
    """Loop seconds of :func:`simulate` (best of ``reps``) and the last summary."""
    best, _cpu, summary = loop_times(sc, reps, engine)
    return best, summary


def loop_times(sc: Any, reps: int, engine: str = "auto", plant: Any = None) -> tuple[float, float, dict]:
    """Loop wall seconds and loop CPU seconds (``RunResult.loop_cpu_s``) of :func:`simulate`, each the
    best of ``reps``, and the last summary; ``plant``: one built plant run every time (reset by
    :func:`simulate`; None: each run builds its own)."""
    from bioform_mj.core.errors import quiet_outcomes
    from bioform_mj.run.simulate import simulate

    best, best_cpu, summary = float("inf"), float("inf"), {}
    for _ in range(reps):
        with quiet_outcomes():  # a timing loop (bioform bench): the outcomes are not its report
            r = stop_if_interrupted(simulate(sc, engine=engine, plant=plant))
        summary = r.summary
        best = min(best, float(r.summary["wall_time_s"]))
        best_cpu = min(best_cpu, float(r.loop_cpu_s))
    return best, best_cpu, summary

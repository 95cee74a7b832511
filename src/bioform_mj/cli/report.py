"""What ``bioform run`` prints and records about a finished run (design §9, §10): the warnings of its
robots and outcomes, the one-paragraph summary, and ``resolved.toml``. Used by :mod:`bioform_mj.cli.main`."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any


def _record_toml(summary: dict[str, Any]) -> str:
    """``resolved.toml``: the run's configuration as a scenario file that repeats it (``scenario/record.py``)."""
    from bioform_mj.scenario.record import to_toml

    scale = summary.get("formation_scale", 1.0)
    note = (
        "The resolved configuration of this run (written by bioform run); `bioform run` on this file repeats it\n"
        "bit for bit on the same machine and engine."
        + (
            f"\nLengths are already x formation.scale = {scale:g} of the scenario as written: scale = 1 here."
            if scale != 1
            else ""
        )
        + (
            f"\nTimes are already x formation.time_scale = {summary['time_scale']:g}: time_scale = 1 here."
            if summary.get("time_scale", 1.0) != 1
            else ""
        )
    )
    return to_toml(summary["config"], note)


def _show_robot_warnings() -> None:
    """Print every :class:`~bioform_mj.core.errors.RobotWarning` (issued before a run) as one
    ``warning:`` line on stderr, each time it is issued; likewise each follower's
    :class:`~bioform_mj.core.errors.OutcomeWarning` of a command that does not print outcomes itself
    (``bioform run`` ignores them and prints :func:`_warn_outcomes`' lines; a divergence's is dropped
    here: every command says it as its ``error:`` line, exit 3)."""
    import warnings

    from bioform_mj.core.errors import OutcomeWarning, RobotWarning

    show = warnings.showwarning

    from bioform_mj.robots.sanity import one_line  # a newline in a name must not forge an error: line (issue 28)

    def showwarning(message, category, filename, lineno, file=None, line=None):  # noqa: ANN001
        if issubclass(category, RobotWarning):
            print(f"warning: {one_line(str(message))}", file=sys.stderr)
        elif issubclass(category, OutcomeWarning):
            if getattr(message, "follower", None) is not None:
                print(f"warning: {one_line(str(message))}", file=sys.stderr)
        else:
            show(message, category, filename, lineno, file, line)

    warnings.showwarning = showwarning
    warnings.simplefilter("always", RobotWarning)
    warnings.simplefilter("always", OutcomeWarning)  # each run's, even if another run's read the same


def _warn_outcomes(summary: dict[str, Any]) -> None:
    """A ``warning:`` line on stderr for every outcome of every follower (never silent: design §9,
    §14: a follower 2 m off that also slips gets both); what the scenario asked beyond the robots
    was said before the run."""
    for f in summary["followers"]:
        outcomes = f.get("outcomes")
        if outcomes is None:  # a summary from before the outcomes list
            outcomes = (
                []
                if f.get("outcome", "ok") == "ok"
                else [{"kind": f["outcome"], "detail": f.get("outcome_detail", "")}]
            )
        for o in outcomes:
            print(f"warning: follower {f['id']}: {o['kind']} ({o['detail']})", file=sys.stderr)


def _print_summary(summary: dict[str, Any], out: Path) -> None:
    print(
        f"{summary['scenario']} / {summary['plant']} / {summary['method']}: "
        f"{summary['sim_time_s']:.2f} s simulated in {summary['wall_time_s']:.2f} s"
    )
    for f in summary["followers"]:
        print(
            f"  follower {f['id']}: formation error {f['final_formation_error_m']:.4f} m, "
            f"total velocity error {f['total_velocity_error']:.2f}, "
            f"c_hat {f['c_hat'][0]:.4g}, {f['c_hat'][1]:.4g} (true {f['c_true'][0]:.4g}, {f['c_true'][1]:.4g})"
        )
    print(f"outputs in {out}/")

"""PNG figures of a run and of Table I, in the spirit of the paper's Figs. 2–6.

:func:`run_figures` draws one run (trajectories, tracking errors, estimation errors,
velocity commands against the measured velocities, learning curves of ``ĉ`` with the
true ``c``, velocity errors, torques and ``V_s``); :func:`table1_figures` compares the
four methods of Table I (velocity commands, velocity error with and without learning,
total velocity error beside the paper's, learning curves, trajectories, formation
error). Matplotlib's Agg canvas is used directly (no pyplot, no display); each PNG is
written to a temporary name and renamed.

The colours (``LEADER_RGB``, :func:`follower_rgb`) are shared with the video and the
rerun recording so that follower 2 is the same colour everywhere.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from bioform_mj.control.common import wrap_angles
from bioform_mj.outputs.files import atomic_path

#: Leader colour (the ghost's orange), RGB in 0..1.
LEADER_RGB: tuple[float, float, float] = (1.0, 0.5, 0.05)
#: obstacles (design §19), as the MuJoCo scene colours them
OBSTACLE_RGB: tuple[float, float, float] = (0.45, 0.42, 0.38)
_FOLLOWER_RGB = [
    (0.12, 0.47, 0.71),
    (0.17, 0.63, 0.17),
    (0.84, 0.15, 0.16),
    (0.58, 0.40, 0.74),
    (0.55, 0.34, 0.29),
    (0.89, 0.47, 0.76),
    (0.50, 0.50, 0.50),
    (0.74, 0.74, 0.13),
    (0.09, 0.75, 0.81),
]
#: Colour of each method in the Table I figures.
METHOD_RGB: dict[str, tuple[float, float, float]] = {
    "backstepping": (0.45, 0.45, 0.45),
    "bioinspired": (0.12, 0.47, 0.71),
    "backstepping-learning": (0.58, 0.40, 0.74),
    "bioinspired-learning": (0.84, 0.15, 0.16),
}
_DPI = 110


def follower_rgb(i: int) -> tuple[float, float, float]:
    """Colour of follower ``i`` (0-based), RGB in 0..1 (tab10 without the leader's orange)."""
    return _FOLLOWER_RGB[i % len(_FOLLOWER_RGB)]


def _figure(
    rows: int, cols: int = 1, *, width: float = 8.0, row_h: float = 2.2, sharex: bool = True
) -> tuple[Any, np.ndarray]:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, max(3.0, row_h * rows)), dpi=_DPI, layout="constrained")
    axes = fig.subplots(rows, cols, sharex=sharex, squeeze=False)
    return fig, axes


def _save(fig: Any, path: Path) -> Path:
    """Render ``fig`` with Agg and write it atomically as PNG."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=_DPI)
    return path


def _title(sc_or_summary: Mapping[str, Any]) -> str:
    g = sc_or_summary.get
    return f"{g('scenario', '')} / {g('plant', '')} plant / {g('method', '')}"


# ---------------------------------------------------------------------------- one run
def _log_scale(ax: Any, data: np.ndarray) -> None:
    """A log y axis when ``data`` has a positive finite value; else the linear one (a 1-step run's
    zero errors: matplotlib would warn "Data has no positive values", design §17)."""
    d = np.asarray(data, dtype=float)
    if np.any(np.isfinite(d) & (d > 0)):
        ax.set_yscale("log")


def run_figures(result: Any, out_dir: str | Path) -> list[Path]:
    """Write the figures of one run (a :class:`~bioform_mj.run.simulate.RunResult`) into ``out_dir``; return their
    paths."""
    log, summary = result.log, result.summary
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t = log["t"]
    n = log["pose"].shape[1]
    title = _title(summary)
    paths: list[Path] = []
    if len(t) == 0:
        return paths

    # Fig. 2: trajectories
    paths.append(_save(_trajectories(log, title), out / "trajectories.png"))

    # Fig. 3: tracking errors (body frame) and formation error
    fig, ax = _figure(4)
    labels = ("x̃ (m)", "ỹ (m)", "θ̃ (rad)")
    for r in range(3):
        for i in range(n):
            ax[r, 0].plot(t, log["tracking_error"][:, i, r], color=follower_rgb(i), lw=1.2, label=f"follower {i + 1}")
        ax[r, 0].set_ylabel(labels[r])
    for i in range(n):
        ax[3, 0].plot(t, log["formation_error"][:, i], color=follower_rgb(i), lw=1.2)
    ax[3, 0].set_ylabel("formation\nerror (m)")
    _log_scale(ax[3, 0], log["formation_error"])
    _finish(fig, ax, title + ": tracking errors")
    paths.append(_save(fig, out / "tracking_errors.png"))

    # Fig. 4: estimation errors of the distributed estimators
    lp, lv = log["leader_pose"], log["leader_vel"]
    fig, ax = _figure(4)
    rows = [
        ("position (m)", log["estimation_error"]),
        ("heading (rad)", wrap_angles(log["est_pose"][:, :, 2] - lp[:, None, 2])),
        ("υ_ir − υ_r (m/s)", log["est_vel"][:, :, 0] - lv[:, None, 0]),
        ("ω_ir − ω_r (rad/s)", log["est_vel"][:, :, 1] - lv[:, None, 1]),
    ]
    for r, (lab, y) in enumerate(rows):
        for i in range(n):
            ax[r, 0].plot(t, y[:, i], color=follower_rgb(i), lw=1.2, label=f"follower {i + 1}")
        ax[r, 0].set_ylabel(lab)
    _finish(fig, ax, title + ": estimation errors of the leader's state")
    paths.append(_save(fig, out / "estimation_errors.png"))

    # Fig. 5: velocity commands and measured velocities
    fig, ax = _figure(2)
    _solid_dashed(ax, t, ("υ (m/s)", "ω (rad/s)"), log["cmd"], "command", log["vel"], "measured", lw=0.9, alpha=0.8)
    for r in range(2):
        ax[r, 0].plot(t, lv[:, r], color="k", lw=0.8, ls=":", label="leader")
    _finish(fig, ax, title + ": velocity commands (solid) and velocities (dashed)")
    paths.append(_save(fig, out / "velocities.png"))

    # Fig. 6: learning of c = (a, b)
    fig, ax = _figure(2)
    _solid_dashed(ax, t, ("â (1/(kg·m))", "b̂ (1/(kg·m²))"), log["c_hat"], "estimate", log["c_true"], "true", lw=1.0)
    _finish(fig, ax, title + ": learning of a, b (dashed: true)")
    paths.append(_save(fig, out / "learning.png"))

    # Fig. 7: velocity errors
    fig, ax = _figure(2)
    err = np.abs(log["cmd"] - log["vel"])
    for r, lab in enumerate(("|υ_cmd − υ| (m/s)", "|ω_cmd − ω| (rad/s)")):
        for i in range(n):
            ax[r, 0].plot(t, err[:, i, r], color=follower_rgb(i), lw=1.0, label=f"follower {i + 1}")
        ax[r, 0].set_ylabel(lab)
        _log_scale(ax[r, 0], err[:, :, r])
    _finish(fig, ax, title + ": velocity errors")
    paths.append(_save(fig, out / "velocity_errors.png"))

    # torques and neuron output
    fig, ax = _figure(3)
    # the log holds each interval's mean torque and its min/max (design §9): the line is the
    # mean, the shaded band the chatter envelope, so a chattering torque is not aliased
    env = "tau_min" in log and "tau_max" in log
    for i in range(n):
        for r in range(2):
            ax[r, 0].plot(
                t, log["tau"][:, i, r], color=follower_rgb(i), lw=1.0, label=f"follower {i + 1}" if r == 0 else None
            )
            if env:
                ax[r, 0].fill_between(
                    t, log["tau_min"][:, i, r], log["tau_max"][:, i, r], color=follower_rgb(i), alpha=0.18, lw=0
                )
        ax[2, 0].plot(t, log["vs"][:, i], color=follower_rgb(i), lw=1.2)
    ax[0, 0].set_ylabel("τ_L (N·m)")
    ax[1, 0].set_ylabel("τ_R (N·m)")
    ax[2, 0].set_ylabel("V_s")
    what = "line: interval mean, band: min..max" if env else "point samples"
    _finish(fig, ax, title + f": torques ({what}), V_s")
    paths.append(_save(fig, out / "torques.png"))
    return paths


def _solid_dashed(
    ax: Any,
    t: np.ndarray,
    labels: tuple[str, str],
    solid: np.ndarray,
    solid_name: str,
    dashed: np.ndarray,
    dashed_name: str,
    **dashed_style: Any,
) -> None:
    """Panel ``r`` (y label ``labels[r]``): channel ``r`` of ``solid`` (K, n, 2) as each follower's solid line
    and of ``dashed`` (K, n, 2) as its dashed line (``dashed_style``: further line keywords, e.g. ``lw``)."""
    for r, lab in enumerate(labels):
        for i in range(solid.shape[1]):
            ax[r, 0].plot(t, solid[:, i, r], color=follower_rgb(i), lw=1.4, label=f"follower {i + 1} {solid_name}")
            ax[r, 0].plot(
                t,
                dashed[:, i, r],
                color=follower_rgb(i),
                ls="--",
                label=f"follower {i + 1} {dashed_name}",
                **dashed_style,
            )
        ax[r, 0].set_ylabel(lab)


def _trajectories(log: Mapping[str, np.ndarray], title: str, ax: Any = None) -> Any:
    """Leader and follower paths with the formation drawn at a few instants (Fig. 2)."""
    fig = None
    if ax is None:
        from matplotlib.figure import Figure

        fig = Figure(figsize=(8.0, 6.0), dpi=_DPI, layout="constrained")
        ax = fig.subplots()
    t, pose, lp = log["t"], log["pose"], log["leader_pose"]
    n = pose.shape[1]
    offsets = np.asarray(log["offsets"], dtype=float) if "offsets" in log else np.zeros((n, 2))
    ax.plot(lp[:, 0], lp[:, 1], color=LEADER_RGB, lw=2.0, ls="--", label="leader")
    if "obstacles" in log and len(log["obstacles"]):  # design §19: their footprints
        from bioform_mj.formation.obstacles import from_rows

        for k, ob in enumerate(from_rows(log["obstacles"])):
            xy = ob.outline()
            ax.fill(xy[:, 0], xy[:, 1], color=OBSTACLE_RGB, alpha=0.7, lw=0, label="obstacles" if k == 0 else None)
    for i in range(n):
        ax.plot(pose[:, i, 0], pose[:, i, 1], color=follower_rgb(i), lw=1.5, label=f"follower {i + 1}")
        ax.plot(pose[0, i, 0], pose[0, i, 1], "o", color=follower_rgb(i), ms=5)
    for k in np.unique(np.linspace(0, len(t) - 1, 5).round().astype(int)):
        slots = log["slots"][k] if "slots" in log else lp[k, None, :2] - offsets
        for i in range(n):
            ax.plot([lp[k, 0], pose[k, i, 0]], [lp[k, 1], pose[k, i, 1]], color="0.6", lw=0.7, zorder=1)
            ax.plot(slots[i, 0], slots[i, 1], "x", color=follower_rgb(i), ms=6, mew=1.2)
            _arrow(ax, pose[k, i], follower_rgb(i))
        _arrow(ax, lp[k], LEADER_RGB)
        ax.annotate(f"{t[k]:.0f} s", (lp[k, 0], lp[k, 1]), textcoords="offset points", xytext=(4, 6), fontsize=8)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    ax.set_title(
        title + ": trajectories (× formation slots, arrows: headings)" if fig is not None else title, fontsize=10
    )
    return fig


def _arrow(ax: Any, pose: np.ndarray, rgb: tuple[float, float, float], length: float = 0.6) -> None:
    ax.annotate(
        "",
        xy=(pose[0] + length * np.cos(pose[2]), pose[1] + length * np.sin(pose[2])),
        xytext=(pose[0], pose[1]),
        arrowprops=dict(arrowstyle="->", color=rgb, lw=1.5),
    )


def _finish(fig: Any, ax: np.ndarray, title: str, *, legend: bool = True) -> None:
    for a in ax.ravel():
        a.grid(True, alpha=0.3)
    for a in ax[-1, :]:
        a.set_xlabel("t (s)")
    if legend and ax.shape[1] > 1:  # one legend for the row of panels, below them
        handles, labels = ax[0, 0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="outside lower center", ncol=min(4, max(1, len(labels))), fontsize=8)
    elif legend:
        ax[0, 0].legend(fontsize=7, ncol=3, loc="best")
    fig.suptitle(title, fontsize=10)


# ---------------------------------------------------------------------------- Table I
def table1_figures(
    results_by_method: Mapping[str, Any], out_dir: str | Path, paper_table: Mapping[str, Any] | None = None
) -> list[Path]:
    """Figures comparing the methods of Table I (``{method: RunResult}``); returns the paths written.

    ``paper_table`` is the paper's own Table I (:data:`bioform_mj.jobs.table1.PAPER_TABLE1`), drawn beside
    ours; the caller passes it (this module is a floor below ``jobs``); ``None``: ours alone."""
    paper_table = paper_table or {}

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    methods = [m for m in METHOD_RGB if m in results_by_method] + [m for m in results_by_method if m not in METHOD_RGB]
    if not methods:
        return []
    logs = {m: results_by_method[m].log for m in methods}
    first = results_by_method[methods[0]].summary
    title = f"{first.get('scenario', '')} / {first.get('plant', '')} plant"
    n = logs[methods[0]]["pose"].shape[1]
    color = {m: METHOD_RGB.get(m, follower_rgb(j)) for j, m in enumerate(methods)}
    paths: list[Path] = []

    # velocity commands of the methods (paper Fig. 4)
    fig, ax = _figure(2, n, width=4.0 * n + 1, row_h=2.6)
    for i in range(n):
        for m in methods:
            lg = logs[m]
            for r in range(2):
                ax[r, i].plot(lg["t"], lg["cmd"][:, i, r], color=color[m], lw=1.2, label=m)
        ax[0, i].set_title(f"follower {i + 1}", fontsize=9)
    ax[0, 0].set_ylabel("υ_cmd (m/s)")
    ax[1, 0].set_ylabel("ω_cmd (rad/s)")
    _finish(fig, ax, title + ": velocity commands of the methods")
    paths.append(_save(fig, out / "table1_velocity_commands.png"))

    # velocity error with and without learning (paper Fig. 6)
    pairs = [
        (a, b)
        for a, b in (("bioinspired", "bioinspired-learning"), ("backstepping", "backstepping-learning"))
        if a in logs and b in logs
    ]
    if pairs:
        fig, ax = _figure(len(pairs), n, width=4.0 * n + 1, row_h=2.6)
        for r, pair in enumerate(pairs):
            for i in range(n):
                for m in pair:
                    lg = logs[m]
                    e = np.abs(lg["cmd"][:, i] - lg["vel"][:, i]).sum(axis=1)
                    ax[r, i].plot(lg["t"], e, color=color[m], lw=1.0, label=m)
                ax[r, i].set_yscale("log")
                ax[0, i].set_title(f"follower {i + 1}", fontsize=9)
            ax[r, 0].set_ylabel("|υ_cmd−υ| + |ω_cmd−ω|")
            ax[r, 0].legend(fontsize=7, loc="best")
        _finish(fig, ax, title + ": velocity error with and without learning", legend=False)
        paths.append(_save(fig, out / "table1_velocity_error_learning.png"))

    # total velocity error, ours beside the paper's (Table I)
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8.0, 4.5), dpi=_DPI, layout="constrained")
    ax1 = fig.subplots()
    width = 0.8 / len(methods)
    x = np.arange(n)
    for j, m in enumerate(methods):
        ours = [f["total_velocity_error"] for f in results_by_method[m].summary["followers"]]
        ax1.bar(x + (j - (len(methods) - 1) / 2) * width, ours, width * 0.9, color=color[m], label=m)
        paper = paper_table.get(m)
        if paper is not None and n == len(paper):
            ax1.plot(
                x + (j - (len(methods) - 1) / 2) * width,
                paper,
                "_",
                color="k",
                ms=14,
                mew=2,
                label="paper" if j == 0 else None,
            )
    ax1.set_xticks(x, [f"follower {i + 1}" for i in range(n)])
    ax1.set_ylabel("∫ |υ_cmd−υ| + |ω_cmd−ω| dt")
    ax1.set_yscale("log")
    ax1.grid(True, axis="y", alpha=0.3)
    ax1.legend(fontsize=8)
    ax1.set_title(title + ": total velocity error (bars: ours, black ticks: paper)", fontsize=10)
    paths.append(_save(fig, out / "table1_total_velocity_error.png"))

    # learning curves of the learning methods (paper Fig. 5)
    learners = [m for m in methods if m.endswith("-learning")]
    if learners:
        fig, ax = _figure(2, len(learners), width=5.0 * len(learners) + 1, row_h=2.6)
        for c, m in enumerate(learners):
            lg = logs[m]
            for r in range(2):
                for i in range(n):
                    ax[r, c].plot(
                        lg["t"], lg["c_hat"][:, i, r], color=follower_rgb(i), lw=1.3, label=f"follower {i + 1}"
                    )
                    ax[r, c].plot(lg["t"], lg["c_true"][:, i, r], color=follower_rgb(i), lw=0.9, ls="--")
            ax[0, c].set_title(m, fontsize=9)
        ax[0, 0].set_ylabel("â (1/(kg·m))")
        ax[1, 0].set_ylabel("b̂ (1/(kg·m²))")
        _finish(fig, ax, title + ": learning of a, b (dashed: true)")
        paths.append(_save(fig, out / "table1_learning.png"))

    # trajectories of each method
    cols = 2 if len(methods) > 1 else 1
    rows = (len(methods) + cols - 1) // cols
    fig = Figure(figsize=(6.0 * cols, 4.6 * rows), dpi=_DPI, layout="constrained")
    axs = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    for a, m in zip(axs, methods):
        _trajectories(logs[m], m, ax=a)
    for a in axs[len(methods) :]:
        a.set_visible(False)
    fig.suptitle(title + ": trajectories", fontsize=10)
    paths.append(_save(fig, out / "table1_trajectories.png"))

    # formation error of each method
    fig, ax = _figure(1, n, width=4.0 * n + 1, row_h=3.2)
    for i in range(n):
        for m in methods:
            ax[0, i].plot(logs[m]["t"], logs[m]["formation_error"][:, i], color=color[m], lw=1.1, label=m)
        ax[0, i].set_yscale("log")
        ax[0, i].set_title(f"follower {i + 1}", fontsize=9)
    ax[0, 0].set_ylabel("formation error (m)")
    _finish(fig, ax, title + ": formation error")
    paths.append(_save(fig, out / "table1_formation_error.png"))
    return paths

"""The outputs a run may write beside its record (summary.json, log.npz, resolved.toml, scene.xml), each
registered once (design §22): its name (the ``bioform run`` flag is ``--NAME``), its help line, the files and
folders it writes into the run folder (those ``--overwrite`` may remove, :mod:`bioform_mj.outputs.rundir`), and
its writer, imported only when asked for.

A writer is named ``"module:function"`` and called after the run as
``write(result, out, watcher=None, options=None, progress=None) -> str``: it writes its files into the folder
``out`` (atomically) and returns the line the CLI prints (``"run.rrd written in 0.4 s"``). One that must watch
the run (the video's snapshots) also names ``watcher``, ``"module:function"`` called as ``watch(options)``
before the run for an observer (``run/simulate.py: Observer``), which its writer then receives. A writer
raises :class:`~bioform_mj.core.errors.InputError` for what it cannot make (no OpenGL context): the CLI says
it as an ``error:`` line and exits 2, the run's record kept.

One more output is one line here::

    register_output(Output("bag", "write bag/ (a format)", (), "mypkg.bag:write", dirs=(("bag", (".db",)),)))
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import import_module
from typing import Any


@dataclass(frozen=True)
class Output:
    """One output a run may write (see the module docstring).

    name: the flag's name (``--NAME``) and the key of :data:`OUTPUTS`; help: the flag's help line;
    files: the file names it writes into the run folder; writer, watcher: ``"module:function"``;
    dirs: ``(folder, suffixes)`` pairs of the folders it writes (``("figures", (".png",))``);
    progress_unit: the unit of a progress bar while it writes (``"frame"``), "" for none.
    """

    name: str
    help: str
    files: tuple[str, ...] = ()
    writer: str = ""
    watcher: str = ""
    dirs: tuple[tuple[str, tuple[str, ...]], ...] = ()
    progress_unit: str = ""

    @property
    def flag(self) -> str:
        """The ``bioform run`` flag: ``--NAME``."""
        return "--" + self.name

    @property
    def dest(self) -> str:
        """The flag's attribute on the parsed arguments."""
        return self.name.replace("-", "_")

    def write(self, result: Any, out: Any, watcher: Any = None, options: Any = None, progress: Any = None) -> str:
        """Write this output of the finished run ``result`` into the folder ``out``; returns the CLI's line.

        Parameters
        ----------
        result : RunResult
            The run (its log, summary, plant).
        out : Path
            The run folder.
        watcher : Observer or None
            What :meth:`watch` made before the run.
        options : Any
            The output's own options (the video's size and frame rate), or None.
        progress : callable or None
            ``progress(k, K)`` while it writes (with ``progress_unit``).
        """
        return _resolve(self.writer)(result, out, watcher=watcher, options=options, progress=progress)

    def watch(self, options: Any = None) -> Any:
        """The observer to run with the loop (None for an output that reads only the finished run).

        Parameters
        ----------
        options : Any
            The output's own options, or None.
        """
        return _resolve(self.watcher)(options) if self.watcher else None


def _resolve(ref: str) -> Any:
    module, _, attr = ref.partition(":")
    return getattr(import_module(module), attr)


#: every registered output by name, in the order of the CLI's flags and of writing
OUTPUTS: dict[str, Output] = {}


def register_output(output: Output) -> None:
    """Register ``output``: ``bioform run`` gets its flag, ``--overwrite`` its files (design §22).

    Parameters
    ----------
    output : Output
        Its name, flag and files must be new, and its writer named as ``"module:function"``.
    """
    if output.name in OUTPUTS:
        raise ValueError(f"output {output.name!r} is registered already")
    taken = output_files() & set(output.files) | set(output_dirs()) & {d for d, _ in output.dirs}
    if taken:
        raise ValueError(f"output {output.name!r}: {', '.join(sorted(taken))} written by another output already")
    if ":" not in output.writer:
        raise ValueError(f"output {output.name!r}: writer must be 'module:function', got {output.writer!r}")
    OUTPUTS[output.name] = output


def output_files() -> frozenset[str]:
    """The file names the registered outputs write into a run folder."""
    return frozenset(f for o in OUTPUTS.values() for f in o.files)


def output_dirs() -> dict[str, tuple[str, ...]]:
    """The folders the registered outputs write into a run folder, with the file suffixes they hold."""
    return {d: sfx for o in OUTPUTS.values() for d, sfx in o.dirs}


register_output(
    Output(
        "video",
        "write video.mp4 (off-screen MuJoCo rendering, MUJOCO_GL=egl by default; the ideal plant is shown in a "
        "composed scene)",
        ("video.mp4",),
        "bioform_mj.outputs.video:write_video",
        watcher="bioform_mj.outputs.video:frame_capture",
        progress_unit="frame",
    )
)
register_output(Output("rrd", "write run.rrd (rerun recording)", ("run.rrd",), "bioform_mj.outputs.rerun_log:write"))
register_output(
    Output("figures", "write figures/*.png", (), "bioform_mj.outputs.figures:write", dirs=(("figures", (".png",)),))
)
register_output(
    Output(
        "rosbag",
        "write rosbag/: the run as a ROS 2 bag (ros extra; --ros-distro)",
        (),
        "bioform_mj.outputs.rosbag:write",
        dirs=(("rosbag", (".yaml", ".mcap")),),
    )
)

"""Where a command writes when ``--out`` is not given (design §10; issue 28): one folder per configuration.

``bioform run PRESET`` writes ``runs/PRESET-PLANT-METHOD`` (``table1``: ``runs/table1-PLANT``); a command whose
``--set`` (other than ``--set name=…``, which names the folder), ``--duration``, ``--seed``,
``--package-path``, ``--xacro-arg`` or ``--control-rate`` change the configuration writes
``runs/PRESET-PLANT-METHOD-<8 hex digits>`` instead, the start of the run's content key (a hash of the resolved
configuration and seed, :func:`bioform_mj.jobs.sweep.content_key`), so a second run of a different configuration
never lands on the first one's folder. The same configuration twice lands on the same folder, which then holds
an earlier run: refused, saying ``--overwrite`` or ``--out`` (:class:`bioform_mj.outputs.rundir.RunDir`).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from bioform_mj.core.errors import InputError

__all__ = ["HASH_DIGITS", "default_name", "out_path", "prepare_out", "claim", "path_arg"]

#: hex digits of the configuration hash in a default folder's name (32 bits: two configurations of one
#: preset share a name with probability ~2e-10)
HASH_DIGITS = 8


def path_arg(text: str) -> Path:
    """``type=`` of the path options (``--out``, ``--json``): ``Path(text)``, an empty one refused (``Path("")`` is
    the current folder: ``--out ""`` wrote, or was refused, as '.')."""
    if not text:
        raise argparse.ArgumentTypeError("an empty path (give a folder or file name)")
    return Path(text)


def changes_configuration(args: argparse.Namespace) -> bool:
    """True when the command line changes the named scenario's configuration beyond plant, method and name
    (``--set name=…`` names the folder itself)."""
    sets = [o for o in getattr(args, "overrides", None) or () if o.partition("=")[0].strip() != "name"]
    return bool(
        sets
        or getattr(args, "duration", None) is not None
        or getattr(args, "seed", None) is not None
        or getattr(args, "package_path", None)
        or getattr(args, "xacro_arg", None)
        or getattr(args, "control_rate", None) is not None
    )


def default_name(args: argparse.Namespace, sc: Any, stem: str) -> str:
    """``stem``, or ``stem-<hash>`` when :func:`changes_configuration` (the hash of the resolved scenario ``sc``)."""
    if not changes_configuration(args):
        return stem
    from bioform_mj.jobs.sweep import content_key

    return f"{stem}-{content_key(sc)[:HASH_DIGITS]}"


def out_path(out: Path | None, default: str) -> Path:
    """``--out``, or ``runs/<default>`` (``default`` is built from a validated plain file name)."""
    if out is not None:
        return Path(out)
    if Path(default).name != default or default in ("", ".", ".."):  # scenario.validate makes this unreachable
        raise InputError(f"output name '{default}' is not a plain file name")
    return Path("runs") / default


def prepare_out(out: Path | None, default: str) -> Path:
    """Check that the output directory can be created or written, without creating it yet.

    Nothing is written before the run has validated its input and built its plant,
    so bad input leaves no directory behind; call ``.mkdir`` just before writing.
    """
    from bioform_mj.outputs.files import check_out_dir

    return check_out_dir(out_path(out, default))


def claim(out: Path | None, default: str, overwrite: bool) -> Any:
    """The run folder, checked now (exit 2 before any work): writable, and empty or holding only
    an earlier run's files, which ``--overwrite`` allows to replace."""
    from bioform_mj.outputs.rundir import RunDir

    return RunDir(out_path(out, default), overwrite=overwrite).check()

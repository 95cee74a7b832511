"""The MJCF robot format (design §12, §13.2): a MuJoCo model file read as published, its keyframe baked in.

:func:`load_mjcf` is the format's loader in the robot-format registry (:mod:`bioform_mj.robots.formats`),
:func:`published_mjcf` its published model, :func:`editable_mjcf` the spec a calibrated copy is written from;
:func:`absolute_asset_files` makes its asset file names absolute. Importing it imports no MuJoCo (the registry is
asked whether a scenario's entry is a path before any model is read).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from bioform_mj.robots.refs import RobotRef

if TYPE_CHECKING:
    import mujoco

__all__ = ["absolute_asset_files", "editable_mjcf", "load_mjcf", "open_compiled", "published_mjcf"]


def load_mjcf(ref: RobotRef, path: Path) -> tuple[Any, ...]:
    """``(spec, model, ref, import notes, keyframe, keyframe qpos, keyframe notes)`` of the MJCF file ``path``
    (compiled; the mapping's ``balance_inertia`` applied; the keyframe of design §13.2 baked in). Raises
    :class:`~bioform_mj.robots.layout.ModelError` (exit 2) naming the file."""
    from bioform_mj.robots.keyframe import apply_keyframe

    spec, model = open_compiled(ref, path)
    absolute_asset_files(spec)
    spec, model, key, key_q, key_notes = apply_keyframe(spec, model, path, ref)  # design §13.2
    return spec, model, ref, (), key, key_q, key_notes


def open_compiled(ref: RobotRef, path: Path) -> tuple[mujoco.MjSpec, mujoco.MjModel]:
    """``(spec, model)`` of the MJCF file ``path`` as the robot's mapping reads it: its includes and assets
    inside its folder or ``asset_roots`` (design §12), ``balance_inertia`` applied, no special file, compiled.
    Raises :class:`~bioform_mj.robots.layout.ModelError` (exit 2) naming the file."""
    from bioform_mj.core.errors import InputError
    from bioform_mj.robots.layout import ModelError, _one_line
    from bioform_mj.robots.mjcf_assets import open_mjcf  # includes and assets inside its folder (design §12)
    from bioform_mj.robots.sanity import spec_file_problem  # a FIFO or a 10 GB mesh: before the compiler opens it

    try:
        spec = open_mjcf(path, ref.asset_roots)
        if ref.balance_inertia:  # the mapping's balance_inertia (design §12)
            spec.compiler.balanceinertia = True
        bad = spec_file_problem(spec)
        model = None if bad else spec.compile()
    except InputError as exc:  # an asset outside the robot's folder, a FIFO: before MuJoCo read it
        raise ModelError(str(exc)) from None
    except Exception as exc:  # mujoco raises ValueError; be robust to other types
        from bioform_mj.robots.compile_hints import compile_hint

        raise ModelError(f"{path}: does not compile: {_one_line(exc)}{compile_hint(exc)}") from exc
    if bad:
        raise ModelError(f"{path}: {bad}")
    return spec, model


def published_mjcf(ref: RobotRef) -> mujoco.MjModel:
    """The robot's MJCF as it stands (no keyframe baked in): the format's published model
    (:mod:`bioform_mj.robots.formats`), read as :func:`open_compiled` reads it."""
    return open_compiled(ref, Path(ref.model))[1]


def editable_mjcf(ref: RobotRef) -> mujoco.MjSpec:
    """The robot's MJCF as published, uncompiled, its asset file names absolute: the spec ``bioform robot fit``
    writes a calibrated copy from (the format's ``editable``, :mod:`bioform_mj.robots.formats`); its includes and
    assets inside its folder or ``asset_roots`` (design §12)."""
    from bioform_mj.robots.mjcf_assets import open_mjcf

    spec = open_mjcf(ref.model, ref.asset_roots)
    absolute_asset_files(spec)
    return spec


def absolute_asset_files(spec: mujoco.MjSpec) -> None:
    """Make the spec's mesh, skin, height-field and texture file names absolute (resolved against
    the model file's folder and its ``meshdir``/``texturedir``), so that a scene composed of robots
    from many folders names each file once and wholly (design §12: a run's ``scene.xml`` copies
    them beside it, :func:`bioform_mj.outputs.scenexml.write_scene`). Files in the spec's own
    asset dictionary are left alone."""
    from bioform_mj.robots.spec_files import spec_files

    top = Path(spec.modelfiledir or ".")
    for f in list(spec_files(spec)):
        if not Path(f.name).is_absolute():
            f.rename(str((top / f.folder / f.name).resolve()))

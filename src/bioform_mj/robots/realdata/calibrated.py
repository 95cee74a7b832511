"""The calibrated robot file ``bioform robot fit`` writes, and what ``robot check`` says of one (issue 29).

:func:`write_calibrated` loads the robot file as published, its format's ``editable`` spec
(:mod:`bioform_mj.robots.formats`: an MJCF as is; a URDF as the project imports it, design §12), writes the
fitted values into it by name (the chassis body's mass and yaw inertia, :func:`~.chassis.chassis_body`; the wheel
joints' damping, frictionloss and armature, the casters' friction) and saves it as MJCF. The file carries where its
numbers came from as the custom text ``bioform_calibration`` (one line: the recording, the date, each value and
whether the recording identified it); :func:`calibration_note` reads it back from a compiled scene, for
``robot check``'s notes.
"""

from __future__ import annotations

import datetime as _dt
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from bioform_mj.robots.layout import CONTACT_PRIORITY
from bioform_mj.robots.refs import RobotRef

__all__ = ["CALIBRATION_TEXT", "write_calibrated", "calibration_note", "assets_folder"]

#: name of the custom text a calibrated robot file carries
CALIBRATION_TEXT = "bioform_calibration"


def _source_spec(ref: RobotRef) -> mujoco.MjSpec:
    """The robot as published, uncompiled, from its format's ``editable`` (:mod:`bioform_mj.robots.formats`; an
    MJCF as is, a URDF as the project imports it). Raises :class:`~bioform_mj.robots.layout.ModelError` (exit 2)
    for a format that cannot give one."""
    from bioform_mj.robots.formats import format_of
    from bioform_mj.robots.layout import ModelError

    fmt = format_of(ref.model)
    if fmt.editable is None:
        raise ModelError(
            f"{ref.model}: the robot format '{fmt.name}' cannot give a spec to write a calibrated copy from"
        )
    return fmt.editable(ref)


def write_calibrated(
    ref: RobotRef, layout: Any, rows: list[dict[str, Any]], caster_geoms: list[str], path: Path, source: str
) -> None:
    """Write ``ref``'s robot with the fitted values of ``rows`` (fit.json's ``parameters``) to ``path``."""
    from bioform_mj.robots.realdata.chassis import chassis_body, explicit_base, set_yaw_inertia

    spec = _source_spec(ref)
    val = {r["name"]: r["fitted"] for r in rows}
    chassis = chassis_body(spec.compile(), layout.base)  # as the fit chose it
    axis, _ = explicit_base(spec, chassis)
    body = spec.body(chassis)
    if "mass" in val:
        body.mass = float(val["mass"])
    if "yaw_inertia" in val:
        set_yaw_inertia(body, axis, float(val["yaw_inertia"]))
    for side, j in zip(("L", "R"), layout.wheel_joints):
        el = spec.joint(j)
        if f"damping_{side}" in val:
            d = np.array(el.damping, float)
            d[0] = float(val[f"damping_{side}"])
            el.damping = d
        if f"frictionloss_{side}" in val:
            el.frictionloss = float(val[f"frictionloss_{side}"])
        if f"armature_{side}" in val:
            el.armature = float(val[f"armature_{side}"])
    if "caster_friction" in val:
        for g in caster_geoms:
            el = spec.geom(g)
            if el is None:
                continue
            fr = np.array(el.friction, float)
            fr[0] = float(val["caster_friction"])
            el.friction = fr
            el.condim = 3
            el.priority = CONTACT_PRIORITY
    when = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC")
    values = ", ".join(
        f"{r['name']} {r['fitted']:.4g} {r['unit']}".rstrip()
        + ("" if r["status"] == "identified" else f" ({r['status']})")  # not identified, negligible
        for r in rows
    )
    note = f"fitted by bioform robot fit from {source} on {when}: {values} (published: {Path(ref.model).name})"
    for t in list(spec.texts):
        if t.name == CALIBRATION_TEXT:
            spec.delete(t)
    spec.add_text(name=CALIBRATION_TEXT, data=note)
    folder, copied = _bundle_assets(spec, ref, path)
    spec.compile()  # refuse to write a file that would not load
    text = spec.to_xml()
    if copied:  # the copies by their path relative to the calibrated file: the folder can move as a whole
        text = text.replace(f'file="{folder}/', f'file="{folder.name}/')
    path.write_text(text, encoding="utf-8")


def assets_folder(path: Path) -> Path:
    """The folder beside the calibrated file ``path`` that holds copies of the robot's asset files."""
    return path.with_name(path.stem + "_assets")


def _bundle_assets(spec: mujoco.MjSpec, ref: RobotRef, path: Path) -> tuple[Path, list[Path]]:
    """Copy every file the robot's meshes, textures, height fields and skins read into
    :func:`assets_folder` and point the spec at the copies (absolute here; :func:`write_calibrated` writes them
    relative). A calibrated TIAGo (menagerie MJCF, one STL) named its mesh by the published file's absolute
    path, which the loader refuses as outside the robot's folder (design §12): the fit ended on that error
    after its work, its calibrated file left behind. Returns the folder and the copies made."""
    import shutil

    folder = assets_folder(path).resolve()
    root = Path(spec.modelfiledir or Path(ref.model).parent)
    copied: list[Path] = []
    names: dict[Path, Path] = {}
    groups = [
        (spec.meshes, spec.meshdir),
        (spec.skins, spec.meshdir),
        (spec.hfields, ""),
        (spec.textures, spec.texturedir),
    ]
    for elements, sub in groups:
        for el in elements:
            if not el.file:
                continue
            src = Path(el.file) if Path(el.file).is_absolute() else root / (sub or "") / el.file
            src = src.resolve()
            if src not in names:
                dst = folder / src.name
                k = 1
                while dst in names.values():  # two files of one name from different folders
                    dst = folder / f"{src.stem}_{k}{src.suffix}"
                    k += 1
                folder.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(src, dst)
                names[src] = dst
                copied.append(dst)
            el.file = str(names[src])
    if copied:
        spec.meshdir = ""
        spec.texturedir = ""
    return folder, copied


def calibration_note(model: mujoco.MjModel, prefix: str = "f1/") -> list[str]:
    """``robot check``'s note on where a calibrated robot's numbers came from (empty for any other)."""
    tid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TEXT, prefix + CALIBRATION_TEXT)
    if tid < 0:
        tid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TEXT, CALIBRATION_TEXT)
    if tid < 0:
        return []
    adr, size = int(model.text_adr[tid]), int(model.text_size[tid])
    text = bytes(model.text_data[adr : adr + size]).split(b"\0", 1)[0].decode(errors="replace")
    return [f"calibrated robot: {text}"]

"""``bioform robot check`` (design §10, §13): the robot's mapping flags, the subcommand's parser and what it prints.
The check itself is :func:`bioform_mj.assess.check.check`; this module only reads arguments and prints."""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from typing import Any

from bioform_mj.assess.check import EXIT_FAIL, check
from bioform_mj.robots.refs import RobotRef
from bioform_mj.robots.xacro_sandbox import add_flags as add_xacro_flags

#: a robot table's key → the ``robot check``/``identify`` flag that sets it (issue 28: errors in the CLI's terms)
FLAG_OF = {
    "left_wheel": "--left-wheel",
    "right_wheel": "--right-wheel",
    "base": "--base",
    "tau_max": "--tau-max",
    "wheel_radius": "--wheel-radius",
    "half_track": "--half-track",
    "top_speed": "--top-speed",
    "caster_friction": "--caster-friction",
    "casters": "--caster",
    "keyframe": "--keyframe",
    "free_joints": "--free-joints",
    "self_collide": "--self-collide",
    "balance_inertia": "--balance-inertia",
}
#: keys rewritten where they stand alone (``base`` is too common a word: only in ``base = "BODY"``)
_BARE = re.compile(
    r"(?<![\w'\"/.-])(left_wheel|right_wheel|tau_max|wheel_radius|half_track|top_speed|caster_friction)"
    r"(?![\w'\"/]|\.\w)"
)


def cli_terms(text: str) -> str:
    """A robot error or note written for a mapping table (``map left_wheel and right_wheel``, ``left_wheel =
    "JOINT"``, ``give tau_max … in the robot's mapping``) in the terms of ``robot check``'s flags
    (``--left-wheel JOINT --right-wheel JOINT``, ``--tau-max``); quoted names (a joint called
    ``'left_wheel'``) and paths are left alone. The Python API and scenario files keep the keys."""

    def flag(m: re.Match, fmt: str = "{}") -> str:
        keys = [g for g in m.groups() if g]
        return fmt.format(*(FLAG_OF[k] for k in keys)) if all(k in FLAG_OF for k in keys) else m.group(0)

    text = re.sub(r"map (\w+) and (\w+)\b", lambda m: flag(m, "map them: {} JOINT {} JOINT"), text)
    text = re.sub(
        r'\b(\w+) = "([A-Z]+)"',
        lambda m: f"{FLAG_OF[m.group(1)]} {m.group(2)}" if m.group(1) in FLAG_OF else m.group(0),
        text,
    )
    text = text.replace("left_wheel/right_wheel", "--left-wheel/--right-wheel").replace(" in the robot's mapping", "")
    text = re.sub(r"\b(?:the robot mapping's|the mapping's|mapping) (\w+)\b", flag, text)
    text = text.replace("leave base unset", "leave --base out").replace("map it with base", "map it with --base")
    return _BARE.sub(lambda m: FLAG_OF[m.group(1)], text)


def mapping_args(p: argparse.ArgumentParser) -> None:
    """The mapping flags shared by ``robot check`` and ``identify``."""
    p.add_argument("--base", help="the chassis body (default: 'base')")
    p.add_argument("--left-wheel", help="left wheel hinge joint (default: 'left_wheel')")
    p.add_argument("--right-wheel", help="right wheel hinge joint (default: 'right_wheel')")
    p.add_argument("--wheel-radius", type=float, help="wheel radius in m (default: from the wheels' collision geoms)")
    p.add_argument("--half-track", type=float, help="half the track in m (default: from the wheel joint anchors)")
    p.add_argument("--tau-max", type=float, help="wheel torque limit in N·m (default: the model's own drive limit)")
    p.add_argument(
        "--top-speed",
        type=float,
        help="top speed in m/s at the tyre, the maker's figure (default: the URDF's wheel <limit velocity> or "
        "the <dcmotor>'s no-load speed; design §21)",
    )
    p.add_argument(
        "--control-rate",
        type=float,
        metavar="HZ",
        help="the rate the robot's own controller commands the wheels at, Hz, the maker's figure (e.g. its ROS 2 "
        "diff_drive_controller's update_rate); the hardware verdict's control_rate check (design §19)",
    )
    p.add_argument(
        "--caster",
        action="append",
        metavar="NAME",
        help="a geom or body that is a caster (repeat for several; design §13)",
    )
    p.add_argument(
        "--caster-friction",
        type=float,
        metavar="MU",
        help="sliding friction of the casters against the floor (default: as published; frictionless "
        "geoms stay frictionless)",
    )
    p.add_argument(
        "--free-joints",
        action="store_true",
        help="leave the joints other than the wheels free (default: held at the file's configuration)",
    )
    p.add_argument(
        "--keyframe",
        metavar="NAME",
        help="MJCF: start and hold the robot in this keyframe (default: 'home' where the file has one; "
        "'none': qpos0; design §13.2)",
    )
    p.add_argument(
        "--package-path",
        action="append",
        default=[],
        metavar="NAME=DIR",
        help="URDF: where package://NAME/... points (repeatable; before $BIOFORM_PACKAGE_PATH, $ROS_PACKAGE_PATH)",
    )
    p.add_argument(
        "--balance-inertia",
        action="store_true",
        help="set MuJoCo's compiler option balanceinertia (an inertia breaking A + B >= C is balanced)",
    )
    p.add_argument(
        "--self-collide",
        action="store_true",
        help="URDF: keep contacts between the robot's own links (default off, as in Gazebo)",
    )
    add_xacro_flags(p)  # --xacro, --xacro-arg (design §12)
    from bioform_mj.robots.mjcf_assets import add_flag

    add_flag(p)  # --asset-root DIR (design §12)


def ref_from_args(model: str, args: argparse.Namespace) -> RobotRef:
    """A :class:`RobotRef` from a model argument and the :func:`mapping_args` flags."""
    from bioform_mj.core.errors import InputError
    from bioform_mj.robots.entries import resolve_robot
    from bioform_mj.robots.refs import package_path_from_args

    for flag in ("wheel_radius", "half_track", "tau_max", "top_speed", "control_rate"):
        v = getattr(args, flag, None)
        if v is not None and not (math.isfinite(v) and v > 0):
            raise InputError(f"--{flag.replace('_', '-')} must be a number > 0, got {v}")
    cf = getattr(args, "caster_friction", None)
    if cf is not None and not (math.isfinite(cf) and cf >= 0):
        raise InputError(f"--caster-friction must be a number >= 0, got {cf}")
    return resolve_robot(
        RobotRef(
            model=model,
            base=args.base or "",
            left_wheel=args.left_wheel or "",
            right_wheel=args.right_wheel or "",
            wheel_radius=args.wheel_radius or 0.0,
            half_track=args.half_track or 0.0,
            tau_max=args.tau_max or 0.0,
            casters=tuple(getattr(args, "caster", None) or ()),
            caster_friction=-1.0 if cf is None else float(cf),
            free_joints=bool(getattr(args, "free_joints", False)),
            self_collide=bool(getattr(args, "self_collide", False)),
            balance_inertia=bool(getattr(args, "balance_inertia", False)),
            package_path=package_path_from_args(getattr(args, "package_path", None)),
            keyframe=getattr(args, "keyframe", None) or "",
            top_speed=getattr(args, "top_speed", None) or 0.0,
            control_rate=getattr(args, "control_rate", None) or 0.0,
        )
    )


def add_parser(sub: Any) -> Any:
    """Add ``bioform robot check`` to the CLI's subparsers; returns ``bioform robot``'s subparsers."""
    robot = sub.add_parser("robot", help="robot models: check what the project finds in one")
    rsub = robot.add_subparsers(dest="robot_command", required=True, parser_class=type(robot))
    chk = rsub.add_parser(
        "check",
        help="parts, a_eff/b_eff (formula and identified), traction and tip-over "
        "margins, damping/armature/frictionloss; verdict pass/warn/fail "
        "(exit 0 pass or warn: a warn says its reasons in one warning: line on stderr; "
        f"2 bad input, {EXIT_FAIL} fail)",
    )
    chk.add_argument("model", help="shipped robot name or path to an MJCF or URDF file")
    mapping_args(chk)
    chk.add_argument("--json", type=str, metavar="FILE", help="write the report as JSON to FILE")
    return rsub  # cli.py adds robot fit / replay / drive-program (issue 29)


def _num(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.5g}"


def main(args: argparse.Namespace) -> int:
    """Run ``bioform robot check``; prints a short report, returns the exit code."""
    from bioform_mj.outputs.files import check_out_file, write_json
    from bioform_mj.robots.contacts import floor_table
    from bioform_mj.robots.sanity import one_line

    if args.json:  # before any work (exit 2): a directory, /proc/x, a read-only folder
        args.json = check_out_file(args.json, "--json")
    from bioform_mj.core.errors import InputError

    try:
        report = check(ref_from_args(args.model, args))
    except InputError as exc:  # in the terms of the flags the user gave (issue 28)
        raise InputError(cli_terms(str(exc))) from None
    if args.json:
        write_json(args.json, report)
    ta = report["tip_accel_mps2"]
    lines = [
        f"{report['verdict']}: {one_line(report['model'])}",  # a newline in the path forged an error: line
        f"  parts: base '{report['parts']['base']}', wheels '{report['parts']['wheel_joints'][0]}' / "
        f"'{report['parts']['wheel_joints'][1]}' (sign {report['parts']['wheel_sign'][0]:+d}/"
        f"{report['parts']['wheel_sign'][1]:+d}), r = {report['wheel_radius_m']:.4g} m, "
        f"l = {report['half_track_m']:.4g} m",
        f"  a_eff = {report['a_eff']:.5g} (identified {_num(report['a_identified'])}), "
        f"b_eff = {report['b_eff']:.5g} (identified {_num(report['b_identified'])})",
        f"  motor limit {report['motor_limit_nm']:.3g} N·m, traction limit {report['traction_limit_nm']:.3g} N·m "
        f"(μ = {report['friction_mu']:g})",
        f"  tips at forward {ta['forward']:.3g}, backward {ta['backward']:.3g}, lateral {ta['lateral']:.3g} m/s² "
        f"(full torque: {report['motor_accel_mps2']:.3g} m/s²); "
        f"CoM {1e3 * report['com_offset_m']:.1f} mm off the axle, "
        f"{report['com_height_m']:.3g} m high",
    ]
    from bioform_mj.robots.limits import block

    lines += block(report["limits"])
    lines.append(
        f"  mass {report['mass_kg']:.4g} kg, yaw inertia {report['yaw_inertia_kgm2']:.4g} kg·m² "
        f"(the file's configuration: {report['yaw_inertia_file_kgm2']:.4g}), c_true = "
        f"({report['c_true']['a']:.5g}, {report['c_true']['b']:.5g}); torque reaching the floor "
        f"{100 * report['floor_fraction']['drive']:.3g} % driving, "
        f"{100 * report['floor_fraction']['turn']:.3g} % turning"
    )
    lines += floor_table(report)
    for sc in report["self_contacts"]:
        lines.append(
            f"  self contact: '{sc['body1']}' / '{sc['body2']}' "
            f"{1e3 * sc['depth_m']:.3g} mm deep, {sc['force_n']:.3g} N"
            + ("" if sc["simulated"] else " (not collided in the scene)")
        )
    moving = report["moving_parts"]
    lines.append(
        "  moving parts (first 2 s): "
        + (
            ", ".join(f"'{m['body']}' {1e3 * m['displacement_m']:.1f} mm / {m['rotation_deg']:.1f}°" for m in moving)
            if moving
            else "none"
        )
    )
    lines += [f"  {cli_terms(r)}" for r in report["reasons"]]
    lines += [f"  note: {cli_terms(n)}" for n in report["notes"]]
    print("\n".join(lines))
    reasons = "; ".join(cli_terms(r) for r in report["reasons"])
    if report["verdict"] == "fail":
        print(f"error: robot check failed: {reasons}", file=sys.stderr)
        return EXIT_FAIL
    if report["verdict"] == "warn":  # never silent: a warn's reasons on stderr too, not only in the report
        print(f"warning: robot check warns: {reasons}", file=sys.stderr)
    return 0


def identify_command(args: argparse.Namespace) -> int:
    """``bioform identify MODEL``: identification as JSON on stdout (and ``--out``); warnings and the cause of
    a robot that cannot be identified on stderr."""
    from bioform_mj.assess.identify import identify_main

    if args.out is not None:
        from bioform_mj.outputs.files import check_out_file

        args.out = check_out_file(args.out, "--out")
    from bioform_mj.core.errors import InputError

    try:
        result = identify_main(ref_from_args(args.model, args))
    except InputError as exc:  # in the terms of the flags the user gave (issue 28)
        raise InputError(cli_terms(str(exc))) from None
    text = json.dumps(result, indent=2)
    if args.out is not None:
        from bioform_mj.outputs.files import write_text

        write_text(args.out, text + "\n")
    print(text)
    if result.get("skid_steer"):  # design §14: named, as robot check names it (and fails it)
        print(
            "warning: a 4-wheel / skid-steer base, not the paper's differential drive (robot check fails it): "
            + "; ".join(result["skid_steer"]),
            file=sys.stderr,
        )
    if result.get("fit_problem"):  # design §14.3: its identified value is a reading of the test, said
        print(f"warning: {result['fit_problem']}", file=sys.stderr)
    if not result.get("identifiable", True):  # a named cause, never an internal error (design §14)
        from bioform_mj.assess.check import cause_of

        c = cause_of(result["findings"])
        print(
            f"error: cannot identify a, b: {c['kind'] + ': ' + c['detail'] if c else result['not_identified']}",
            file=sys.stderr,
        )
        return EXIT_FAIL
    return 0  # exit code: done

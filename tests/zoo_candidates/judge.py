"""The independent reference (tests/zoo/reference.py: mujoco and numpy only, no bioform_mj) on the
published robots judged for issue 18 that are not in the zoo (README.md beside this file).

    python tests/zoo_candidates/judge.py [--robot NAME] [--write]

prints, per robot, the formula and the reference's identification of ``a_eff, b_eff``, the floor contacts
and the reference's notes; ``--write`` stores them in ``judged.json`` beside this file. (The Neobotix
MP-400 is not here: its URDF has no joint that can be a wheel, so there is nothing to identify.)
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "zoo"))
import reference as R  # noqa: E402  (tests/zoo/reference.py)

_Z = "../zoo_candidates/"  # file paths are relative to tests/zoo, as reference.Robot's are

CANDIDATES: tuple[R.Robot, ...] = (
    R.Robot(
        name="hello_robot_stretch_mjcf",
        file=_Z + "hello_robot_stretch_mjcf/stretch.xml",
        format="mjcf",
        maker="Hello Robot",
        collection="hello-robot/stretch_mujoco",
        source="https://github.com/hello-robot/stretch_mujoco/blob/d107e094cc295d92f7461bd233daef96e9e22fab/"
        "stretch_mujoco/models/stretch_mj_3.3.0.xml",
        license="BSD-3-Clause-Clear",
        base="base_link",
        left="joint_left_wheel",
        right="joint_right_wheel",
        tau_max=10.0,
        tau_max_source="none in the file (velocity servos, no forcerange): 10 N·m chosen for the judging",
        expected_verdict="fail",
        expected_cause="wheel frictionloss 35 N·m: a dead band of 70 N·m on τ_a, beyond any motor limit; at qpos0 the "
        "wrist lies inside the base (a self contact of ~1.8 kN under the position servos)",
    ),
    R.Robot(
        name="fetch_freight_urdf",
        file=_Z + "fetch_freight_urdf/fetch_description/robots/freight.urdf",
        format="urdf",
        maker="Fetch Robotics",
        collection="ZebraDevs/fetch_ros",
        source="https://github.com/ZebraDevs/fetch_ros/blob/9c38de60834e6e51e676a302337e9ca56436e94f/"
        "fetch_description/robots/freight.urdf",
        license="CC-BY-NC-SA-4.0",
        base="base_link",
        left="l_wheel_joint",
        right="r_wheel_joint",
        packages={"fetch_description": _Z + "fetch_freight_urdf/fetch_description"},
        tau_max=8.85,
        tau_max_source="the wheel joints' <limit effort>",
        expected_verdict="fail",
        expected_cause="braking chassis: no casters in the URDF, the base mesh's rear edge drags on the floor "
        "(frictionless: formula within 0.3 %)",
    ),
    R.Robot(
        name="mir100_urdf",
        file=_Z + "mir100_urdf/mir.urdf",
        format="urdf",
        maker="MiR (DFKI-NI description)",
        collection="DFKI-NI/mir_robot",
        source="https://github.com/DFKI-NI/mir_robot/blob/a82951afcf1f884cdbd5963cc18d597f5d9be39a/"
        "mir_description/urdf/mir.urdf.xacro",
        license="BSD-3-Clause",
        base="base_footprint",
        left="left_wheel_joint",
        right="right_wheel_joint",
        free_joints=tuple(f"{c}_caster_{k}_joint" for c in ("fl", "fr", "bl", "br") for k in ("rotation", "wheel")),
        packages={"mir_description": _Z + "mir100_urdf/mir_description"},
        tau_max=100.0,
        tau_max_source="the wheel joints' <limit effort>",
        expected_verdict="fail",
        expected_cause="six wheels on one plane (2 driven, 4 swivel casters) with Gazebo mu1 200 on the driven ones: "
        "MuJoCo's pyramidal cone gives the high-μ contacts almost no normal load (0 N of 850 N)",
    ),
    R.Robot(
        name="pioneer3dx_urdf",
        file=_Z + "pioneer3dx_urdf/p3dx_description/urdf/pioneer3dx.urdf",
        format="urdf",
        maker="Adept MobileRobots (community description)",
        collection="mario-serna/pioneer_p3dx_model",
        source="https://github.com/mario-serna/pioneer_p3dx_model/blob/ecbb08cb09ee8e0f12ba13fe41702a0187976497/"
        "p3dx_description/urdf/pioneer3dx.urdf",
        license="GPL-3.0",
        base="base_link",
        left="base_left_wheel_joint",
        right="base_right_wheel_joint",
        packages={"p3dx_description": _Z + "pioneer3dx_urdf/p3dx_description"},
        tau_max=5.0,
        tau_max_source="the Gazebo diff-drive plugin's <wheelTorque>",
        expected_verdict="warn",
        expected_cause="rolls as the formula says at small torques, but its inertias are placeholders (1 kg·m² on a "
        "10 g plate and a 0.1 g sonar; hubcaps with the wheels' inertia): b_eff is not the real robot's",
    ),
)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robot", action="append")
    p.add_argument("--write", action="store_true")
    a = p.parse_args(argv)
    out = {}
    for r in CANDIDATES:
        if a.robot and r.name not in a.robot:
            continue
        if not (HERE.parent / "zoo" / r.file).exists():
            print(
                f"{r.name:26s} not here: its license keeps it out of this repository; fetch {r.source}", file=sys.stderr
            )
            continue
        rec = R._round(R.reference(r))
        out[r.name] = rec
        e = rec["relative_error"]
        print(
            f"{r.name:26s} m {rec['mass_kg']:8.3f} kg  a {rec['a_formula']:.5g} id {rec['a_identified']:.5g} "
            f"({100 * e['a']:+.2f} %)  b {rec['b_formula']:.5g} id {rec['b_identified']:.5g} ({100 * e['b']:+.2f} %)"
            f"  {rec['disagreement_cause']}"
        )
        for key in ("braking_geoms_frictionless", "named_causes_removed"):
            if rec[key]:
                cf = rec[key]["relative_error"]
                print(f"    {key}: a {100 * cf['a']:+.2f} %  b {100 * cf['b']:+.2f} %")
        for c in rec["floor_contacts"]:
            print(f"    {c['geom']:36s} {c['body']:24s} {c['load_n']:9.4f} N  μ {c['friction_simulated']:g}")
        for n in rec["notes"]:
            print("    note:", n)
    if a.write:
        (HERE / "judged.json").write_text(json.dumps(out, indent=1, ensure_ascii=False) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

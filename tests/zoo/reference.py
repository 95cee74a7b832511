"""Independent reference for the zoo of published robots (tests/zoo, docs/zoo.md).

This script does NOT import bioform_mj: only mujoco and numpy. For each robot of :data:`ROBOTS` it

1. loads the description as its maker published it (MJCF directly; URDF through MuJoCo's own URDF
   compiler with ``fusestatic="false" discardvisual="true" strippath="false"
   inertiafromgeom="false"`` inserted, ``package://NAME/`` rewritten to the zoo's package folder,
   a free joint added to the root link, links without ``<inertial>`` massless as the URDF
   specification says, self-collision off as in Gazebo, ``<gazebo><mu1>`` friction applied, the
   smaller of it and the floor's as in Gazebo);
2. puts it on our own plane floor (friction 1, condim 3); a geom its maker made frictionless
   (friction < 1e-3 or condim 1, or a Gazebo ``mu1`` < 1e-3) keeps that against the floor through
   geom ``priority`` (MuJoCo uses the higher-priority geom's friction/condim for a pair);
3. removes the model's actuators (torques enter as ``qfrc_applied``: a torque source, the
   paper's model), welds every joint that is not a wheel or a listed passive caster joint (the
   joint is deleted from the spec, so its child moves with its parent at ``qpos0``; keyframes and the
   tendons, equalities and sensors go with them), and lets
   each wheel touch the floor through one sphere of its radius (a flat tread scrubs when turning);
4. lets it settle (free caster swivels set to trail the coming test's motion), records the floor
   contacts (geom, body, normal load, friction as published and as simulated), then drives it
   from the settled state with constant wheel torques at three levels, ``τ_L = τ_R = T`` (drive)
   and ``τ_R = −τ_L = T`` (turn), and fits the centre-of-mass forward acceleration and the yaw
   acceleration over a window after the start-up transient; across the levels
   ``a_id = d υ̇ / d τ_a`` with ``τ_a = τ_L + τ_R`` and ``b_id = d ω̇ / d τ_b`` with
   ``τ_b = τ_R − τ_L`` (design §5, CCW-positive ω), so a dead band (wheel frictionloss) or any
   constant resistance drops out of the slope;
5. computes the rigid-body formula from the compiled masses and inertias (design §8):
   ``a = 1/(m r + 2 I_w/r)``, ``b = l/(I r + 2 I_w l²/r)``, ``m`` the total mass, ``I`` the yaw
   inertia about the vertical through the axle midpoint, ``I_w`` one wheel's spin inertia
   including everything welded to it and the joint armature, ``r`` the wheel radius from the
   wheel's collision geometry, ``l`` half the distance between the wheel joint anchors.

``python tests/zoo/reference.py`` prints the table; ``--write`` regenerates
``tests/zoo/expectations.json``; ``--robot NAME`` limits it to one robot.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

HERE = Path(__file__).resolve().parent
EXPECTATIONS = HERE / "expectations.json"

#: our floor's sliding friction (the other two: MuJoCo's defaults)
FLOOR_FRICTION = (1.0, 0.005, 0.0001)
#: a geom whose sliding friction is below this (or condim 1) is frictionless as published
FRICTIONLESS = 1e-3
#: at rest before each test, s
SETTLE_S = 0.5
#: each constant-torque test, s; the fit uses WINDOW_S of it (after the start-up transient)
RUN_S = 0.5
WINDOW_S = (0.15, 0.5)
#: drive tests: forward accelerations aimed at (m/s², from the formula's a); turn tests: rim accelerations
#: l ω̇ aimed at, at most TURN_RATE_MAX rad/s of yaw rate at the end of a test
ACCELS = (0.2, 0.4, 0.6)
TURN_RATE_MAX = 2.0
#: identification and formula agree within this (relative)
AGREE = 0.05


@dataclass(frozen=True)
class Robot:
    """One zoo robot: where its file is, what drives it, and what we expect of it."""

    name: str
    file: str  # relative to tests/zoo
    format: str  # "mjcf" | "urdf"
    maker: str
    collection: str
    source: str  # URL of the published file
    license: str
    base: str  # body (MJCF) / link (URDF) of the chassis
    left: str  # left wheel joint
    right: str  # right wheel joint
    kind: str = "differential"  # or "skid-steer"
    other_wheels: tuple[str, ...] = ()  # further wheel joints left free to roll (skid-steer)
    free_joints: tuple[str, ...] = ()  # passive joints left free (caster swivels and rollers), not welded
    packages: dict = field(default_factory=dict)  # package name -> folder (relative to tests/zoo)
    tau_max: float = 0.0  # N·m per wheel: the motor limit a user maps (the description has none usable)
    tau_max_source: str = ""
    top_speed: float = 0.0  # m/s at the tyre: the maker's datasheet figure (the `top_speed` mapping key, design §21)
    top_speed_source: str = ""
    # Hz: the rate the maker's controller commands the wheels at (the `control_rate` mapping key, design §19), from the
    # maker's own controller configuration or firmware (cited); 0 where the maker publishes none we found
    control_rate: float = 0.0
    control_rate_source: str = ""
    expected_verdict: str = "pass"
    expected_cause: str = ""


_MENAGERIE_TB3 = (
    "https://github.com/ROBOTIS-GIT/robotis_mujoco_menagerie/blob/d8344c0dbe7a00208d0301111523dde65efc174a/"
)
_TB3 = "https://github.com/ROBOTIS-GIT/turtlebot3/blob/"


def _robotis(fmt: str) -> dict:
    """What the two ROBOTIS MJCFs (``fmt`` "mjcf": menagerie names) and the two URDFs ("urdf") share."""
    urdf = fmt == "urdf"
    return dict(
        format=fmt,
        maker="ROBOTIS",
        collection="ROBOTIS-GIT/turtlebot3 (turtlebot3_description)"
        if urdf
        else "ROBOTIS-GIT/robotis_mujoco_menagerie",
        license="Apache-2.0",
        base="base_footprint" if urdf else "base",
        left="wheel_left_joint" if urdf else "wheel_left",
        right="wheel_right_joint" if urdf else "wheel_right",
    )


#: PAL's four casters (TIAGo, PMB2): a swivel (1) and a roller (2) joint each, left free
_PAL_CASTERS = tuple(
    f"caster_{corner}_{k}_joint" for corner in ("front_right", "front_left", "back_right", "back_left") for k in (1, 2)
)

ROBOTS: tuple[Robot, ...] = (
    Robot(
        name="robotis_tb3_burger",
        file="robotis_tb3_burger/turtlebot3_burger.xml",
        **_robotis("mjcf"),
        source=_MENAGERIE_TB3 + "robotis_tb3/turtlebot3_burger.xml",
        tau_max=1.4,
        top_speed=0.22,
        top_speed_source="ROBOTIS e-Manual, TurtleBot3 specifications: max. linear velocity 0.22 m/s (Burger)",
        control_rate=30.0,
        control_rate_source=(
            "ROBOTIS OpenCR firmware turtlebot3_core_config.h: CONTROL_MOTOR_SPEED_PERIOD 30 //hz (the wheel "
            "speed loop; Burger), https://github.com/ROBOTIS-GIT/OpenCR/blob/09bf34f5f9ebc1253e03ac789cf820dcc46eb99d/"
            "arduino/opencr_arduino/opencr/libraries/turtlebot3/examples/turtlebot3_burger/turtlebot3_core/turtlebot3_core_config.h"
        ),
        tau_max_source="Dynamixel XL430-W250 stall torque, 11.1 V (ROBOTIS e-Manual); the MJCF has velocity servos",
        expected_verdict="warn",
        expected_cause=(
            "rolls as the formula says once its caster stays frictionless as published (friction 1e-4, condim 1); "
            "caveats: centre of mass 30 mm behind the axle, wheel frictionloss 0.1 N·m (a dead band of 0.2 N·m "
            "on τ_a), armature 0.01 kg·m² (≈ 9 m r²: most of the torque spins the rotor, so the traction limit "
            "is μ N/(m a) ≈ 2 N·m per wheel, not μ N r)"
        ),
    ),
    Robot(
        name="robotis_tb3_waffle_pi",
        file="robotis_tb3_waffle_pi/turtlebot3_waffle_pi.xml",
        **_robotis("mjcf"),
        source=_MENAGERIE_TB3 + "robotis_tb3/turtlebot3_waffle_pi.xml",
        tau_max=3.0,
        top_speed=0.26,
        top_speed_source="ROBOTIS e-Manual, TurtleBot3 specifications: max. linear velocity 0.26 m/s (Waffle Pi)",
        control_rate=30.0,
        control_rate_source=(
            "ROBOTIS OpenCR firmware turtlebot3_core_config.h: CONTROL_MOTOR_SPEED_PERIOD 30 //hz (the wheel "
            "speed loop; Waffle / Waffle Pi), https://github.com/ROBOTIS-GIT/OpenCR/blob/009a18f7068fe33fe4d35eb18023b463af0d7fd1/"
            "arduino/opencr_arduino/opencr/libraries/turtlebot3/examples/turtlebot3_waffle/turtlebot3_core/turtlebot3_core_config.h"
        ),
        tau_max_source="Dynamixel XM430-W210 stall torque, 12 V (ROBOTIS e-Manual); the MJCF has velocity servos only",
        expected_verdict="warn",
        expected_cause=(
            "rolls as the formula says on its two frictionless casters (friction 1e-4, condim 1); caveats: centre "
            "of mass 62 mm behind the axle, dead band 0.2 N·m, motor limit 3 N·m above the traction limit "
            "μ N/(m a) ≈ 2.1 N·m"
        ),
    ),
    Robot(
        name="menagerie_tiago",
        file="menagerie_tiago/tiago.xml",
        format="mjcf",
        maker="PAL Robotics",
        collection="google-deepmind/mujoco_menagerie (pal_tiago)",
        source="https://github.com/google-deepmind/mujoco_menagerie/blob/dd150f1bbf144b86752091a325d2a2c107af9deb/"
        "pal_tiago/tiago.xml",
        license="Apache-2.0",
        base="base_link",
        left="wheel_left_joint",
        right="wheel_right_joint",
        free_joints=_PAL_CASTERS,
        tau_max=100.0,
        top_speed=1.0,
        top_speed_source="PAL Robotics TIAGo datasheet: maximum speed 1 m/s",
        control_rate=50.0,
        control_rate_source=(
            "PAL's TIAGo mobile_base_controller (diff_drive_controller) publish_rate: 50.0 in "
            "tiago_controller_configuration/config/mobile_base_controller.yaml, https://github.com/pal-robotics/"
            "tiago_robot/blob/041dc7552f9d54e14c0528a726f83276cd827a5b/tiago_controller_configuration/config/"
            "mobile_base_controller.yaml (the PMB-2 base's own file says the same)"
        ),
        tau_max_source="the wheel joints' actuatorfrcrange (-100, 100) in the published MJCF",
        expected_verdict="warn",
        expected_cause=(
            "rolls as the formula says on four passive casters (left free); caveats: the motor limit 100 N·m is "
            "far above the traction limit and full torque would tip it; the arm, head and torso joints have "
            "no actuators in tiago.xml (damping and frictionloss only): they must be held, or the arm drops"
        ),
    ),
    Robot(
        name="tb3_burger_urdf",
        file="tb3_burger_urdf/turtlebot3_burger.urdf",
        **_robotis("urdf"),
        source=_TB3 + "754a9ddd937667839d7c38e88ca08ee0d93c08a8/turtlebot3_description/urdf/turtlebot3_burger.urdf",
        tau_max=1.4,
        top_speed=0.22,
        top_speed_source="ROBOTIS e-Manual, TurtleBot3 specifications: max. linear velocity 0.22 m/s (Burger)",
        control_rate=30.0,
        control_rate_source=(
            "ROBOTIS OpenCR firmware turtlebot3_core_config.h: CONTROL_MOTOR_SPEED_PERIOD 30 //hz (the wheel "
            "speed loop; Burger), https://github.com/ROBOTIS-GIT/OpenCR/blob/09bf34f5f9ebc1253e03ac789cf820dcc46eb99d/"
            "arduino/opencr_arduino/opencr/libraries/turtlebot3/examples/turtlebot3_burger/turtlebot3_core/turtlebot3_core_config.h"
        ),
        tau_max_source="Dynamixel XL430-W250 stall torque (ROBOTIS e-Manual); the URDF has no effort limit",
        expected_verdict="fail",
        expected_cause=(
            "braking caster: the caster is a box link 'caster_back_link' with no friction given (no <gazebo> mu, "
            "so μ 1) carrying 0.41 N at rest: it drags the robot (a 61 % low) and keeps it from turning"
        ),
    ),
    Robot(
        name="tb3_waffle_pi_urdf",
        file="tb3_waffle_pi_urdf/turtlebot3_waffle_pi.urdf",
        **_robotis("urdf"),
        source=_TB3 + "fd74967cd79cd40cc23d2ae907adda93ea92cece/turtlebot3_description/urdf/turtlebot3_waffle_pi.urdf",
        tau_max=3.0,
        top_speed=0.26,
        top_speed_source="ROBOTIS e-Manual, TurtleBot3 specifications: max. linear velocity 0.26 m/s (Waffle Pi)",
        control_rate=30.0,
        control_rate_source=(
            "ROBOTIS OpenCR firmware turtlebot3_core_config.h: CONTROL_MOTOR_SPEED_PERIOD 30 //hz (the wheel "
            "speed loop; Waffle / Waffle Pi), https://github.com/ROBOTIS-GIT/OpenCR/blob/009a18f7068fe33fe4d35eb18023b463af0d7fd1/"
            "arduino/opencr_arduino/opencr/libraries/turtlebot3/examples/turtlebot3_waffle/turtlebot3_core/turtlebot3_core_config.h"
        ),
        tau_max_source="Dynamixel XM430-W210 stall torque (ROBOTIS e-Manual); the URDF has no effort limit",
        expected_verdict="fail",
        expected_cause=(
            "braking casters: boxes 'caster_back_left_link', 'caster_back_right_link' with no friction given (μ 1) "
            "carry 0.46 N together: a 32 % low, no turning"
        ),
    ),
    Robot(
        name="kobuki_urdf",
        file="kobuki_urdf/kobuki_standalone.urdf",
        format="urdf",
        maker="Yujin Robot",
        collection="yujinrobot/kobuki (kobuki_description)",
        source="https://github.com/yujinrobot/kobuki/blob/4f7f1beea87a970519f8d842be0eb40f0d5cde68/"
        "kobuki_description/urdf/kobuki_standalone.urdf.xacro",
        license="BSD",
        base="base_footprint",
        left="wheel_left_joint",
        right="wheel_right_joint",
        tau_max=1.0,
        top_speed=0.7,
        top_speed_source="Kobuki specifications (kobuki.yujinrobot.com): max. translational velocity 70 cm/s",
        control_rate=50.0,
        control_rate_source=(
            "Yujin's Kobuki protocol: 'Kobuki sends below default feedbacks periodically in 50 Hz', "
            "https://github.com/yujinrobot/kobuki_core/blob/3e3c2d7f78e82ac17d648f08653f9083db4f438b/kobuki_driver/"
            "doxygen/english/en_appendix_protocol.dox; its driver sends one Base Control (wheel) command per "
            "feedback packet (sendBaseControlCommand() in Kobuki::spin), https://github.com/kobuki-base/kobuki_core/"
            "blob/e2f0feac0f7a9964d021ac3241b7663f7728d5b9/src/driver/kobuki.cpp"
        ),
        tau_max_source="<torque>1.0</torque> of the gazebo_ros_kobuki plugin in the published URDF (as expanded)",
        expected_verdict="warn",
        expected_cause=(
            "rolls as the formula says once its casters keep the Gazebo mu1 = 0 as published; caveats: motor limit "
            "1 N·m (the Gazebo plugin's torque) above the traction limit μ N/(m a) ≈ 0.64 N·m, and full torque "
            "(14 m/s²) beyond the 9.7 m/s² that lifts the front caster (centre of mass 10 mm high, 10 mm ahead "
            "of the axle, as published); the published wheel inertia 0.001 kg·m² (≈ 80 m r² of its 0.01 kg "
            "wheel) is 40 % of a's denominator"
        ),
    ),
    Robot(
        name="create3_urdf",
        file="create3_urdf/create3.urdf",
        format="urdf",
        maker="iRobot",
        collection="iRobotEducation/create3_sim (irobot_create_description)",
        source="https://github.com/iRobotEducation/create3_sim/blob/7df657e1c0dbc7a618e7f12d382dc1676040855a/"
        "irobot_create_common/irobot_create_description/urdf/create3.urdf.xacro",
        license="BSD-3-Clause",
        base="base_link",
        left="left_wheel_joint",
        right="right_wheel_joint",
        packages={"irobot_create_description": "create3_urdf/irobot_create_description"},
        tau_max=0.05,
        top_speed=0.306,
        top_speed_source="iRobot Create 3 docs (iroboteducation.github.io/create3_docs): max. speed 0.306 m/s",
        control_rate=62.5,
        control_rate_source=(
            "iRobot Create 3 docs, odometry: the wheel_status, wheel_ticks and wheel_vels topics publish at 62.5 Hz "
            "(the robot's wheel loop as it reports it), https://github.com/iRobotEducation/create3_docs/blob/"
            "53f188ffce498133d589f980fc18d38493d0ca84/docs/api/odometry.md; its simulator's diffdrive_controller "
            "publish_rate 62.0 (controller_manager update_rate 1000 in simulation), https://github.com/"
            "iRobotEducation/create3_sim/blob/7df657e1c0dbc7a618e7f12d382dc1676040855a/irobot_create_common/"
            "irobot_create_control/config/control.yaml"
        ),
        tau_max_source=(
            "our choice (the description publishes none): full torque accelerates at 0.86 m/s², below the margin "
            "1.1 m/s² at which accelerating lifts the front caster (centre of mass 7 mm ahead of the axle)"
        ),
        expected_verdict="warn",
        expected_cause=(
            "caster 'front_caster_link' with Gazebo mu1 = 0.1 as published carries 1.7 N (6 % of the weight): a "
            "drag of 0.17 N whose share changes with the load transfer, identification +5.5 % on a; wheel-drop "
            "joints locked at qpos0; the wheels sit inside the chassis cylinder (self-contacts off, URDF convention)"
        ),
    ),
    Robot(
        name="husky_urdf",
        file="husky_urdf/husky.urdf",
        format="urdf",
        maker="Clearpath Robotics",
        collection="husky/husky (husky_description)",
        source="https://github.com/husky/husky/blob/dff7c81a277e916d6169f118ab33809b429d0acf/"
        "husky_description/urdf/husky.urdf.xacro",
        license="BSD-3-Clause",
        base="base_link",
        left="front_left_wheel",
        right="front_right_wheel",
        kind="skid-steer",
        other_wheels=("rear_left_wheel", "rear_right_wheel"),
        packages={"husky_description": "husky_urdf/husky_description"},
        tau_max=20.0,
        top_speed=1.0,
        top_speed_source="Clearpath Robotics Husky UGV datasheet: maximum speed 1.0 m/s",
        tau_max_source="our choice (the URDF's transmissions give none)",
        control_rate=10.0,
        control_rate_source=(
            "Clearpath's husky_base driver (husky_node) control_frequency: 10.0 in husky_base/launch/base.launch, "
            "https://github.com/husky/husky/blob/0fef78742105a1dd35ea9aedffbc775388a29628/husky_base/launch/base.launch"
        ),
        expected_verdict="fail",
        expected_cause=(
            "skid-steer: four fixed wheels on the floor, turning needs lateral wheel slip (it does not turn at the "
            "test torques): not the paper's differential drive, refused"
        ),
    ),
    Robot(
        name="pmb2_urdf",
        file="pmb2_urdf/pmb2.urdf",
        format="urdf",
        maker="PAL Robotics",
        collection="pal-robotics/pmb2_robot (pmb2_description)",
        source="https://github.com/pal-robotics/pmb2_robot/blob/6fcda2695dee70efd3756ee4645b2190462e78ac/"
        "pmb2_description/robots/pmb2.urdf.xacro",
        license="Apache-2.0",
        base="base_footprint",
        left="wheel_left_joint",
        right="wheel_right_joint",
        free_joints=_PAL_CASTERS,
        packages={"pmb2_description": "pmb2_urdf/pmb2_description"},
        tau_max=6.0,
        top_speed=1.0,
        top_speed_source="PAL Robotics PMB-2 datasheet: maximum speed 1 m/s",
        control_rate=50.0,
        control_rate_source=(
            "PAL's mobile_base_controller (diff_drive_controller) publish_rate: 50.0 in pmb2_controller_configuration/"
            "config/default_controllers.yaml, https://github.com/pal-robotics/pmb2_robot/blob/"
            "c46179832d7a3b6dff5bd20925696521bc5897dc/pmb2_controller_configuration/config/default_controllers.yaml "
            "(its Gazebo controller manager runs at 100 Hz: "
            "pmb2_description/ros2_control/gazebo_controller_manager_cfg.yaml)"
        ),
        tau_max_source="the wheel joints' <limit effort='6.0'> (PAL's wheel_torque)",
        expected_verdict="warn",
        expected_cause=(
            "rolls as the formula says on four passive casters (swivel and roller joints free; welded they brake: "
            "spheres with Gazebo mu 1); caveats: wheel damping 1 N·m·s/rad (drag time constant ≈ 0.26 s) and "
            "friction 2 N·m per wheel (a dead band of 4 N·m on τ_a, a third of the motors' 12 N·m); 10 kg "
            "suspension links on ±5 mm prismatic joints (locked at qpos0)"
        ),
    ),
    Robot(
        name="diffbot_urdf",
        file="diffbot_urdf/diffbot.urdf",
        format="urdf",
        maker="ros-controls",
        collection="ros-controls/ros2_control_demos (example_2 DiffBot)",
        source="https://github.com/ros-controls/ros2_control_demos/blob/0d9df42ab19bc3f8f53b04f8d43ae7ae9857cd64/"
        "example_2/description/urdf/diffbot.urdf.xacro",
        license="Apache-2.0",
        base="base_link",
        # the joint named 'left_wheel_joint' sits at y = -0.05 (the right-hand side, x forward): mapped by position
        left="right_wheel_joint",
        right="left_wheel_joint",
        tau_max=0.05,
        top_speed_source="none (a ros2_control demo, not a product); the URDF limit 1.0 rad/s × r = 0.015 m/s",
        control_rate=10.0,
        control_rate_source=(
            "ros2_control_demos example_2 controller_manager update_rate: 10 (Hz; the diff_drive_controller's "
            "publish_rate 50 cannot exceed it), https://github.com/ros-controls/ros2_control_demos/blob/"
            "6e0719c12645ad5993d7aca71e964a6ce60cd2cb/example_2/bringup/config/diffbot_controllers.yaml"
        ),
        tau_max_source="our choice (the URDF's effort limit 100 N·m is a placeholder)",
        expected_verdict="fail",
        expected_cause=(
            "wheel damping 0.2 N·m·s/rad: a drag rate 2 a c/r ≈ 1500 1/s (time constant < 1 ms), the robot "
            "moves at the speed the damping allows, not as υ̇ = a τ; two sphere casters with friction 1 (no "
            "<gazebo> mu) level with the wheels carry load and brake"
        ),
    ),
)


# ----------------------------------------------------------------------------------------------- loading


def _gazebo_friction(urdf_text: str) -> dict[str, tuple[float, float]]:
    """``{link: (mu1, mu2)}`` from ``<gazebo reference="LINK"><mu1>…`` (text or ``value=``)."""
    root = ET.fromstring(urdf_text)
    out: dict[str, tuple[float, float]] = {}
    for gz in root.iter("gazebo"):
        ref = gz.get("reference")
        if not ref:
            continue
        mus = []
        for tag, nested in (("mu1", "friction/ode/mu"), ("mu2", "friction/ode/mu2")):
            el = gz.find(tag)
            if el is None:
                el = gz.find(nested)  # SDF-style <friction><ode><mu>
            if el is None:
                mus.append(None)
                continue
            txt = (el.text or "").strip() or el.get("value", "")
            mus.append(float(txt))
        if mus[0] is not None or mus[1] is not None:
            mu1 = mus[0] if mus[0] is not None else mus[1]
            mu2 = mus[1] if mus[1] is not None else mus[0]
            out[ref] = (mu1, mu2)
    return out


def urdf_text_for_mujoco(robot: Robot) -> str:
    """The URDF with our minimal fixes for MuJoCo's URDF compiler (see the module docstring)."""
    text = (HERE / robot.file).read_text()
    for pkg, folder in robot.packages.items():
        text = text.replace(f"package://{pkg}/", str((HERE / folder).resolve()) + os.sep)
    fixes = (
        '<mujoco><compiler fusestatic="false" discardvisual="true" strippath="false" '
        'inertiafromgeom="false" angle="radian"/></mujoco>'
    )
    text, n = re.subn(r"(<robot\b[^>]*>)", lambda m: m.group(1) + fixes, text, count=1)
    if n != 1:
        raise ValueError(f"{robot.file}: no <robot> element")
    return text


@dataclass
class Loaded:
    """A robot composed on our floor, ready to step."""

    model: mujoco.MjModel
    data: mujoco.MjData
    root: int  # body id of the free-jointed root
    base: int  # body id of the chassis
    wheels: tuple[int, int]  # joint ids (left, right)
    floor: int  # geom id
    published: dict  # geom name -> {"friction": [...], "condim": int, "source": str}
    notes: list


def _name_geoms(spec: mujoco.MjSpec) -> None:
    counts: dict[str, int] = {}
    for g in spec.geoms:
        if not g.name:
            body = g.parent.name or "world"
            k = counts.get(body, 0)
            counts[body] = k + 1
            g.name = f"{body}/geom{k}"


def _point_wheels(spec: mujoco.MjSpec, joints, notes: list, published: dict) -> None:
    """Give each wheel one contact point: its collision geoms off, a sphere of the wheel's radius on the axle.

    A cylinder (or a mesh hull) lying on the floor touches it at both edges of the tread, so turning
    scrubs them sideways: MuJoCo's soft friction then acts like a yaw damper (design §8 pitfall). The
    sphere (density 0, the first collision geom's friction, condim, priority and solver parameters)
    rolls on one point, as the rigid-body formula assumes.
    """
    model = spec.copy().compile()
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    for jn in joints:
        j = model.joint(jn).id
        wb = int(model.jnt_bodyid[j])
        geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == wb and _collides(model, g)]
        if not geoms:
            continue
        r = max(data.xanchor[j][2] - _lowest(model, data, g) for g in geoms)
        src = spec.geom(model.geom(geoms[0]).name)
        body = spec.body(model.body(wb).name)
        sph = body.add_geom(
            name=f"{jn}_point_wheel",
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[r, 0, 0],
            pos=[float(x) for x in model.jnt_pos[j]],
            density=0,
            contype=src.contype,
            conaffinity=src.conaffinity,
            condim=src.condim,
            friction=[float(x) for x in src.friction],
            priority=src.priority,
            solref=[float(x) for x in src.solref],
            solimp=[float(x) for x in src.solimp],
            group=3,
        )
        published[sph.name] = published.get(src.name, {})
        for g in geoms:
            gs = spec.geom(model.geom(g).name)
            gs.contype, gs.conaffinity = 0, 0
    notes.append(f"wheels {list(joints)} touch the floor through one sphere each (point contact)")


def load(
    robot: Robot,
    point_wheels: bool = True,
    frictionless: tuple[str, ...] = (),
    lossless: bool = False,
    self_collision: bool = False,
    lock: bool = True,
) -> Loaded:
    """Compose ``robot`` on our floor (steps 1–3 of the module docstring) and place it on the floor.

    ``point_wheels``: the wheels touch the floor through one point each (:func:`_point_wheels`);
    False keeps their published collision shapes. ``frictionless``: geoms made frictionless (condim 1,
    priority 1) — the counterfactual that checks a braking contact is the cause; ``lossless``: every
    remaining joint's damping and frictionloss set to 0 (the same check for those terms);
    ``self_collision``: URDF geoms keep MuJoCo's default collision filter (only parent–child pairs
    excluded) instead of Gazebo's no-self-collision (:func:`self_contacts` uses it); ``lock``: False
    keeps the non-wheel joints as published.
    """
    notes: list[str] = []
    published: dict = {}
    if robot.format == "mjcf":
        spec = mujoco.MjSpec.from_file(str(HERE / robot.file))
        _name_geoms(spec)
        root_spec = spec.body(robot.base)
        while root_spec.parent is not None and root_spec.parent.name != "world":
            root_spec = root_spec.parent
        if not any(j.type == mujoco.mjtJoint.mjJNT_FREE for j in root_spec.joints):
            root_spec.add_freejoint()
            notes.append(f"free joint added to '{root_spec.name}'")
        for g in spec.geoms:
            if g.contype or g.conaffinity:
                published[g.name] = {"friction": [float(x) for x in g.friction], "condim": int(g.condim)}
                if g.friction[0] < FRICTIONLESS or g.condim == 1:
                    g.priority = 1  # keeps its friction/condim against our floor
    else:
        text = urdf_text_for_mujoco(robot)
        gz = _gazebo_friction(text)
        spec = mujoco.MjSpec.from_string(text)
        _name_geoms(spec)
        root_spec = spec.worldbody.first_body()
        root_spec.add_freejoint()
        notes.append(f"root link '{root_spec.name}' given a free joint; fixed links kept as welded bodies")
        heavy = [b.name for b in spec.bodies if b.name != "world" and b.mass == 0 and len(b.geoms)]
        if heavy:
            notes.append(f"links without <inertial> but with collision geometry are massless (URDF default): {heavy}")
        bad = []
        for b in spec.bodies:  # an inertia that is not positive definite (Gazebo takes it, MuJoCo does not)
            fi = np.asarray(b.fullinertia, float)
            if b.name == "world" or not np.all(np.isfinite(fi)):
                continue
            mat = np.array([[fi[0], fi[3], fi[4]], [fi[3], fi[1], fi[5]], [fi[4], fi[5], fi[2]]])
            if np.linalg.eigvalsh(mat).min() <= 0:
                bad.append(b.name)
                b.fullinertia = [float(x) for x in np.abs(fi[:3])] + [0.0, 0.0, 0.0]
        if bad:
            notes.append(f"inertia not positive definite, products of inertia dropped: {bad}")
        for g in spec.geoms:
            if not self_collision:
                g.contype, g.conaffinity = 2, 1  # self-collision off (Gazebo's default); floor contacts kept
            link = g.parent.name
            if link in gz:
                mu1, mu2 = gz[link]
                mu = min(mu1, mu2)
                published[g.name] = {"friction": [mu1, mu2], "condim": None, "source": "gazebo mu1/mu2"}
                # ODE (Gazebo) takes the smaller mu of a pair: one below our floor's wins by priority, one above is
                # the floor's (a MiR100's mu1 200 would also starve its wheels' normal load in the pyramidal cone)
                g.friction = [min(mu, FLOOR_FRICTION[0]), g.friction[1], g.friction[2]]
                g.priority = 1 if mu < FLOOR_FRICTION[0] else 0
                if mu < FRICTIONLESS:
                    g.condim = 1
                if mu1 != mu2:
                    notes.append(f"{link}: Gazebo mu1 {mu1} ≠ mu2 {mu2}; simulated isotropic with {mu}")
            else:
                published[g.name] = {"friction": None, "condim": None, "source": "none (no <gazebo> mu)"}
    # the model's own actuators go: torques enter as qfrc_applied (a torque source)
    acts = list(spec.actuators)
    for a in acts:
        spec.delete(a)
    if acts:
        notes.append(f"{len(acts)} actuator(s) of the model removed (torque source instead)")
    keys = list(spec.keys)  # a keyframe's ctrl/qpos no longer fit the model: the reference starts at qpos0
    for k in keys:
        spec.delete(k)
    if keys:
        notes.append(f"{len(keys)} keyframe(s) dropped (the tests start at qpos0)")
    keep = {robot.left, robot.right, *robot.other_wheels, *robot.free_joints}
    if lock:  # tendons, equalities and sensors may name the joints welded below; at qpos0 they do nothing we test
        tied = [*spec.tendons, *spec.equalities, *spec.sensors]
        for el in tied:
            spec.delete(el)
        if tied:
            notes.append(f"{len(tied)} tendon(s)/equality(ies)/sensor(s) removed with the welded joints")
    locked = []
    for j in list(spec.joints):
        if j.type == mujoco.mjtJoint.mjJNT_FREE or j.name in keep or not lock:
            continue
        locked.append(j.name)
        spec.delete(j)
    if locked:
        notes.append(f"non-wheel joints welded at qpos0: {locked}")
    if robot.free_joints:
        notes.append(f"passive joints left free: {list(robot.free_joints)}")
    if lossless:
        for j in spec.joints:
            j.damping, j.frictionloss = [0.0, 0.0, 0.0], 0.0
        notes.append("counterfactual: joint damping and frictionloss removed")
    for name in frictionless:
        g = spec.geom(name)
        g.friction = [0.0, 0.0, 0.0]
        g.condim, g.priority = 1, 1
    if frictionless:
        notes.append(f"counterfactual: {list(frictionless)} made frictionless")
    if point_wheels:
        _point_wheels(spec, (robot.left, robot.right, *robot.other_wheels), notes, published)
    spec.worldbody.add_geom(
        name="zoo_floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[0, 0, 1],
        friction=list(FLOOR_FRICTION),
        condim=3,
        contype=1,
        conaffinity=1,
    )
    model = spec.compile()
    data = mujoco.MjData(model)
    root = model.body(root_spec.name).id
    base = model.body(robot.base).id
    wheels = (model.joint(robot.left).id, model.joint(robot.right).id)
    floor = model.geom("zoo_floor").id
    mujoco.mj_forward(model, data)
    # stand on the floor: lowest collision point of the robot to z = 0
    low = min(_lowest(model, data, g) for g in range(model.ngeom) if g != floor and _collides(model, g))
    free = next(j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE)
    model.qpos0[model.jnt_qposadr[free] + 2] -= low
    mujoco.mj_resetData(model, data)
    mujoco.mj_forward(model, data)
    return Loaded(model, data, root, base, wheels, floor, published, notes)


def self_contacts(robot: Robot) -> list[dict]:
    """Pairs of the robot's own bodies in contact at qpos0 (joints as published) under MuJoCo's rules.

    MJCF as the file says; URDF with MuJoCo's defaults (every pair but parent–child collides), which
    is what a plain MuJoCo URDF import simulates and what Gazebo does not. ``depth_m`` > 0: overlap.
    """
    L = load(robot, point_wheels=False, self_collision=True, lock=False)
    m, d = L.model, L.data
    out: dict[tuple[str, str], float] = {}
    for i in range(d.ncon):
        c = d.contact[i]
        if L.floor in (c.geom1, c.geom2) or c.exclude:
            continue
        pair = tuple(sorted((m.body(m.geom_bodyid[c.geom1]).name, m.body(m.geom_bodyid[c.geom2]).name)))
        out[pair] = max(out.get(pair, 0.0), -float(c.dist))
    return [{"bodies": list(p), "depth_m": v} for p, v in sorted(out.items())]


def _collides(model: mujoco.MjModel, g: int) -> bool:
    return bool(model.geom_contype[g] or model.geom_conaffinity[g])


def _lowest(model: mujoco.MjModel, data: mujoco.MjData, g: int) -> float:
    """World z of the lowest point of geom ``g`` (exact for primitives, vertices for meshes)."""
    t = model.geom_type[g]
    s = model.geom_size[g]
    R = data.geom_xmat[g].reshape(3, 3)
    z = data.geom_xpos[g][2]
    az = R[2]  # z components of the geom's axes
    G = mujoco.mjtGeom
    if t == G.mjGEOM_SPHERE:
        return z - s[0]
    if t == G.mjGEOM_CAPSULE:
        return z - abs(az[2]) * s[1] - s[0]
    if t == G.mjGEOM_CYLINDER:
        return z - abs(az[2]) * s[1] - s[0] * math.sqrt(max(0.0, 1 - az[2] ** 2))
    if t == G.mjGEOM_BOX:
        return z - float(np.abs(az) @ s)
    if t == G.mjGEOM_ELLIPSOID:
        return z - float(np.sqrt(((az * s) ** 2).sum()))
    if t == G.mjGEOM_MESH:
        mid = model.geom_dataid[g]
        a, n = model.mesh_vertadr[mid], model.mesh_vertnum[mid]
        v = model.mesh_vert[a : a + n]
        return float((v @ R.T)[:, 2].min() + z)
    return z - float(model.geom_rbound[g])


# ----------------------------------------------------------------------------------------------- formula


def _subtree(model: mujoco.MjModel, root: int) -> list[int]:
    inside = [False] * model.nbody
    inside[root] = True
    for b in range(root + 1, model.nbody):
        inside[b] = inside[model.body_parentid[b]]
    return [b for b in range(model.nbody) if inside[b]]


def _welded(model: mujoco.MjModel, body: int) -> list[int]:
    """``body`` and every descendant joined to it without a joint (they spin with it)."""
    out = [body]
    for b in range(body + 1, model.nbody):
        if model.body_parentid[b] in out and model.body_jntnum[b] == 0:
            out.append(b)
    return out


def formula(L: Loaded) -> dict:
    """Rigid-body ``a, b`` and the parts (module docstring, step 5), from the current state of ``L.data``."""
    m, d = L.model, L.data
    mujoco.mj_kinematics(m, d)
    up = np.array([0.0, 0.0, 1.0])
    jl, jr = L.wheels
    anchors = d.xanchor[[jl, jr]]
    mid = anchors.mean(axis=0)
    bodies = _subtree(m, L.root)
    mass = float(m.body_mass[bodies].sum())
    yaw = 0.0
    for b in bodies:
        n = d.ximat[b].reshape(3, 3).T @ up
        rel = d.xipos[b] - mid
        yaw += float(n @ (m.body_inertia[b] * n)) + float(m.body_mass[b]) * float(rel @ rel - (rel @ up) ** 2)
    com = (m.body_mass[bodies, None] * d.xipos[bodies]).sum(axis=0) / mass
    rel = com - mid
    spins, radii, welded_names = [], [], []
    for j in (jl, jr):
        wb = m.jnt_bodyid[j]
        axis = d.xaxis[j]
        anchor = d.xanchor[j]
        i_w = float(m.dof_armature[m.jnt_dofadr[j]])
        for b in _welded(m, wb):
            n = d.ximat[b].reshape(3, 3).T @ axis
            rb = d.xipos[b] - anchor
            i_w += float(n @ (m.body_inertia[b] * n)) + float(m.body_mass[b]) * float(rb @ rb - (rb @ axis) ** 2)
            if b != wb:
                welded_names.append(m.body(b).name)
        spins.append(i_w)
        geoms = [g for g in range(m.ngeom) if m.geom_bodyid[g] == wb and _collides(m, g)]
        radii.append(max(anchor[2] - _lowest(m, d, g) for g in geoms) if geoms else float("nan"))
    i_w = float(np.mean(spins))
    r = float(np.mean(radii))
    dl = anchors[0] - anchors[1]
    l = 0.5 * float(np.linalg.norm(dl - (dl @ up) * up))
    a = 1.0 / (mass * r + 2 * i_w / r)
    b = l / (yaw * r + 2 * i_w * l**2 / r)
    return {
        "mass_kg": mass,
        "yaw_inertia_kgm2": yaw,
        "wheel_inertia_kgm2": i_w,
        "wheel_inertia_lr_kgm2": spins,
        "welded_to_wheels": welded_names,
        "r_m": r,
        "wheel_radius_lr_m": radii,
        "l_m": l,
        "com_from_axle_m": [float(x) for x in rel],
        "a_formula": a,
        "b_formula": b,
    }


# ----------------------------------------------------------------------------------------------- tests


def _state(L: Loaded) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return L.data.qpos.copy(), L.data.qvel.copy(), L.data.qacc_warmstart.copy()


def _restore(L: Loaded, st) -> None:
    mujoco.mj_resetData(L.model, L.data)
    L.data.qpos[:], L.data.qvel[:], L.data.qacc_warmstart[:] = st
    mujoco.mj_forward(L.model, L.data)


def _signs(L: Loaded) -> tuple[float, float]:
    """+1/−1 per wheel so that a positive torque drives forward (base x)."""
    d = L.data
    h = d.xmat[L.base].reshape(3, 3)[:, 0]
    fwd_spin = np.cross([0.0, 0.0, 1.0], h)  # a wheel rolling forward spins about up × heading
    return tuple(1.0 if float(d.xaxis[j] @ fwd_spin) > 0 else -1.0 for j in L.wheels)


def floor_contacts(L: Loaded) -> list[dict]:
    """Geoms touching our floor in the current state: body, normal load (N), friction published/simulated."""
    m, d = L.model, L.data
    agg: dict[int, dict] = {}
    f6 = np.zeros(6)
    for i in range(d.ncon):
        c = d.contact[i]
        if L.floor not in (c.geom1, c.geom2):
            continue
        g = c.geom2 if c.geom1 == L.floor else c.geom1
        mujoco.mj_contactForce(m, d, i, f6)
        e = agg.setdefault(
            int(g),
            {
                "load_n": 0.0,
                "pos": np.zeros(3),
                "friction_simulated": float(c.friction[0]),
                "condim_simulated": int(c.dim),
            },
        )
        e["load_n"] += float(f6[0])
        e["pos"] += float(f6[0]) * c.pos
    out = []
    for g, e in sorted(agg.items()):
        name = m.geom(g).name
        pub = L.published.get(name, {})
        out.append(
            {
                "geom": name,
                "body": m.body(m.geom_bodyid[g]).name,
                "load_n": round(e["load_n"], 4),
                "friction_published": pub.get("friction"),
                "condim_published": pub.get("condim"),
                "friction_simulated": e["friction_simulated"],
                "condim_simulated": e["condim_simulated"],
                "pos_m": [float(x) for x in e["pos"] / max(e["load_n"], 1e-12)],
            }
        )
    return out


def statics(L: Loaded, f: dict, contacts: list[dict], wheel_geoms: set[str], tau_max: float) -> dict:
    """Traction and tip-over from the contacts at rest (all in the base heading frame, from the axle midpoint).

    Traction: with both wheels at ``τ``, ``υ̇ = 2 a τ`` and each driven wheel pushes ``≈ m a τ`` on the
    floor (the rest of the torque spins the rotor), so it skids above ``τ_skid = μ N / (m a)`` for its
    load ``N``. Tip-over: accelerating at ``υ̇`` tips the chassis about its rearmost support once
    ``υ̇ > g (c_x − x_rear)/h``, braking about the foremost once ``υ̇ > g (x_front − c_x)/h``, turning
    sideways once ``υω > g min(y_left − c_y, c_y − y_right)/h`` (``c`` the centre of mass, ``h`` its height).
    """
    m, d = L.model, L.data
    g = 9.81
    R = d.xmat[L.base].reshape(3, 3)
    hx = R[:, 0].copy()
    hx[2] = 0
    hx /= np.linalg.norm(hx)
    hy = np.cross([0.0, 0.0, 1.0], hx)
    mid = d.xanchor[list(L.wheels)].mean(axis=0)
    bodies = _subtree(m, L.root)
    com = (m.body_mass[bodies, None] * d.xipos[bodies]).sum(axis=0) / m.body_mass[bodies].sum()
    cx, cy, h = float((com - mid) @ hx), float((com - mid) @ hy), float(com[2])
    pts = [np.array(c["pos_m"]) - mid for c in contacts if c["load_n"] > 1e-6]
    xs = [float(p @ hx) for p in pts]
    ys = [float(p @ hy) for p in pts]
    wheel = [c for c in contacts if c["geom"] in wheel_geoms]
    n_min = min((c["load_n"] for c in wheel), default=0.0)
    mu = min((c["friction_simulated"] for c in wheel), default=0.0)
    tau_skid = mu * n_min / (f["mass_kg"] * f["a_formula"]) if wheel else 0.0
    weight = f["mass_kg"] * g
    return {
        "com_height_m": h,
        "support_x_m": [min(xs), max(xs)],
        "support_y_m": [min(ys), max(ys)],
        "tip_accel_mps2": {
            "forward": g * (cx - min(xs)) / h,
            "backward": g * (max(xs) - cx) / h,
            "lateral": g * min(max(ys) - cy, cy - min(ys)) / h,
        },
        "weight_on_driven_wheels": sum(c["load_n"] for c in wheel) / weight,
        "traction_torque_nm": tau_skid,
        "traction_torque_naive_nm": mu * n_min * f["r_m"],
        "tau_max_nm": tau_max,
        "full_torque_accel_mps2": 2 * tau_max * f["a_formula"],
    }


def _run(L: Loaded, st, tau_l: float, tau_r: float, signs) -> dict:
    """One constant-torque test from the settled state ``st``: CoM forward speed and yaw rate series."""
    m, d = L.model, L.data
    _restore(L, st)
    dl, dr = (m.jnt_dofadr[j] for j in L.wheels)
    n = round(RUN_S / m.opt.timestep)
    t = np.empty(n)
    v = np.empty(n)
    w = np.empty(n)
    pitch = np.empty(n)
    free_dof = m.jnt_dofadr[next(j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE)]
    mujoco.mj_subtreeVel(m, d)
    h0 = d.xmat[L.base].reshape(3, 3)[:, 0].copy()
    h0[2] = 0.0
    h0 /= np.linalg.norm(h0)
    v0 = float(d.subtree_linvel[L.root] @ h0)
    w0 = float((d.xmat[L.root].reshape(3, 3) @ d.qvel[free_dof + 3 : free_dof + 6])[2])
    for k in range(n):
        d.qfrc_applied[:] = 0
        d.qfrc_applied[dl] = signs[0] * tau_l
        d.qfrc_applied[dr] = signs[1] * tau_r
        mujoco.mj_step(m, d)
        mujoco.mj_subtreeVel(m, d)
        R = d.xmat[L.base].reshape(3, 3)
        h = R[:, 0].copy()
        h[2] = 0.0
        h /= np.linalg.norm(h)
        t[k] = d.time
        v[k] = float(d.subtree_linvel[L.root] @ h)
        Rr = d.xmat[L.root].reshape(3, 3)
        w[k] = float((Rr @ d.qvel[free_dof + 3 : free_dof + 6])[2])  # free joint: local angular velocity
        pitch[k] = math.asin(max(-1.0, min(1.0, -R[2, 0])))
    t -= t[0] - m.opt.timestep
    return {"t": t, "v": v, "w": w, "pitch": pitch, "v0": v0, "w0": w0}


def _rate(t: np.ndarray, y: np.ndarray, y0: float, damped: bool) -> tuple[float, float]:
    """``(α, β)`` of ``ẏ = α + β y``: without wheel damping ``β = 0`` and ``α`` is the slope of ``y(t)`` over
    WINDOW_S; with damping (a drag that settles within milliseconds) a least-squares fit of the forward
    differences against the new value (MuJoCo integrates joint damping implicitly) over the whole test."""
    if not damped:
        sel = (t >= WINDOW_S[0]) & (t <= WINDOW_S[1])
        return float(np.polyfit(t[sel], y[sel], 1)[0]), 0.0
    yy = np.concatenate([[y0], y])
    dt = float(t[1] - t[0])
    rate = np.diff(yy) / dt
    A = np.column_stack([np.ones(len(y)), y])
    (alpha, beta), *_ = np.linalg.lstsq(A, rate, rcond=None)
    return float(alpha), float(beta)


def _swivels(L: Loaded) -> list[tuple[int, float, np.ndarray]]:
    """Free vertical hinges carrying a trailing caster: ``(joint id, trail angle at qpos0, anchor)``.

    The trail is the horizontal offset from the swivel axis to the centre of the lowest collision geom
    below it (the roller); its angle is measured in the base heading frame.
    """
    m, d = L.model, L.data
    mujoco.mj_resetData(m, d)
    mujoco.mj_forward(m, d)
    R = d.xmat[L.base].reshape(3, 3)
    out = []
    for j in range(m.njnt):
        if m.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE or j in L.wheels or abs(d.xaxis[j][2]) < 0.9:
            continue
        geoms = [g for g in range(m.ngeom) if m.geom_bodyid[g] in _subtree(m, m.jnt_bodyid[j]) and _collides(m, g)]
        if not geoms:
            continue
        g = min(geoms, key=lambda g: _lowest(m, d, g))
        trail = R.T @ (d.geom_xpos[g] - d.xanchor[j])
        if math.hypot(trail[0], trail[1]) < 1e-4:
            continue
        out.append((j, math.atan2(trail[1], trail[0]), R.T @ d.xanchor[j]))
    return out


def _settle(L: Loaded, swivels, turn: bool, mid: np.ndarray) -> tuple:
    """Reset, set every swivel so its caster trails the motion of the coming test, settle; the state."""
    m, d = L.model, L.data
    mujoco.mj_resetData(m, d)
    for j, theta0, anchor in swivels:
        rel = anchor - mid
        v = np.array([-rel[1], rel[0]]) if turn else np.array([1.0, 0.0])  # anchor velocity (base frame)
        want = math.atan2(-v[1], -v[0])  # the roller behind the swivel axis
        d.qpos[m.jnt_qposadr[j]] = math.remainder(want - theta0, 2 * math.pi)
    mujoco.mj_forward(m, d)
    for _ in range(round(SETTLE_S / m.opt.timestep)):
        mujoco.mj_step(m, d)
    return _state(L)


def _levels(L: Loaded, st, torques: list[float], turn: bool, signs, damped: bool) -> tuple:
    """The drive (``τ_L = τ_R = T``) or turn (``τ_R = −τ_L = T``) tests at each ``T`` of ``torques`` from the
    settled state ``st``: ``(slope, intercept, accelerations, drag rates, pitch range rad)`` with the slope and
    intercept of the accelerations (CoM forward / yaw) against ``τ_a = 2 T`` resp. ``τ_b = 2 T``."""
    acc, drag, pitch = [], [], 0.0
    for T in torques:
        r = _run(L, st, -T if turn else T, T, signs)
        alpha, beta = _rate(r["t"], r["w" if turn else "v"], r["w0" if turn else "v0"], damped)
        acc.append(alpha)
        drag.append(-beta)
        pitch = max(pitch, float(np.ptp(r["pitch"])))
    slope, intercept = np.polyfit(2 * np.array(torques), acc, 1)
    return slope, intercept, acc, drag, pitch


def identify(L: Loaded, f: dict) -> dict:
    """Settle, record the floor contacts, run the drive and turn tests at three levels; fit ``a_id, b_id``.

    Free caster swivels (:func:`_swivels`) start each test trailing the motion it makes (their steady
    state), so the start-up transient is not a caster turning round.
    """
    m, d = L.model, L.data
    swivels = _swivels(L)
    mujoco.mj_resetData(m, d)
    mujoco.mj_kinematics(m, d)
    R0 = d.xmat[L.base].reshape(3, 3)
    mid0 = R0.T @ d.xanchor[list(L.wheels)].mean(axis=0)
    st_turn = _settle(L, swivels, True, mid0) if swivels else None
    st = _settle(L, swivels, False, mid0)
    if st_turn is None:
        st_turn = st
    contacts = floor_contacts(L)
    f_rest = formula(L)  # the configuration that runs (settled)
    signs = _signs(L)
    fl = float(np.mean([m.dof_frictionloss[m.jnt_dofadr[j]] for j in L.wheels]))
    damp = float(np.mean([m.dof_damping[m.jnt_dofadr[j]] for j in L.wheels]))
    a_f, b_f, l = f_rest["a_formula"], f_rest["b_formula"], f_rest["l_m"]
    turn_max = min(max(ACCELS) / l, TURN_RATE_MAX / RUN_S)  # rad/s²
    drive_t = [fl + acc / (2 * a_f) for acc in ACCELS]
    turn_t = [fl + turn_max * k / len(ACCELS) / (2 * b_f) for k in range(1, len(ACCELS) + 1)]
    # a drag that settles within the test is fitted as ẏ = α + β y; one that settles within a few steps
    # (k dt > 0.2) leaves nothing to fit at these torques: the speed is the damping's, the cause is named
    k_est = 2 * a_f * damp / f_rest["r_m"]
    damped = damp > 0 and k_est * m.opt.timestep < 0.2
    a_id, c_v, acc_v, drag_v, pitch_amp = _levels(L, st, drive_t, False, signs, damped)
    b_id, c_w, acc_w, drag_w, _ = _levels(L, st_turn, turn_t, True, signs, damped)
    _restore(L, st)  # leave the robot at rest where it settled (statics() reads it)
    return {
        "floor_contacts": contacts,
        "formula_settled": f_rest,
        "a_identified": float(a_id),
        "b_identified": float(b_id),
        "deadband_tau_a_nm": float(-c_v / a_id) if a_id else None,
        "deadband_tau_b_nm": float(-c_w / b_id) if b_id else None,
        "test": {
            "timestep_s": float(m.opt.timestep),
            "integrator": mujoco.mjtIntegrator(m.opt.integrator).name,
            "drive_torques_nm": drive_t,
            "turn_torques_nm": turn_t,
            "drive_accel_mps2": acc_v,
            "turn_accel_radps2": acc_w,
            "pitch_range_deg": math.degrees(pitch_amp),
            "wheel_frictionloss_nm": fl,
            "wheel_damping_nms": damp,
            "drag_rate_identified_per_s": [float(np.mean(drag_v)), float(np.mean(drag_w))] if damped else None,
        },
    }


def reference(robot: Robot) -> dict:
    """The full reference record of one robot (what expectations.json holds per robot)."""
    L = load(robot)
    f0 = formula(L)
    ident = identify(L, f0)
    fs = ident.pop("formula_settled")
    Lp = load(robot, point_wheels=False)
    ident_p = identify(Lp, formula(Lp))
    fp = ident_p.pop("formula_settled")
    published_wheels = {
        "a_identified": ident_p["a_identified"],
        "b_identified": ident_p["b_identified"],
        "relative_error": {
            "a": ident_p["a_identified"] / fp["a_formula"] - 1,
            "b": ident_p["b_identified"] / fp["b_formula"] - 1,
        },
        "floor_contacts": ident_p["floor_contacts"],
    }
    ea = ident["a_identified"] / fs["a_formula"] - 1
    eb = ident["b_identified"] / fs["b_formula"] - 1
    notes = list(L.notes)
    for k in ("a_formula", "b_formula"):
        if abs(fs[k] / f0[k] - 1) > 1e-3:
            notes.append(f"{k} at rest differs from qpos0 by {100 * (fs[k] / f0[k] - 1):+.2f} %")
    if fs["welded_to_wheels"]:
        notes.append(f"bodies welded to the wheels (in I_w): {fs['welded_to_wheels']}")
    if abs(fs["wheel_radius_lr_m"][0] - fs["wheel_radius_lr_m"][1]) > 1e-6:
        notes.append(f"left/right wheel radii differ: {fs['wheel_radius_lr_m']} m (mean used)")
    if abs(fs["wheel_inertia_lr_kgm2"][0] - fs["wheel_inertia_lr_kgm2"][1]) > 1e-12:
        notes.append(f"left/right wheel inertia differ: {fs['wheel_inertia_lr_kgm2']} (mean used)")
    wheel_bodies = [L.model.jnt_bodyid[L.model.joint(j).id] for j in (robot.left, robot.right, *robot.other_wheels)]
    wheel_geoms = {L.model.geom(g).name for g in range(L.model.ngeom) if L.model.geom_bodyid[g] in wheel_bodies}
    m_ = L.model
    passive = set()  # bodies that move on a free passive joint (caster swivel/roller): they roll, not brake
    for jn in robot.free_joints:
        passive.update(m_.body(b).name for b in _subtree(m_, m_.jnt_bodyid[m_.joint(jn).id]))
    other = [c for c in ident["floor_contacts"] if c["geom"] not in wheel_geoms and c["body"] not in passive]
    braking = [  # condim 1: frictionless whatever its friction
        c for c in other if c["friction_simulated"] >= FRICTIONLESS and c["condim_simulated"] > 1 and c["load_n"] > 1e-3
    ]
    if braking:
        notes.append(
            "non-driven geoms with friction carry load at rest (they brake): "
            + ", ".join(f"{c['geom']} {c['load_n']:.3g} N μ {c['friction_simulated']:g}" for c in braking)
        )
    st = statics(L, fs, ident["floor_contacts"], wheel_geoms, robot.tau_max)
    damp = ident["test"]["wheel_damping_nms"]
    if damp:
        k = 2 * fs["a_formula"] * damp / fs["r_m"]
        notes.append(f"wheel damping {damp:g} N·m·s/rad: drag rate 2 a c/r = {k:.3g} 1/s (time constant {1 / k:.3g} s)")
    if st["tau_max_nm"] > st["traction_torque_nm"]:
        notes.append(
            f"motor limit {robot.tau_max:g} N·m above the traction limit μ N/(m a) = {st['traction_torque_nm']:.3g} N·m"
        )
    agree = abs(ea) <= AGREE and abs(eb) <= AGREE
    cause = ""
    if not agree:
        causes = []
        if robot.kind == "skid-steer":
            causes.append("skid-steer: the free-rolling wheels resist turning by lateral slip")
        if braking:
            causes.append("braking contact: " + ", ".join(c["geom"] for c in braking))
        if damp and 2 * fs["a_formula"] * damp / fs["r_m"] * RUN_S > 0.1:
            causes.append("wheel damping")
        if ident["test"]["wheel_frictionloss_nm"] and damp:
            causes.append("wheel frictionloss")
        cause = "; ".join(causes) or "unexplained"
    all_wheels = None
    if robot.other_wheels:  # the free-rolling wheels spin too: their inertia belongs in M_eff when driving straight
        m_ = L.model
        extra = 0.0
        for jn in robot.other_wheels:
            j = m_.joint(jn).id
            wb = m_.jnt_bodyid[j]
            ax = L.data.xaxis[j]
            for b in _welded(m_, wb):
                n = L.data.ximat[b].reshape(3, 3).T @ ax
                extra += float(n @ (m_.body_inertia[b] * n))
            extra += float(m_.dof_armature[m_.jnt_dofadr[j]])
        r_ = fs["r_m"]
        a_all = 1.0 / (fs["mass_kg"] * r_ + (2 * fs["wheel_inertia_kgm2"] + extra) / r_)
        all_wheels = {"a_formula": a_all, "relative_error_a": ident["a_identified"] / a_all - 1}
        notes.append(
            f"with the {len(robot.other_wheels)} free wheels' spin inertia in M_eff, a = {a_all:.4g}: identified "
            f"{100 * all_wheels['relative_error_a']:+.2f} %"
        )
    counterfactual = None
    if braking:  # the same tests with the braking geoms frictionless: is the named contact the cause?
        Lc = load(robot, frictionless=tuple(c["geom"] for c in braking))
        ident_c = identify(Lc, formula(Lc))
        fc = ident_c.pop("formula_settled")
        counterfactual = {
            "frictionless": [c["geom"] for c in braking],
            "relative_error": {
                "a": ident_c["a_identified"] / fc["a_formula"] - 1,
                "b": ident_c["b_identified"] / fc["b_formula"] - 1,
            },
        }
    removed = None
    if cause and robot.kind != "skid-steer" and ("damping" in cause or "frictionloss" in cause):
        Lr = load(robot, frictionless=tuple(c["geom"] for c in braking), lossless=True)
        ident_r = identify(Lr, formula(Lr))
        fr = ident_r.pop("formula_settled")
        removed = {
            "frictionless": [c["geom"] for c in braking],
            "joint_damping_and_frictionloss": "removed",
            "relative_error": {
                "a": ident_r["a_identified"] / fr["a_formula"] - 1,
                "b": ident_r["b_identified"] / fr["b_formula"] - 1,
            },
        }
    return {
        "name": robot.name,
        "maker": robot.maker,
        "collection": robot.collection,
        "format": robot.format,
        "file": robot.file,
        "source": robot.source,
        "license": robot.license,
        "kind": robot.kind,
        "mapping": {"base": robot.base, "left_wheel": robot.left, "right_wheel": robot.right},
        "packages": robot.packages,
        "mass_kg": fs["mass_kg"],
        "yaw_inertia_kgm2": fs["yaw_inertia_kgm2"],
        "wheel_inertia_kgm2": fs["wheel_inertia_kgm2"],
        "r_m": fs["r_m"],
        "l_m": fs["l_m"],
        "com_from_axle_m": fs["com_from_axle_m"],
        "a_formula": fs["a_formula"],
        "b_formula": fs["b_formula"],
        "a_formula_qpos0": f0["a_formula"],
        "b_formula_qpos0": f0["b_formula"],
        "a_identified": ident["a_identified"],
        "b_identified": ident["b_identified"],
        "relative_error": {"a": ea, "b": eb},
        "agrees_within_5pct": agree,
        "disagreement_cause": cause,
        "deadband_tau_a_nm": ident["deadband_tau_a_nm"],
        "deadband_tau_b_nm": ident["deadband_tau_b_nm"],
        "floor_contacts": ident["floor_contacts"],
        "statics": st,
        "tau_max_source": robot.tau_max_source,
        "top_speed_mps": robot.top_speed or None,
        "top_speed_source": robot.top_speed_source,
        "control_rate_hz": robot.control_rate or None,
        "control_rate_source": robot.control_rate_source,
        "test": ident["test"],
        "published_wheel_shapes": published_wheels,
        "self_contacts_mujoco_rules": self_contacts(robot),
        "braking_geoms_frictionless": counterfactual,
        "named_causes_removed": removed,
        "all_wheels": all_wheels,
        "notes": notes,
        "expected_verdict": robot.expected_verdict,
        "expected_cause": robot.expected_cause,
    }


def _round(x):
    if isinstance(x, float):
        return float(f"{x:.6g}")
    if isinstance(x, dict):
        return {k: _round(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_round(v) for v in x]
    return x


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--write", action="store_true", help=f"write {EXPECTATIONS.name}")
    p.add_argument("--robot", action="append", help="only this robot (repeatable)")
    args = p.parse_args(argv)
    robots = [r for r in ROBOTS if not args.robot or r.name in args.robot]
    if args.robot and len(robots) != len(args.robot):
        print(f"error: unknown robot in {args.robot}; known: {[r.name for r in ROBOTS]}", file=sys.stderr)
        return 2
    out = {}
    for r in robots:
        rec = _round(reference(r))
        out[r.name] = rec
        print(
            f"{r.name:24s} m {rec['mass_kg']:8.3f} kg  a {rec['a_formula']:.5g} id {rec['a_identified']:.5g} "
            f"({100 * rec['relative_error']['a']:+.2f} %)  b {rec['b_formula']:.5g} id {rec['b_identified']:.5g} "
            f"({100 * rec['relative_error']['b']:+.2f} %)  {rec['disagreement_cause']}"
        )
        pw = rec["published_wheel_shapes"]["relative_error"]
        print(f"    published wheel shapes: a {100 * pw['a']:+.2f} %  b {100 * pw['b']:+.2f} %")
        if rec["braking_geoms_frictionless"]:
            cf = rec["braking_geoms_frictionless"]["relative_error"]
            print(f"    braking geoms frictionless: a {100 * cf['a']:+.2f} %  b {100 * cf['b']:+.2f} %")
        if rec["named_causes_removed"]:
            cf = rec["named_causes_removed"]["relative_error"]
            print(f"    every named cause removed: a {100 * cf['a']:+.2f} %  b {100 * cf['b']:+.2f} %")
        for c in rec["floor_contacts"]:
            print(
                f"    {c['geom']:32s} {c['body']:24s} {c['load_n']:9.4f} N  μ pub {c['friction_published']} "
                f"sim {c['friction_simulated']:g} condim {c['condim_simulated']}"
            )
        for n in rec["notes"]:
            print("    note:", n)
    if args.write:
        if args.robot:
            old = json.loads(EXPECTATIONS.read_text()) if EXPECTATIONS.exists() else {}
            old.update(out)
            out = {r.name: old[r.name] for r in ROBOTS if r.name in old}
        tmp = EXPECTATIONS.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(out, indent=1, ensure_ascii=False) + "\n")
        tmp.replace(EXPECTATIONS)
        print(f"wrote {EXPECTATIONS}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

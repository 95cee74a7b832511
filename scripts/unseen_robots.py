"""The table "Robots the tests had not seen" of docs/real-robot.md, reproduced (issue 29): each published robot
recorded 60 s by the test recorder (``tests/realdata_recorder.py``: a plain MuJoCo loop and ``rosbags``' writer,
none of the fit's code) with a payload, wheel damping and dry friction changed from its file, then fitted by
``bioform robot fit`` with the flags a user gives, one robot at a time. Prints per parameter the fitted value, its
95 % half-width, the truth, whether the interval holds it and the fit's status, with the wall time and load.

The robots are the zoo's files under ``tests/zoo`` (Kobuki, TIAGo, Create 3, Husky, PMB-2, TurtleBot3 Waffle Pi);
Fetch's Freight is not committed: give ``--fetch-description`` (a checkout of fetch_ros' ``fetch_description``).

    PYTHONPATH=src python scripts/unseen_robots.py [--robots kobuki,waffle,...] [--out DIR] [--fetch-description P]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
Z = ROOT / "tests" / "zoo"


def _absolute(urdf: Path, pkg: str, folder: Path, out: Path) -> str:
    """``urdf`` with ``package://pkg/`` made absolute (MuJoCo's own URDF parser, which the recorder uses, has no
    package paths); written into ``out``."""
    p = out / f"{urdf.stem}_{pkg}_abs.urdf"
    p.write_text(urdf.read_text().replace(f"package://{pkg}/", f"{folder}/"))
    return str(p)


def robots(rr, out: Path, fetch: Path | None) -> dict[str, dict]:
    """name -> recorder file, truth, torque scale (N·m), program seed, the fit's file and flags (the table's rows)."""
    wheels = ("wheel_left_joint", "wheel_right_joint")
    lr = ["--left-wheel", wheels[0], "--right-wheel", wheels[1]]
    c3 = Z / "create3_urdf" / "irobot_create_description"
    hu = Z / "husky_urdf" / "husky_description"
    pm = Z / "pmb2_urdf" / "pmb2_description"
    waffle = Z / "tb3_waffle_pi_urdf" / "turtlebot3_waffle_pi.urdf"
    swivels = tuple(f"caster_{a}_{b}_{k}_joint" for a in ("front", "back") for b in ("right", "left") for k in (1, 2))
    tiago_held = ("torso_lift_joint", "head_1_joint", "head_2_joint", *[f"arm_{k}_joint" for k in range(1, 8)])
    tiago_held += ("gripper_right_finger_joint", "gripper_left_finger_joint")
    pmb2 = dict(
        rec=lambda: _absolute(Z / "pmb2_urdf" / "pmb2.urdf", "pmb2_description", pm, out),
        truth=rr.Truth(payload_kg=10.0, payload_yaw_kgm2=0.2, damping=(0.04, 0.05), frictionloss=(0.1, 0.08),
                       joints=wheels, base="base_link", odom_body="base_footprint"),
        tau=1.2, seed=5, model=str(Z / "pmb2_urdf" / "pmb2.urdf"),
        flags=["--base", "base_footprint", *lr, "--package-path", f"pmb2_description={pm}"],
    )  # fmt: skip
    create3 = dict(
        rec=lambda: _absolute(Z / "create3_urdf" / "create3.urdf", "irobot_create_description", c3, out),
        truth=rr.Truth(payload_kg=0.5, payload_yaw_kgm2=0.005, damping=(0.0005, 0.0006), frictionloss=(0.004, 0.003),
                       caster_friction=0.15, casters=("front_caster_link",),
                       joints=("left_wheel_joint", "right_wheel_joint"), base="base_link"),
        tau=0.0581, seed=5, model=str(Z / "create3_urdf" / "create3.urdf"),
        flags=["--base", "base_link", "--left-wheel", "left_wheel_joint", "--right-wheel", "right_wheel_joint",
               "--package-path", f"irobot_create_description={c3}", "--caster", "front_caster_link",
               "--tau-max", "0.5"],
    )  # fmt: skip
    rows = {
        "kobuki": dict(rec=lambda: str(rr.KOBUKI_URDF), truth=rr.KOBUKI_TRUTH, tau=rr.KOBUKI_TAU, seed=3,
                       model=str(rr.KOBUKI_URDF), flags=["--base", "base_footprint", *lr, "--tau-max", "1"]),
        "tiago": dict(rec=lambda: str(Z / "menagerie_tiago" / "tiago.xml"),
                      truth=rr.Truth(payload_kg=8.0, payload_yaw_kgm2=0.5, damping=(0.08, 0.1), frictionloss=(0.3, 0.4),
                                     joints=wheels, base="base_link", recorded=swivels, held=tiago_held,
                                     point_wheels=True),
                      tau=3.88, seed=5, model=str(Z / "menagerie_tiago" / "tiago.xml"),
                      flags=["--base", "base_link", *lr]),
        "create3": create3,
        "create3_free": dict(create3, flags=[*create3["flags"], "--free-joints"], bag="create3"),
        "husky": dict(rec=lambda: _absolute(Z / "husky_urdf" / "husky.urdf", "husky_description", hu, out),
                      truth=rr.Truth(payload_kg=10.0, payload_yaw_kgm2=1.0, damping=(0.2, 0.25),
                                     frictionloss=(0.4, 0.3),
                                     joints=("front_left_wheel", "front_right_wheel"),
                                     coupled=("rear_left_wheel", "rear_right_wheel"),
                                     recorded=("rear_left_wheel", "rear_right_wheel"), base="inertial_link",
                                     odom_body="base_link"),
                      tau=4.94, seed=5, model=str(Z / "husky_urdf" / "husky.urdf"),
                      flags=["--base", "base_link", "--left-wheel", "front_left_wheel", "--right-wheel",
                             "front_right_wheel", "--package-path", f"husky_description={hu}", "--tau-max", "20"]),
        "pmb2": pmb2,
        "pmb2_rec": dict(pmb2, truth=dataclasses.replace(pmb2["truth"], recorded=swivels)),
        "pmb2_rec_free": dict(pmb2, truth=dataclasses.replace(pmb2["truth"], recorded=swivels),
                              flags=[*pmb2["flags"], "--free-joints"], bag="pmb2_rec"),
        "waffle": dict(rec=lambda: str(waffle),
                       truth=rr.Truth(payload_kg=0.5, payload_yaw_kgm2=0.004, damping=(0.002, 0.0025),
                                      frictionloss=(0.004, 0.003), caster_friction=0.0,
                                      casters=("caster_back_right_link", "caster_back_left_link"), joints=wheels,
                                      base="base_link", odom_body="base_footprint"),
                       tau=0.1, seed=5, model=str(waffle),
                       flags=["--base", "base_footprint", *lr, "--caster", "caster_back_right_link", "--caster",
                              "caster_back_left_link", "--caster-friction", "0", "--tau-max", "1"]),
    }  # fmt: skip
    if fetch is not None:
        freight = fetch / "robots" / "freight.urdf"
        rows["freight"] = dict(
            rec=lambda: _absolute(freight, "fetch_description", fetch, out),
            truth=rr.Truth(payload_kg=15.0, payload_yaw_kgm2=0.3, damping=(0.05, 0.06), frictionloss=(0.08, 0.06),
                           caster_friction=0.0, casters=("base_link",), joints=("l_wheel_joint", "r_wheel_joint"),
                           base="base_link"),
            tau=1.5, seed=5, model=str(freight),
            flags=["--base", "base_link", "--left-wheel", "l_wheel_joint", "--right-wheel", "r_wheel_joint",
                   "--package-path", f"fetch_description={fetch}", "--caster", "base_link", "--caster-friction", "0"],
        )  # fmt: skip
    return rows


def fit_row(name: str, cfg: dict, bag: Path, out: Path) -> None:
    """Fit one row's recording with ``bioform robot fit`` and print each parameter against the truth."""
    tr = cfg["truth"]
    res = out / "fits" / name
    shutil.rmtree(res, ignore_errors=True)
    cmd = [sys.executable, "-m", "bioform_mj.cli", "robot", "fit", cfg["model"], *cfg["flags"], "--bag", str(bag)]
    cmd += ["--out", str(res)]
    load0, t0 = Path("/proc/loadavg").read_text().split()[0], time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall, load1 = time.perf_counter() - t0, Path("/proc/loadavg").read_text().split()[0]
    print(f"=== {name}: exit {p.returncode}, {wall:.1f} s wall, load {load0} -> {load1}", flush=True)
    if p.returncode:
        print(p.stderr.strip().splitlines()[-1:])
        return
    rep = json.loads((res / "fit.json").read_text())
    pub = {q["name"]: q["published"] for q in rep["parameters"]}
    truth = tr.values(pub.get("mass", 0.0), pub.get("yaw_inertia", 0.0)) | {"caster_friction": tr.caster_friction}
    for q in rep["parameters"]:
        t, ci, hw = truth.get(q["name"]), q["ci95"], q["ci95_halfwidth"]
        holds = "-" if ci is None or t is None else ("holds" if ci[0] <= t <= ci[1] else "OUTSIDE")
        h = "inf" if hw is None else f"{hw:.2g}"
        print(f"  {q['name']:15} {q['fitted']:.5g} ± {h}; truth {t:.5g}; {holds}; {q['status']}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", default="kobuki,tiago,create3,create3_free,husky,pmb2,pmb2_rec,pmb2_rec_free,waffle")
    ap.add_argument("--out", default=None, help="keep recordings and fits here (default: a temporary folder)")
    ap.add_argument("--fetch-description", type=Path, default=None, help="fetch_description folder (adds freight)")
    a = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT / "tests"))
    import realdata_recorder as rr

    tmp = tempfile.TemporaryDirectory(prefix="unseen-") if a.out is None else None
    out = Path(a.out if a.out is not None else tmp.name)  # type: ignore[union-attr]
    out.mkdir(parents=True, exist_ok=True)
    rows = robots(rr, out, a.fetch_description)
    names = [n for n in a.robots.split(",") if n]
    if bad := [n for n in names if n not in rows]:
        print(f"error: unknown robot {bad[0]!r} (known: {', '.join(rows)})", file=sys.stderr)
        return 2
    for name in names:
        cfg = rows[name]
        bag = out / "bags" / cfg.get("bag", name)
        if not bag.exists():
            t0 = time.perf_counter()
            rr.record(bag, cfg["rec"](), cfg["truth"], duration=60.0, tau=cfg["tau"], seed=cfg["seed"])
            print(f"recorded {bag.name}: 60 s in {time.perf_counter() - t0:.1f} s", flush=True)
        fit_row(name, cfg, bag, out)
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

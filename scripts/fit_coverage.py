"""How often `bioform robot fit`'s 95 % intervals hold the truth (issue 29; design §8.4): recordings of robots
whose true parameters differ from their published files, made by the test recorder (``tests/realdata_recorder.py``:
a plain MuJoCo loop and ``rosbags``' writer, none of the fit's code), fitted, and each interval checked against
the truth. The intervals are recomputed from the fit's residual and Jacobian at its optimum both ways (``CR1``: the
plain cluster-robust sandwich, the fit's default before; ``CR3``: the leave-one-chunk-out jackknife, its default
now), each the wider of it and the autocorrelation-widened independent-residual interval, as the fit does.

Prints per fit one line (fitted − truth over the CR3 half-width per parameter, the chunks used, wall and CPU
seconds), then per robot and overall: coverage, RMS of (fitted − truth)/half-width (about 0.51 for an exact 95 %
interval of a normal error), median half-width over the truth; and (kind ``fit``) the intervals and statuses the
fit reports: of the parameters called ``identified``, how many intervals miss the truth (an under-covering
interval called found). ``--noise-seeds`` several with one ``--programs`` seed: the spread that the sensor noise
alone makes (bias against spread). ``--seconds 12`` with ``--chunk`` unset: the fit's own chunk length for a short
recording (design §8.4).

    PYTHONPATH=src python scripts/fit_coverage.py [--robots kobuki,tb3,lab] [--programs 11-18] [--seconds 60]
        [--chunk S]
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _robots(rr):
    from bioform_mj.robots.refs import RobotRef, as_ref

    kobuki = rr.KOBUKI_URDF
    return {  # name: (robot file for the recorder, truth, torque scale N·m, the fit's mapping)
        "kobuki": (
            str(kobuki),
            rr.KOBUKI_TRUTH,
            rr.KOBUKI_TAU,
            RobotRef(
                model=str(kobuki),
                base="base_footprint",
                left_wheel="wheel_left_joint",
                right_wheel="wheel_right_joint",
                tau_max=1.0,
            ),
        ),
        "tb3": (
            "tb3",
            rr.Truth(payload_kg=0.3, payload_yaw_kgm2=0.001, damping=(0.002, 0.0025), frictionloss=(0.004, 0.003)),
            0.025,
            as_ref("tb3"),
        ),
        "lab": (
            "lab",
            rr.Truth(payload_kg=0.5, payload_yaw_kgm2=0.0004, damping=(0.003, 0.002), frictionloss=(0.006, 0.008)),
            0.06,
            as_ref("lab"),
        ),
    }


def _seeds(text: str) -> list[int]:
    out = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b or a) + 1))
    return out


def _halfwidths(res) -> dict[str, np.ndarray]:
    """Both kinds of interval recomputed from the fit's residual and Jacobian, as the fit computes its own
    (:func:`~bioform_mj.robots.realdata.intervals.halfwidths`, without the remaining step), in the parameters' units."""
    from bioform_mj.robots.realdata.intervals import halfwidths

    r, J, G, s = res.residual, res.jacobian, res.n_chunks, res.n_signals
    return {k: halfwidths(r, J, G, s, kind=k)[0] * res.scales for k in ("CR1", "CR3")}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", default="kobuki,tb3,lab")
    ap.add_argument("--programs", default="11-18", help="torque-program seeds, e.g. 11-18 or 3,5")
    ap.add_argument("--noise-seeds", default="", help="sensor-noise seeds (default: program seed + 100)")
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--time-budget", type=float, default=600.0)
    ap.add_argument("--chunk", type=float, default=None, help="chunk length, s (default: the fit's choice)")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "tests"))
    import realdata_recorder as rr
    from bioform_mj.robots.realdata.fit import fit
    from bioform_mj.robots.realdata.recording import read_recording
    from bioform_mj.robots.realdata.simmodel import other_joints, sim_spec

    table = _robots(rr)
    robots = args.robots.split(",")
    bad = [r for r in robots if r not in table]
    if bad:
        print(f"error: --robots: unknown '{bad[0]}' (known: {', '.join(table)})", file=sys.stderr)
        return 2
    got: dict[str, list] = {r: [] for r in robots}
    with tempfile.TemporaryDirectory() as tmp:
        for name in robots:
            file, truth, tau, ref = table[name]
            path = Path(file) if file.endswith((".urdf", ".xml")) else rr.MODELS / f"{file}_robot.xml"
            model = rr.true_model(path, truth)
            for prog in _seeds(args.programs):
                sim = rr.simulate(model, truth, args.seconds, tau, prog)
                for noise in _seeds(args.noise_seeds) if args.noise_seeds else [prog + 100]:
                    bag = Path(tmp) / f"{name}_{prog}_{noise}"
                    rr.write_bag(bag, sim, truth, seed=noise)
                    robot = sim_spec(ref)
                    rec = read_recording(bag, truth.joints, None, other_joints(robot))
                    t0, c0 = time.perf_counter(), time.process_time()
                    kw = {} if args.chunk is None else {"chunk_s": args.chunk}
                    res, _ = fit(robot, rec, time_budget_s=args.time_budget, progress=False, **kw)
                    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
                    shutil.rmtree(bag)
                    names = [p["name"] for p in res.parameters]
                    pub = {p["name"]: p["published"] for p in res.parameters}
                    want = truth.values(pub["mass"], pub["yaw_inertia"])
                    true = np.array([want[n] for n in names])
                    err = np.array([p["fitted"] for p in res.parameters]) - true
                    half = _halfwidths(res)
                    hws = [p["ci95_halfwidth"] for p in res.parameters]
                    rep = np.array([np.inf if h is None else h for h in hws])  # 0.0 is a width, None none
                    half["fit"] = np.where(np.isfinite(rep), rep, np.inf)
                    ident = np.array([p["status"] == "identified" for p in res.parameters])
                    got[name].append((err, true, half, ident))
                    z = " ".join(f"{n}={e / h:+.2f}" for n, e, h in zip(names, err, half["CR3"]))
                    z = f"{name} program {prog} noise {noise}: (fitted-truth)/h {z}"
                    stat = "".join("I" if i else "-" for i in ident)
                    print(
                        f"{z}; identified {stat}; {res.notes[0].split(';')[0]}; {wall:.0f} s wall, {cpu:.0f} s CPU",
                        flush=True,
                    )
    print(
        f"{'robot':8} {'kind':5} {'fits':>4} {'coverage':>9} {'outside':>8} {'RMS e/h':>8} {'median h/truth':>15} "
        f"{'identified':>10} {'ident. outside':>14}"
    )
    for name in [*robots, "all"]:
        rows = [x for r in robots for x in got[r]] if name == "all" else got[name]
        if not rows:
            continue
        E = np.array([x[0] for x in rows])
        T = np.array([x[1] for x in rows])
        ident = np.array([x[3] for x in rows])
        for kind in ("CR1", "CR3", "fit"):
            H = np.array([x[2][kind] for x in rows])
            with np.errstate(divide="ignore", invalid="ignore"):
                z = np.where(H > 0, np.abs(E) / H, np.inf)
            line = (
                f"{name:8} {kind:5} {len(rows):>4} {np.mean(z <= 1):>9.3f} {int(np.sum(z > 1)):>4}/{z.size:<3} "
                f"{np.sqrt(np.mean(np.where(np.isfinite(z), z, 0) ** 2)):>8.2f} {np.median(H / np.abs(T)):>15.2%}"
            )
            if kind == "fit":
                line += f" {int(ident.sum()):>6}/{ident.size:<3} {int(np.sum(ident & (z > 1))):>14}"
            print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

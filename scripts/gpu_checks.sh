#!/usr/bin/env bash
# The batch engine's GPU checks in one prepared run (a lent GPU machine has minutes, not hours).
#
# On the device machine, from the repository root, with mujoco, mujoco-warp, warp-lang on
# PYTHONPATH (wheels carried over: docs/warp_engine.md, "Versions and install"), e.g.
#   PYTHONPATH=/tmp/site:$PWD/src MUJOCO_GL=disable bash scripts/gpu_checks.sh $OUT
# Writes into OUT (default ./runs/gpu): check_paper.json, check_all.json (scripts/warp_check.py:
# per-world agreement with the CPU engine by design §11's criterion, the paper scenario and every
# device feature at once), bench.json (bioform bench --backend warp: closed loop against replayed
# physics at 1k/4k/32k worlds, and the CPU engine). Stops at the first failing step.
set -euo pipefail
OUT=${1:-runs/gpu}
mkdir -p "$OUT"
PY=${PYTHON:-python3}
DEV=${DEVICE:-cuda}
$PY scripts/warp_check.py --device "$DEV" --worlds 8 --duration 2 --json "$OUT/check_paper.json"
$PY scripts/warp_check.py --device "$DEV" --worlds 8 --duration 2 --json "$OUT/check_all.json" \
  --set 'plant.robots=[{model="paper", motor="dc", driver="voltage"}]' --set plant.sensing=odometry \
  --set plant.encoder_cpr=4096 --set plant.gyro_noise=0.01 --set plant.gyro_bias=0.005 \
  --set sim.control_dt=0.01 --set sim.log_dt=0.01 --set faults.packet_loss=0.2 --set faults.delay=0.02 \
  --set 'faults.noise_pose=[0.01,0.01,0.01]' --set 'faults.push=[[3,0.5,0.1,40.0,0.0,1.0]]' \
  --set 'faults.actuator=[[2,0.8,1.2,0.5]]'
$PY -m bioform_mj.cli bench --backend warp --device "$DEV" --worlds 1024,4096,32768 --duration 1 \
  --json "$OUT/bench.json"

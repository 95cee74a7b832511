"""The crossing scene shared by test_safety, test_cbf and test_hardware (design §19).

Two followers on the paper robot (MuJoCo plant) behind a leader on the x axis, each starting in the
other's slot: they must swap sides, and the paper's law has no avoidance, so they touch unless a
safety filter acts. Each test adds its own ``sim.duration`` and ``safety.distance``.
"""

from __future__ import annotations

CROSSING = {
    "leader.kind": "line",
    "leader.y0": 0.0,
    "leader.speed": 0.2,
    "plant.kind": "mujoco",
    "graph.edges": [[1, 2]],
    "graph.leader_access": [1, 2],
    "formation.offsets": [[1.0, 0.5], [1.0, -0.5]],
    # each starts in the other's slot: they must swap sides, and the paper's law has no avoidance
    "formation.initial_poses": [[-1.0, 0.5, 0.0], [-1.0, -0.5, 0.0]],
}

"""Obstacles on the floor: configuration, the seeded random field, and their plane geometry (design §19).

A scenario lists fixed obstacles as ``[[obstacles]]`` tables and may ask for a seeded random
field (``[obstacle_field]``). :func:`resolve` turns both into :class:`Obstacle` rows (the field
drawn from ``sim.seed``, kept away from the leader's path if asked); :mod:`bioform_mj.robots.scene`
composes them into the MuJoCo scene as static geoms of the world body, and the figures, the
video and rerun draw them. The ideal plant refuses obstacles (it has no bodies to touch them).

This module imports nothing of the package but the errors and the unit helper (the scenario imports it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bioform_mj.core.errors import ScenarioError
from bioform_mj.core.units import unit

SHAPES = ("box", "cylinder")

#: random field: candidate draws per obstacle before the field counts as too dense to place
FIELD_TRIES = 200


@dataclass(frozen=True)
class ObstacleCfg:
    """One fixed obstacle. ``shape``: ``box`` (``size = [sx, sy, sz]`` half-extents, m) or
    ``cylinder`` (``size = [radius, half_height]``, m); ``position = [x, y]`` m of its centre on the
    floor (it stands on the floor); ``yaw`` rad (boxes). A wall is a long, thin box."""

    shape: str = unit("box", "-")
    position: tuple[float, ...] = unit((0.0, 0.0), "m")
    size: tuple[float, ...] = unit((0.5, 0.5, 0.5), "m")
    yaw: float = unit(0.0, "rad")


@dataclass(frozen=True)
class ObstacleFieldCfg:
    """A seeded random field (``sim.seed``): ``count`` obstacles of ``shape`` (``box``: square
    footprint, half-side; ``cylinder``: radius) with the size drawn uniformly in ``size = [min, max]``
    m and height ``height`` m, centres uniform in ``region = [x0, y0, x1, y1]`` m, yaw uniform (boxes).
    ``keep_out`` m > 0: no obstacle closer than this to the leader's path (sampled over the run)
    nor to a follower's initial position;
    ``gap`` m: least distance between two obstacles. ``count = 0``: no field."""

    count: int = unit(0, "1")
    shape: str = unit("cylinder", "-")
    size: tuple[float, ...] = unit((0.2, 0.5), "m")
    height: float = unit(0.5, "m")
    region: tuple[float, ...] = unit((0.0, -5.0, 20.0, 5.0), "m")
    keep_out: float = unit(0.0, "m")
    gap: float = unit(0.0, "m")


@dataclass(frozen=True)
class Obstacle:
    """A resolved obstacle: ``shape``, centre ``(x, y)`` m, ``size`` as MuJoCo takes it (box: 3
    half-extents; cylinder: radius, half-height), ``yaw`` rad, ``name`` (``obstacle_k``, 1-based)."""

    name: str
    shape: str
    x: float
    y: float
    size: tuple[float, ...]
    yaw: float

    @property
    def radius(self) -> float:
        """Horizontal bounding radius about the centre, m."""
        return float(math.hypot(self.size[0], self.size[1])) if self.shape == "box" else float(self.size[0])

    @property
    def height(self) -> float:
        """Full height, m."""
        return 2.0 * float(self.size[2] if self.shape == "box" else self.size[1])

    def distance(self, xy: np.ndarray) -> np.ndarray:
        """Signed horizontal distance (m) of points ``xy`` (k, 2) from this obstacle's footprint
        (negative inside)."""
        p = np.atleast_2d(np.asarray(xy, dtype=float)) - [self.x, self.y]
        if self.shape == "cylinder":
            return np.hypot(p[:, 0], p[:, 1]) - self.size[0]
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        u = np.abs(c * p[:, 0] + s * p[:, 1]) - self.size[0]
        v = np.abs(-s * p[:, 0] + c * p[:, 1]) - self.size[1]
        outside = np.hypot(np.maximum(u, 0), np.maximum(v, 0))
        return outside + np.minimum(np.maximum(u, v), 0.0)

    def outline(self, k: int = 48) -> np.ndarray:
        """(m, 2) closed outline of the footprint, m (for figures)."""
        if self.shape == "cylinder":
            a = np.linspace(0, 2 * np.pi, k + 1)
            return np.column_stack([self.x + self.size[0] * np.cos(a), self.y + self.size[0] * np.sin(a)])
        sx, sy = self.size[0], self.size[1]
        corners = np.array([[sx, sy], [-sx, sy], [-sx, -sy], [sx, -sy], [sx, sy]])
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return corners @ np.array([[c, s], [-s, c]]) + [self.x, self.y]

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "shape": self.shape,
            "position": [self.x, self.y],
            "size": list(self.size),
            "yaw": self.yaw,
        }


def to_rows(obstacles: list[Obstacle]) -> np.ndarray:
    """(m, 7) ``[shape (0 box, 1 cylinder), x, y, size0, size1, size2, yaw]`` rows: the obstacles as
    the run's log keeps them (``log.npz`` key ``obstacles``; the figures and rerun draw from it)."""
    out = np.zeros((len(obstacles), 7))
    for k, o in enumerate(obstacles):
        s = list(o.size) + [0.0] * (3 - len(o.size))
        out[k] = [SHAPES.index(o.shape), o.x, o.y, s[0], s[1], s[2], o.yaw]
    return out


def from_rows(rows: np.ndarray) -> list[Obstacle]:
    """The inverse of :func:`to_rows`."""
    out = []
    for k, r in enumerate(np.asarray(rows, dtype=float).reshape(-1, 7)):
        shape = SHAPES[int(r[0])]
        size = (float(r[3]), float(r[4]), float(r[5])) if shape == "box" else (float(r[3]), float(r[4]))
        out.append(Obstacle(f"obstacle_{k + 1}", shape, float(r[1]), float(r[2]), size, float(r[6])))
    return out


def validate(obstacles: tuple[ObstacleCfg, ...], field: ObstacleFieldCfg) -> None:
    """Shape, sizes and the field's numbers (ScenarioError naming the key)."""
    for i, o in enumerate(obstacles):
        key = f"obstacles[{i}]"
        if o.shape not in SHAPES:
            raise ScenarioError(f"{key}.shape", f"unknown shape '{o.shape}' (expected one of: {', '.join(SHAPES)})")
        if len(o.position) != 2:
            raise ScenarioError(f"{key}.position", f"expected [x, y], got {list(o.position)}")
        want = 3 if o.shape == "box" else 2
        if len(o.size) != want:
            what = "[sx, sy, sz] half-extents" if o.shape == "box" else "[radius, half_height]"
            raise ScenarioError(f"{key}.size", f"a {o.shape} takes {what}, got {list(o.size)}")
        if any(not v > 0 for v in o.size):
            raise ScenarioError(f"{key}.size", f"every size must be > 0 m, got {list(o.size)}")
    f = field
    if f.count < 0:
        raise ScenarioError("obstacle_field.count", f"must be >= 0, got {f.count}")
    if f.count > 10_000:
        raise ScenarioError("obstacle_field.count", f"at most 10000 obstacles, got {f.count}")
    if f.shape not in SHAPES:
        raise ScenarioError("obstacle_field.shape", f"unknown shape '{f.shape}' (expected one of: {', '.join(SHAPES)})")
    if len(f.size) != 2 or not (0 < f.size[0] <= f.size[1]):
        raise ScenarioError("obstacle_field.size", f"expected [min, max] with 0 < min <= max m, got {list(f.size)}")
    if not f.height > 0:
        raise ScenarioError("obstacle_field.height", f"must be > 0 m, got {f.height:g}")
    if len(f.region) != 4 or not (f.region[0] < f.region[2] and f.region[1] < f.region[3]):
        raise ScenarioError(
            "obstacle_field.region", f"expected [x0, y0, x1, y1] with x0 < x1, y0 < y1, got {list(f.region)}"
        )
    if f.keep_out < 0:
        raise ScenarioError("obstacle_field.keep_out", f"must be >= 0 m, got {f.keep_out:g}")
    if f.gap < 0:
        raise ScenarioError("obstacle_field.gap", f"must be >= 0 m, got {f.gap:g}")


def scaled(obstacles: tuple[ObstacleCfg, ...], field: ObstacleFieldCfg, s: float):
    """Obstacles and field with every length × ``s`` (``formation.scale``: the experiment at a robot's scale)."""
    import dataclasses

    obs = tuple(
        dataclasses.replace(o, position=tuple(v * s for v in o.position), size=tuple(v * s for v in o.size))
        for o in obstacles
    )
    fd = dataclasses.replace(
        field,
        size=tuple(v * s for v in field.size),
        height=field.height * s,
        region=tuple(v * s for v in field.region),
        keep_out=field.keep_out * s,
        gap=field.gap * s,
    )
    return obs, fd


def resolve(
    obstacles: tuple[ObstacleCfg, ...], field: ObstacleFieldCfg, seed: int, path: np.ndarray | None
) -> list[Obstacle]:
    """The fixed obstacles then the random field's, as :class:`Obstacle` rows.

    The field is drawn by rejection sampling from ``numpy.random.default_rng([seed, 21])`` (its own
    stream: the initial-pose jitter is unchanged): a candidate is kept when it stays ``keep_out``
    m from every point of ``path`` (k, 2) (the leader's positions over the run) and ``gap`` m from
    every obstacle kept so far; after :data:`FIELD_TRIES` × ``count`` candidates the field is too
    dense and a ScenarioError says how many were placed.
    """
    out = [
        Obstacle(
            f"obstacle_{i + 1}",
            o.shape,
            float(o.position[0]),
            float(o.position[1]),
            tuple(map(float, o.size)),
            float(o.yaw),
        )
        for i, o in enumerate(obstacles)
    ]
    f = field
    if f.count == 0:
        return out
    rng = np.random.default_rng([int(seed), 21])
    x0, y0, x1, y1 = f.region
    placed = 0
    tries = 0
    while placed < f.count:
        if tries >= FIELD_TRIES * f.count:
            raise ScenarioError(
                "obstacle_field",
                f"too dense to place: {placed} of {f.count} obstacles after {tries} draws in region "
                f"{list(f.region)} with keep_out {f.keep_out:g} m and gap {f.gap:g} m "
                "(fewer, smaller, or a larger region)",
            )
        tries += 1
        r = float(rng.uniform(f.size[0], f.size[1]))
        x, y = float(rng.uniform(x0, x1)), float(rng.uniform(y0, y1))
        yaw = float(rng.uniform(-np.pi, np.pi)) if f.shape == "box" else 0.0
        size = (r, r, f.height / 2) if f.shape == "box" else (r, f.height / 2)
        cand = Obstacle(f"obstacle_{len(out) + 1}", f.shape, x, y, size, yaw)
        if f.keep_out > 0 and path is not None and len(path) and np.min(cand.distance(path)) < f.keep_out:
            continue
        if any(math.hypot(o.x - x, o.y - y) < o.radius + cand.radius + f.gap for o in out[len(obstacles) :]):
            continue
        out.append(cand)
        placed += 1
    return out

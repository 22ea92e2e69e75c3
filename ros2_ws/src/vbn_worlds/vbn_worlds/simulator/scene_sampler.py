"""Random polygonal worlds of the Chapter 8 simulator (Section 8.1, Table 8.1).

A world is a perimeter polygon with polygonal obstacles inside it and point features
on every polygon edge (Figure 8.1). :func:`random_scene` draws one from a
:class:`~vbn_worlds.simulator.settings.WorldSetting`:

1. the perimeter: an axis-aligned rectangle, or a star-shaped polygon whose vertices
   sit at jittered, sorted angles around the centre (always simple);
2. the obstacles: rectangles or star-shaped polygons placed by rejection sampling so
   that every polygon keeps ``clearance`` metres from every other (the pose grid then
   stays connected around each obstacle); an obstacle that does not fit after many
   tries is dropped, which the scene's obstacle count shows;
3. the features: ``round(density x total wall length)`` points uniformly along the
   walls (kept 5 cm from the corners), each facing into free space, with an angular
   extent and a range drawn from the feature type.
"""
from __future__ import annotations

import logging
import math

import numpy as np

from landmark_db.geometry2d import segment_distance
from landmark_db.scene import Scene, SceneFeatures, points_in_polygon
from vbn_worlds.simulator.settings import ShapeClass, WorldSetting

__all__ = ['inward_normals', 'place_features', 'random_scene']

_LOG = logging.getLogger(__name__)
_CORNER_MARGIN = 0.05  # metres kept free of features at each polygon vertex
_MAX_TRIES = 200


def random_scene(setting: WorldSetting, rng: np.random.Generator, name: str = '') -> Scene:
    """Draw a random world of ``setting``.

    Args:
        setting: shape class and feature type.
        rng: the random generator (the only source of randomness).
        name: the scene's name.

    Returns:
        A scene with perimeter, obstacles and features (features index the walls in
        the order of :meth:`Scene.wall_segments`).
    """
    shape = setting.shape
    perimeter = _random_perimeter(shape, rng)
    obstacles: list[np.ndarray] = []
    wanted = shape.obstacle_count.sample_count(rng, minimum=0)
    for _ in range(wanted):
        obstacle = _place_obstacle(shape, perimeter, obstacles, rng)
        if obstacle is not None:
            obstacles.append(obstacle)
    if len(obstacles) < wanted:
        _LOG.debug('placed %d of %d obstacles', len(obstacles), wanted)
    scene = Scene(perimeter=perimeter, obstacles=tuple(obstacles), name=name)
    features = place_features(scene, setting, rng)
    return Scene(perimeter=perimeter, obstacles=tuple(obstacles), features=features, name=name)


def place_features(scene: Scene, setting: WorldSetting,
                   rng: np.random.Generator) -> SceneFeatures:
    """Scatter features uniformly along the scene's walls.

    Args:
        scene: the polygons (its own features are ignored).
        setting: gives the density and the visibility distributions.
        rng: the random generator.

    Returns:
        The features, sorted by their position along the walls.
    """
    starts, ends, _ = scene.wall_segments()
    normals = inward_normals(scene)
    lengths = np.linalg.norm(ends - starts, axis=1)
    usable = np.maximum(lengths - 2 * _CORNER_MARGIN, 0.0)
    total = float(usable.sum())
    count = int(round(setting.features.density_per_m * total))
    if count == 0 or total == 0:
        return SceneFeatures.empty()
    along = np.sort(rng.uniform(0.0, total, count))
    cumulative = np.concatenate([[0.0], np.cumsum(usable)])
    wall = np.clip(np.searchsorted(cumulative, along, side='right') - 1, 0, len(usable) - 1)
    offset = _CORNER_MARGIN + along - cumulative[wall]
    direction = (ends - starts)[wall] / lengths[wall, None]
    positions = starts[wall] + direction * offset[:, None]
    kind = setting.features
    angle = np.clip(kind.angular_range_deg.sample(rng, count), 1.0, 179.0)
    aperture = 2.0 * angle if kind.angle_is_half_aperture else angle
    aperture = np.minimum(aperture, 179.0)
    range_min = np.clip(kind.range_min.sample(rng, count), 0.0, None)
    range_max = np.maximum(kind.range_max.sample(rng, count), range_min + 0.5)
    return SceneFeatures(positions, normals[wall], aperture, range_min, range_max)


def inward_normals(scene: Scene) -> np.ndarray:
    """Return the unit normal of every wall segment, pointing into free space.

    Free space is inside the perimeter and outside the obstacles.

    Returns:
        ``(s, 2)`` normals in the order of :meth:`Scene.wall_segments`.
    """
    out = []
    for i, polygon in enumerate(scene.polygons()):
        edge = np.roll(polygon, -1, axis=0) - polygon
        left = np.stack([-edge[:, 1], edge[:, 0]], axis=1)
        left /= np.linalg.norm(left, axis=1, keepdims=True)
        ccw = _signed_area(polygon) > 0
        # The left normal of a counter-clockwise polygon points into it.
        into_polygon = left if ccw else -left
        out.append(into_polygon if i == 0 else -into_polygon)
    return np.concatenate(out)


def _polygon_gap(p: np.ndarray, q: np.ndarray) -> float:
    """Smallest distance between the edges of polygons ``p`` and ``q``."""
    p0, p1 = p[:, None, :], np.roll(p, -1, axis=0)[:, None, :]
    q0, q1 = q[None, :, :], np.roll(q, -1, axis=0)[None, :, :]
    p0, p1, q0, q1 = np.broadcast_arrays(p0, p1, q0, q1)
    return float(segment_distance(p0, p1, q0, q1).min())


def _signed_area(polygon: np.ndarray) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _star_polygon(sides: int, radius: float, rng: np.random.Generator,
                  radial_jitter: float = 0.25) -> np.ndarray:
    """Return a simple polygon around the origin: sorted jittered angles and radii."""
    step = 2 * math.pi / sides
    angles = rng.uniform(0, 2 * math.pi) + step * (np.arange(sides)
                                                   + rng.uniform(-0.3, 0.3, sides))
    radii = radius * rng.uniform(1 - radial_jitter, 1.0, sides)
    return np.stack([radii * np.cos(angles), radii * np.sin(angles)], axis=1)


def _random_perimeter(shape: ShapeClass, rng: np.random.Generator) -> np.ndarray:
    if shape.rectangular:
        width, height = np.maximum(shape.size_m.sample(rng, 2), 4 * shape.clearance)
        return np.array([[0.0, 0.0], [width, 0.0], [width, height], [0.0, height]])
    sides = shape.perimeter_sides.sample_count(rng, minimum=3)
    radius = max(float(shape.size_m.sample(rng)), 4 * shape.clearance)
    polygon = _star_polygon(sides, radius, rng, radial_jitter=0.2)
    return polygon - polygon.min(axis=0)


def _place_obstacle(shape: ShapeClass, perimeter: np.ndarray, placed: list[np.ndarray],
                    rng: np.random.Generator) -> np.ndarray | None:
    lo, hi = perimeter.min(axis=0), perimeter.max(axis=0)
    rmin, rmax = shape.obstacle_radius_m
    for _ in range(_MAX_TRIES):
        radius = rng.uniform(rmin, rmax)
        if shape.rectangular:
            angle = rng.uniform(0.2, 0.5 * math.pi - 0.2)
            half = radius * np.array([math.cos(angle), math.sin(angle)])
            local = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
        else:
            sides = shape.obstacle_sides.sample_count(rng, minimum=3)
            local = _star_polygon(sides, radius, rng)
        centre = rng.uniform(lo, hi)
        candidate = local + centre
        if not np.all(points_in_polygon(candidate, perimeter)):
            continue
        if _polygon_gap(candidate, perimeter) < shape.clearance:
            continue
        if any(points_in_polygon(other[:1], candidate)[0]
               or points_in_polygon(candidate[:1], other)[0]
               or _polygon_gap(candidate, other) < shape.clearance for other in placed):
            continue
        return candidate
    return None

"""The polygon world of the Chapter 8 simulator (Section 8.1), shared with the renderer.

A scene is a 2-D top view of the pose space: a perimeter polygon, polygonal
obstacles inside it, and point features lying on the polygons' edges. Each feature
has a visibility angular extent about its wall's inward normal and a visibility
range. The image renderer of ``visibility_builder`` extrudes the same polygons into
walls of ``wall_height`` metres and places the camera at ``camera_height``.

Scene JSON (all lengths in metres, angles in degrees)::

    {
      "name": "room",
      "perimeter": [[x, y], ...],            # simple polygon, either orientation
      "obstacles": [[[x, y], ...], ...],      # simple polygons inside the perimeter
      "wall_height": 2.5,
      "camera_height": 1.2,
      "texture_seed": 0,
      "features": [                           # optional, may be empty
        {"position": [x, y], "normal": [nx, ny],
         "angular_extent_deg": 25.0, "range_min": 0.65, "range_max": 12.5}
      ]
    }

``angular_extent_deg`` is the full aperture of the feature's visibility cone: a
pose sees the feature when the direction from the feature to the pose lies within
half that angle of the feature's normal (the normal points into free space).
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math
from pathlib import Path
from typing import Any

import numpy as np

from landmark_db.errors import LandmarkDbError
from landmark_db.geometry2d import nearest_segment_distance
from vbn_common.jsonio import read_json_file, write_json_atomic

__all__ = ['Scene', 'SceneFeatures', 'load_scene', 'points_in_polygon', 'save_scene']


@dataclass(frozen=True)
class SceneFeatures:
    """Point features on the scene's walls, as parallel arrays.

    Attributes:
        positions: ``(n, 2)`` feature positions on polygon edges, metres.
        normals: ``(n, 2)`` unit normals of the feature's wall, pointing into free space.
        angular_extent_deg: ``(n,)`` full visibility aperture about the normal, degrees.
        range_min: ``(n,)`` minimum visibility distance, metres.
        range_max: ``(n,)`` maximum visibility distance, metres.
    """

    positions: np.ndarray
    normals: np.ndarray
    angular_extent_deg: np.ndarray
    range_min: np.ndarray
    range_max: np.ndarray

    def __len__(self) -> int:
        return int(self.positions.shape[0])

    @staticmethod
    def empty() -> SceneFeatures:
        """Return a feature set with no features."""
        return SceneFeatures(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), np.zeros(0),
                             np.zeros(0))


@dataclass(frozen=True)
class Scene:
    """A polygonal world: perimeter, obstacles, wall features and camera set-up.

    Attributes:
        perimeter: ``(p, 2)`` vertices of the outer wall polygon, metres.
        obstacles: one ``(q_i, 2)`` vertex array per obstacle polygon.
        features: the point features on the walls (may be empty).
        wall_height: height of the extruded walls, metres.
        camera_height: height of the camera's optical centre above the floor, metres.
        texture_seed: seed that picks the wall textures in the renderer.
        name: a short name for reports.
    """

    perimeter: np.ndarray
    obstacles: tuple[np.ndarray, ...] = ()
    features: SceneFeatures = field(default_factory=SceneFeatures.empty)
    wall_height: float = 2.5
    camera_height: float = 1.2
    texture_seed: int = 0
    name: str = ''

    def polygons(self) -> list[np.ndarray]:
        """Return the perimeter followed by the obstacles, each ``(m, 2)``."""
        return [self.perimeter, *self.obstacles]

    def wall_segments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return every polygon edge as a wall segment.

        Returns:
            ``(starts, ends, polygon_index)``: ``(s, 2)`` start and end points and the
            ``(s,)`` index into :meth:`polygons` (0 is the perimeter).
        """
        starts, ends, index = [], [], []
        for i, polygon in enumerate(self.polygons()):
            starts.append(polygon)
            ends.append(np.roll(polygon, -1, axis=0))
            index.append(np.full(len(polygon), i))
        return np.concatenate(starts), np.concatenate(ends), np.concatenate(index)

    def wall_distance(self, points: np.ndarray) -> np.ndarray:
        """Return each point's distance to the nearest wall segment.

        Args:
            points: ``(n, 2)`` query points, metres.

        Returns:
            ``(n,)`` distances, metres.
        """
        starts, ends, _ = self.wall_segments()
        return nearest_segment_distance(points, starts, ends)

    def free_space(self, points: np.ndarray) -> np.ndarray:
        """Tell which points lie inside the perimeter and outside every obstacle.

        Args:
            points: ``(n, 2)`` query points, metres.

        Returns:
            ``(n,)`` bool mask.
        """
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        inside = points_in_polygon(points, self.perimeter)
        for obstacle in self.obstacles:
            inside &= ~points_in_polygon(points, obstacle)
        return inside

    def bounds(self) -> tuple[float, float, float, float]:
        """Return ``(xmin, ymin, xmax, ymax)`` of the perimeter."""
        lo = self.perimeter.min(axis=0)
        hi = self.perimeter.max(axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])

    def to_dict(self) -> dict[str, Any]:
        """Return the scene as a JSON-ready dict (the format in the module docstring)."""
        f = self.features
        return {
            'name': self.name,
            'perimeter': self.perimeter.tolist(),
            'obstacles': [o.tolist() for o in self.obstacles],
            'wall_height': self.wall_height,
            'camera_height': self.camera_height,
            'texture_seed': self.texture_seed,
            'features': [
                {'position': f.positions[i].tolist(), 'normal': f.normals[i].tolist(),
                 'angular_extent_deg': float(f.angular_extent_deg[i]),
                 'range_min': float(f.range_min[i]), 'range_max': float(f.range_max[i])}
                for i in range(len(f))
            ],
        }

    @staticmethod
    def from_dict(data: Any) -> Scene:
        """Build a scene from a dict in the scene JSON format, checking every field.

        Raises:
            LandmarkDbError: naming the first field that is missing or invalid.
        """
        if not isinstance(data, dict):
            raise LandmarkDbError('scene must be a JSON object')
        if 'perimeter' not in data:
            raise LandmarkDbError("scene has no 'perimeter'")
        perimeter = _polygon(data['perimeter'], 'perimeter')
        obstacles_raw = data.get('obstacles', [])
        if not isinstance(obstacles_raw, list):
            raise LandmarkDbError("scene 'obstacles' must be a list of polygons")
        obstacles = tuple(_polygon(o, f'obstacles[{i}]') for i, o in enumerate(obstacles_raw))
        features = _features(data.get('features', []))
        wall_height = _positive(data.get('wall_height', 2.5), 'wall_height')
        camera_height = _positive(data.get('camera_height', 1.2), 'camera_height')
        if camera_height >= wall_height:
            raise LandmarkDbError(
                f'camera_height {camera_height} must be below wall_height {wall_height}')
        seed = data.get('texture_seed', 0)
        if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
            raise LandmarkDbError(f"scene 'texture_seed' must be a non-negative integer, "
                                  f'got {seed!r}')
        name = data.get('name', '')
        if not isinstance(name, str):
            raise LandmarkDbError(f"scene 'name' must be a string, got {name!r}")
        return Scene(perimeter, obstacles, features, wall_height, camera_height, seed, name)


def load_scene(path: str | Path) -> Scene:
    """Read a scene JSON file.

    Raises:
        LandmarkDbError: if the file is missing, unreadable, not valid JSON or not a
            valid scene.
    """
    return read_json_file(path, Scene.from_dict, LandmarkDbError)


def save_scene(scene: Scene, path: str | Path) -> None:
    """Write a scene JSON file atomically (temporary file, then rename)."""
    write_json_atomic(scene.to_dict(), path, indent=1)


def points_in_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon test, vectorised over points and edges.

    Args:
        points: ``(n, 2)`` query points.
        polygon: ``(m, 2)`` polygon vertices (closing edge implied).

    Returns:
        ``(n,)`` bool mask, True strictly inside (boundary points are undefined).
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    a = np.asarray(polygon, dtype=float)
    b = np.roll(a, -1, axis=0)
    px, py = points[:, 0:1], points[:, 1:2]
    straddles = (a[None, :, 1] > py) != (b[None, :, 1] > py)
    with np.errstate(divide='ignore', invalid='ignore'):
        x_cross = a[None, :, 0] + (py - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / (
            b[None, :, 1] - a[None, :, 1])
    crossings = straddles & (px < x_cross)
    return (crossings.sum(axis=1) % 2) == 1


def _polygon(raw: Any, name: str) -> np.ndarray:
    try:
        polygon = np.asarray(raw, dtype=float)
    except (TypeError, ValueError) as error:
        raise LandmarkDbError(f'{name} must be a list of [x, y] points') from error
    if polygon.ndim != 2 or polygon.shape[1] != 2 or polygon.shape[0] < 3:
        raise LandmarkDbError(f'{name} must be a list of at least 3 [x, y] points')
    if not np.all(np.isfinite(polygon)):
        raise LandmarkDbError(f'{name} has non-finite coordinates')
    area = 0.5 * np.sum(polygon[:, 0] * np.roll(polygon[:, 1], -1)
                        - np.roll(polygon[:, 0], -1) * polygon[:, 1])
    if abs(area) < 1e-9:
        raise LandmarkDbError(f'{name} has zero area')
    return polygon


def _positive(value: Any, name: str) -> float:
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(
            value) or value <= 0:
        raise LandmarkDbError(f"scene '{name}' must be a positive number, got {value!r}")
    return float(value)


def _features(raw: Any) -> SceneFeatures:
    if not isinstance(raw, list):
        raise LandmarkDbError("scene 'features' must be a list")
    if not raw:
        return SceneFeatures.empty()
    keys = ('position', 'normal', 'angular_extent_deg', 'range_min', 'range_max')
    columns: dict[str, list[Any]] = {key: [] for key in keys}
    for i, feature in enumerate(raw):
        if not isinstance(feature, dict):
            raise LandmarkDbError(f'features[{i}] must be an object')
        for key in keys:
            if key not in feature:
                raise LandmarkDbError(f"features[{i}] has no '{key}'")
            columns[key].append(feature[key])
    try:
        positions = np.asarray(columns['position'], dtype=float).reshape(-1, 2)
        normals = np.asarray(columns['normal'], dtype=float).reshape(-1, 2)
        extent = np.asarray(columns['angular_extent_deg'], dtype=float)
        rmin = np.asarray(columns['range_min'], dtype=float)
        rmax = np.asarray(columns['range_max'], dtype=float)
    except (TypeError, ValueError) as error:
        raise LandmarkDbError('features must hold numbers: position and normal as [x, y]'
                              ) from error
    for name, values in (('position', positions), ('normal', normals),
                         ('angular_extent_deg', extent), ('range_min', rmin),
                         ('range_max', rmax)):
        bad = np.flatnonzero(~np.all(np.isfinite(values.reshape(len(raw), -1)), axis=1))
        if bad.size:
            raise LandmarkDbError(f'features[{bad[0]}] has a non-finite {name}')
    norms = np.linalg.norm(normals, axis=1)
    if np.any(norms < 1e-9):
        raise LandmarkDbError(f'features[{int(np.argmin(norms))}] has a zero normal')
    if np.any((rmin < 0) | (rmax <= rmin)):
        i = int(np.flatnonzero((rmin < 0) | (rmax <= rmin))[0])
        raise LandmarkDbError(f'features[{i}] needs 0 <= range_min < range_max')
    return SceneFeatures(positions, normals / norms[:, None], extent, rmin, rmax)

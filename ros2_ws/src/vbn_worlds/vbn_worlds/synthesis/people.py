"""People walking through a run's view: occluders that move.

Each walker goes from one random free point to the next along straight lines that keep
``clearance`` from every wall, at a walking speed of its own (0.8 to 1.3 m/s), pausing
0 to 2 s at each point, for as long as the run lasts. A walker is an upright box 0.45 m
wide, 0.28 m deep and 1.6 to 1.85 m tall, turned along its way, in the colours of its
clothes: taller than the camera, so it hides whole columns of the walls, unlike a table.
Everything is drawn from one seed.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from landmark_db.scene import Scene
from vbn_worlds.errors import WorldsError
from vbn_worlds.render.renderer import Occluders

__all__ = ['Walkers', 'walkers']

_WIDTH_M, _DEPTH_M = 0.45, 0.28
#: A walker's centre stays this far from the robot's (half a walker and a robot's radius).
KEEP_M = 0.5


@dataclass(frozen=True)
class Walkers:
    """Walkers' paths: per walker, the times and places of its way points.

    Attributes:
        times: One ``(k,)`` array of seconds per walker (pairs: arrive, leave).
        places: One ``(k, 2)`` array of positions per walker.
        heights: ``(n,)`` metres.
        colours: ``(n, 3)`` BGR.
    """

    times: tuple[np.ndarray, ...]
    places: tuple[np.ndarray, ...]
    heights: np.ndarray
    colours: np.ndarray

    def positions(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(positions (n, 2), headings (n,))`` at ``t`` seconds."""
        xy, heading = [], []
        for times, places in zip(self.times, self.places):
            x = np.interp(t, times, places[:, 0])
            y = np.interp(t, times, places[:, 1])
            k = int(np.clip(np.searchsorted(times, t), 1, len(times) - 1))
            step = places[k] - places[k - 1]
            xy.append((x, y))
            heading.append(math.atan2(step[1], step[0]) if np.any(step) else 0.0)
        return np.array(xy, float).reshape(-1, 2), np.array(heading)

    def occluders(self, t: float, robot: np.ndarray | None = None,
                  keep_m: float = KEEP_M) -> Occluders:
        """Return the walkers at ``t`` seconds as occluders.

        ``robot``: the robot's position then; a walker whose centre is nearer than
        ``keep_m`` is left out (people step round a robot, they do not stand in it: a
        run once started with the camera inside two walkers, blind for three frames).
        """
        xy, heading = self.positions(t)
        if robot is not None and len(xy):
            away = np.linalg.norm(xy - np.asarray(robot, float)[:2], axis=1) >= keep_m
            xy, heading = xy[away], heading[away]
            heights, colours = self.heights[away], self.colours[away]
        else:
            heights, colours = self.heights, self.colours
        box = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * [_DEPTH_M / 2,
                                                                       _WIDTH_M / 2]
        footprints = []
        for (x, y), yaw in zip(xy, heading):
            c, s = math.cos(yaw), math.sin(yaw)
            footprints.append(box @ np.array([[c, s], [-s, c]]) + [x, y])
        return Occluders.boxes(footprints, list(heights), [tuple(c) for c in colours])


def walkers(scene: Scene, count: int, seed: int, duration_s: float,
            clearance: float = 0.35) -> Walkers:
    """Draw ``count`` walkers through ``scene``'s free space for ``duration_s`` seconds."""
    rng = np.random.default_rng([seed, 1_800])
    lo, hi = np.array(scene.bounds()[:2]), np.array(scene.bounds()[2:])

    def free_point() -> np.ndarray:
        for _ in range(1000):
            p = rng.uniform(lo, hi)
            if scene.free_space(p[None])[0] and scene.wall_distance(p[None])[0] >= clearance:
                return p
        raise WorldsError(f'no room for people to walk in scene {scene.name!r}')

    def clear(a: np.ndarray, b: np.ndarray) -> bool:
        line = a + (b - a) * np.linspace(0.0, 1.0, max(2, int(np.linalg.norm(b - a) / 0.05)))[
            :, None]
        return bool(scene.free_space(line).all() and
                    scene.wall_distance(line).min() >= clearance)

    times, places = [], []
    for _ in range(count):
        speed = float(rng.uniform(0.8, 1.3))
        here, t = free_point(), 0.0
        stops_t, stops_p = [t], [here]
        while t < duration_s:
            target = next((p for p in (free_point() for _ in range(50)) if clear(here, p)),
                          None)
            if target is None:   # boxed in: stand
                break
            t += float(np.linalg.norm(target - here)) / speed
            stops_t.append(t)
            stops_p.append(target)
            t += float(rng.uniform(0.0, 2.0))
            stops_t.append(t)
            stops_p.append(target)
            here = target
        times.append(np.array(stops_t))
        places.append(np.array(stops_p))
    heights = rng.uniform(1.6, 1.85, count)
    colours = rng.integers(20, 230, (count, 3)).astype(float)
    return Walkers(tuple(times), tuple(places), heights, colours)

"""A world that changed after its exploration: furniture, posters, light, people.

A database describes the building on the day of its exploration; the robot runs on
other days. :class:`WorldChanges` says what differs on the day of a run:

- **furniture**: upright prisms on the floor. One lower than the walls (a table, a
  chair, a cabinet) hides the walls' lower part and shows their upper part; one as high
  as the walls (a shelf, a partition) is a new textured wall, posters and all. Either is
  an obstacle the run's path goes round.
- **posters** (:class:`~vbn_worlds.render.textures.Appearance`): walls whose
  posters were replaced and moved, walls whose posters were taken down.
- **light**: a global gain (0.5x to 1.5x) and a light from one side.
- **people** (:mod:`.people`): walkers crossing the view, occluders that move.

:func:`random_changes` draws a change set from a seed (what the benchmark runs through);
:func:`load_changes` reads one from JSON::

    {"furniture": [{"footprint": [[x, y], ...], "height": 0.75, "colour": [b, g, r]}],
     "light": {"gain": 0.7, "side_deg": 90, "side_strength": 0.4},
     "posters": {"rehung": [3, 7], "bare": [5], "seed": 1},
     "people": 2}

Wall indices are the scene's wall segments in order (perimeter first, then each
obstacle's edges). New walls come after the scene's, so the old walls keep their
textures.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
import math
from pathlib import Path
from typing import Any

import numpy as np

from landmark_db.scene import Scene, points_in_polygon
from vbn_common.jsonio import read_json_file
from vbn_worlds.errors import WorldsError
from vbn_worlds.render.renderer import Occluders
from vbn_worlds.render.textures import Appearance

__all__ = ['Furniture', 'WorldChanges', 'load_changes', 'random_changes']


@dataclass(frozen=True)
class Furniture:
    """An upright prism on the floor.

    Attributes:
        footprint: ``(m, 2)`` polygon, metres in ``map``.
        height: Its top above the floor, metres (the walls' height or more: a new wall).
        colour: BGR colour of a piece lower than the walls.
    """

    footprint: np.ndarray
    height: float
    colour: tuple[float, float, float] = (60.0, 90.0, 140.0)


@dataclass(frozen=True)
class WorldChanges:
    """What differs from the exploration on the day of a run (module docstring).

    Attributes:
        furniture: Pieces added.
        appearance: Light and posters.
        people: Walkers crossing the scene.
        seed: Seeds the walkers' paths and colours.
    """

    furniture: tuple[Furniture, ...] = ()
    appearance: Appearance = field(default_factory=Appearance)
    people: int = 0
    seed: int = 0

    def walls(self, scene: Scene) -> list[Furniture]:
        """Return the pieces as high as ``scene``'s walls (new walls)."""
        return [f for f in self.furniture if f.height >= scene.wall_height]

    def render_scene(self, scene: Scene) -> Scene:
        """Return ``scene`` with the new walls (what the wall renderer draws)."""
        return replace(scene, obstacles=(*scene.obstacles,
                                         *(f.footprint for f in self.walls(scene))))

    def planning_scene(self, scene: Scene) -> Scene:
        """Return ``scene`` with every piece as an obstacle (what a path goes round)."""
        return replace(scene, obstacles=(*scene.obstacles,
                                         *(f.footprint for f in self.furniture)))

    def occluders(self, scene: Scene) -> Occluders:
        """Return the pieces lower than ``scene``'s walls as occluders."""
        low = [f for f in self.furniture if f.height < scene.wall_height]
        return Occluders.boxes([f.footprint for f in low], [f.height for f in low],
                               [f.colour for f in low])

    def check(self, scene: Scene) -> None:
        """Raise :class:`WorldsError` for changes that do not fit ``scene``."""
        count = len(scene.wall_segments()[0])
        for name, walls in (('rehung', self.appearance.rehung), ('bare', self.appearance.bare)):
            bad = [w for w in walls if not 0 <= w < count]
            if bad:
                raise WorldsError(f'changes: posters {name} wall {bad[0]} is not a '
                                             f'wall of scene {scene.name!r} (0 to {count - 1})')
        a = self.appearance
        if not (0.05 <= a.gain <= 5.0 and 0.0 <= a.side_strength <= 1.0):
            raise WorldsError(f'changes: light gain must be 0.05 to 5 and side '
                                         f'strength 0 to 1, got {a.gain} and {a.side_strength}')
        if not 0 <= self.people <= 50:
            raise WorldsError(f'changes: people must be 0 to 50, got {self.people}')
        for k, piece in enumerate(self.furniture):
            if not (math.isfinite(piece.height) and piece.height > 0):
                raise WorldsError(f'changes: furniture[{k}] height must be '
                                             f'positive, got {piece.height}')
            if not scene.free_space(piece.footprint).all():
                raise WorldsError(f'changes: furniture[{k}] does not stand in the '
                                             "scene's free space")

    def to_dict(self) -> dict[str, Any]:
        """Return the changes as a JSON-ready dict (the format in the module docstring)."""
        a = self.appearance
        return {'furniture': [{'footprint': f.footprint.tolist(), 'height': f.height,
                               'colour': list(f.colour)} for f in self.furniture],
                'light': {'gain': a.gain, 'side_deg': a.side_deg,
                          'side_strength': a.side_strength},
                'posters': {'rehung': list(a.rehung), 'bare': list(a.bare), 'seed': a.seed},
                'people': self.people, 'seed': self.seed}

    @staticmethod
    def from_dict(data: Any) -> WorldChanges:
        """Build changes from a dict in the JSON format, naming the first bad field."""
        if not isinstance(data, dict):
            raise WorldsError('changes must be a JSON object')
        unknown = set(data) - {'furniture', 'light', 'posters', 'people', 'seed'}
        if unknown:
            raise WorldsError(f'changes: unknown field {sorted(unknown)[0]!r}')
        try:
            furniture = tuple(
                Furniture(_footprint(f['footprint'], k), float(f['height']),
                          tuple(float(c) for c in f.get('colour', (60, 90, 140)))[:3])
                for k, f in enumerate(data.get('furniture', [])))
            light, posters = data.get('light', {}), data.get('posters', {})
            appearance = Appearance(float(light.get('gain', 1.0)),
                                    float(light.get('side_deg', 0.0)),
                                    float(light.get('side_strength', 0.0)),
                                    tuple(int(w) for w in posters.get('rehung', ())),
                                    tuple(int(w) for w in posters.get('bare', ())),
                                    int(posters.get('seed', 1)))
            return WorldChanges(furniture, appearance, int(data.get('people', 0)),
                                int(data.get('seed', 0)))
        except (KeyError, TypeError, ValueError, AttributeError) as error:
            raise WorldsError(f'changes: invalid field ({error!r})') from error


def _footprint(raw: Any, k: int) -> np.ndarray:
    footprint = np.asarray(raw, float)
    if footprint.ndim != 2 or footprint.shape[1] != 2 or len(footprint) < 3 or \
            not np.all(np.isfinite(footprint)):
        raise WorldsError(f'changes: furniture[{k}] footprint must be three or '
                                     'more finite [x, y] points')
    return footprint


def load_changes(path: str | Path) -> WorldChanges:
    """Read a change set from a JSON file (module docstring).

    Raises:
        WorldsError: a missing or unreadable file, or a bad field.
    """
    return read_json_file(path, WorldChanges.from_dict, WorldsError)


def random_changes(scene: Scene, seed: int, *, furniture: int = 3, rehung: float = 0.3,
                   bare: float = 0.1, gain: float | None = None, side_strength: float = 0.4,
                   people: int = 2, passage_m: float = 0.6) -> WorldChanges:
    """Draw a change set for ``scene`` from ``seed``.

    Args:
        scene: The explored scene.
        seed: Seeds every draw.
        furniture: Pieces added: footprints 0.4 to 1.0 m by 0.4 to 0.8 m, turned at
            random, two in three lower than the camera (0.45 to 0.9 m: tables, chairs,
            cabinets), the others as high as the walls; each at least ``passage_m`` from
            every wall and piece, so that the robot still passes (fewer when the scene
            has no room for them).
        rehung: Share of the walls whose posters are replaced and moved.
        bare: Share of the walls whose posters are taken down.
        gain: The light's gain (None: drawn from 0.5 to 1.5).
        side_strength: Strength of a light from a random side.
        people: Walkers.
        passage_m: See ``furniture``.
    """
    rng = np.random.default_rng([seed, 18])
    lo, hi = np.array(scene.bounds()[:2]), np.array(scene.bounds()[2:])
    pieces: list[Furniture] = []
    for _ in range(200 * max(furniture, 1)):
        if len(pieces) >= furniture:
            break
        half = rng.uniform([0.2, 0.2], [0.5, 0.4])
        turn = rng.uniform(0.0, math.pi)
        corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * half
        rotation = np.array([[math.cos(turn), -math.sin(turn)],
                             [math.sin(turn), math.cos(turn)]])
        footprint = rng.uniform(lo, hi) + corners @ rotation.T
        edge = np.concatenate([footprint + (np.roll(footprint, -1, 0) - footprint) * t
                               for t in np.linspace(0.0, 1.0, 5, endpoint=False)])
        if not scene.free_space(edge).all() or scene.wall_distance(edge).min() < passage_m:
            continue
        if any(points_in_polygon(edge, p.footprint).any() or
               np.min(np.linalg.norm(edge[:, None] - p.footprint[None], axis=2)) < passage_m
               for p in pieces):
            continue
        low = rng.uniform() < 2.0 / 3.0
        height = float(rng.uniform(0.45, 0.9)) if low else scene.wall_height
        colour = tuple(float(c) for c in rng.integers(30, 220, 3))
        pieces.append(Furniture(footprint, height, colour))
    walls = len(scene.wall_segments()[0])
    order = rng.permutation(walls)
    n_rehung, n_bare = int(round(rehung * walls)), int(round(bare * walls))
    appearance = Appearance(
        gain=float(rng.uniform(0.5, 1.5)) if gain is None else float(gain),
        side_deg=float(rng.uniform(0.0, 360.0)), side_strength=float(side_strength),
        rehung=tuple(sorted(int(w) for w in order[:n_rehung])),
        bare=tuple(sorted(int(w) for w in order[n_rehung:n_rehung + n_bare])),
        seed=int(seed) + 1)
    return WorldChanges(tuple(pieces), appearance, int(people), int(seed))

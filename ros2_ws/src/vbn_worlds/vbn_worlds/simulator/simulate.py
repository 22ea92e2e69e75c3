"""One synthetic world instance, from setting and seed to poses, graph and visibility.

This composes the simulator's steps (Section 8.1): :func:`random_scene` draws the
polygon world, :func:`pose_grid` samples its free space every ``spacing`` metres,
and :func:`visible_pairs` gives each pose's visibility set. Feature ids are the
row indices of ``scene.features``, so the renderer and the world instance agree.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from landmark_db.scene import Scene
from landmark_db.world import WorldInstance
from vbn_worlds.simulator.grid import pose_grid
from vbn_worlds.simulator.scene_sampler import random_scene
from vbn_worlds.simulator.settings import WorldSetting, get_setting
from vbn_worlds.simulator.visibility import visible_pairs

__all__ = ['SimulatedWorld', 'simulate_world', 'world_from_scene', 'world_rng']


@dataclass(frozen=True)
class SimulatedWorld:
    """A simulated world: the polygon scene and its world instance.

    Attributes:
        scene: perimeter, obstacles and features.
        world: poses, grid edges and visibility; feature id ``j`` is
            ``scene.features`` row ``j``.
    """

    scene: Scene
    world: WorldInstance

    @property
    def mean_visible(self) -> float:
        """Mean number of features visible per pose (Table 8.4's statistic)."""
        counts = self.world.visible_counts
        return float(np.mean(counts)) if counts.size else 0.0


def world_rng(setting: int, seed: int) -> np.random.Generator:
    """Return the generator for world ``seed`` of setting number ``setting``.

    ``vbn simulate --setting S --seed N`` and the benchmark's world ``N`` of setting
    ``S`` both use this, so any benchmark world can be regenerated alone.
    """
    return np.random.default_rng([int(seed), int(setting)])


def simulate_world(setting: int | WorldSetting, seed: int, spacing: float = 0.5,
                   name: str | None = None) -> SimulatedWorld:
    """Generate a random world of a setting and compute its visibility.

    Args:
        setting: setting number 1-4 or a :class:`WorldSetting` (e.g. a small one).
        seed: non-negative seed; the same ``(setting, seed, spacing)`` gives the same
            world.
        spacing: pose grid step, metres.
        name: world name; default ``setting<S>-seed<N>``.

    Returns:
        The scene and its world instance.
    """
    config = get_setting(setting) if isinstance(setting, int) else setting
    name = f'setting{config.number}-seed{seed}' if name is None else name
    rng = world_rng(config.number, seed)
    scene = random_scene(config, rng, name=name)
    poses, edges = pose_grid(scene, spacing)
    return SimulatedWorld(scene, world_from_scene(scene, poses, edges, spacing, name))


def world_from_scene(scene: Scene, poses: np.ndarray, edges: np.ndarray, spacing: float,
                     name: str) -> WorldInstance:
    """Compute the visibility of ``scene``'s features from ``poses`` as a world instance.

    Feature id ``j`` is ``scene.features`` row ``j``; the visibility is assembled
    sparse, so worlds of 100,000 poses and 10,000 features fit in memory.
    """
    rows, cols = visible_pairs(scene, poses)
    f = len(scene.features)
    visible = sp.csr_matrix((np.ones(rows.size, dtype=bool), (rows, cols)),
                            shape=(poses.shape[0], f))
    return WorldInstance.from_visibility(poses, edges, visible, np.arange(f), spacing=spacing,
                                         name=name)

"""Figures of decompositions: regions over the floor plan (like Figures 8.8 to 8.15).

Each region is painted on the pose grid in its own colour and outlined along the
grid-cell boundaries, so overlapping regions stay visible; k-coverable poses that
no region covers are marked with black crosses and poses that see fewer than ``k``
features are shown in light grey. When the polygon scene is known, the perimeter
(green), the obstacles (blue) and optionally the features (red dots) are drawn as in
Figure 8.1. Uses matplotlib's non-interactive Agg backend.
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from vbn_common.palette import region_colours

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from landmark_db.scene import Scene
    from landmark_db.world import WorldInstance

__all__ = ['draw_decomposition', 'draw_scene', 'grid_cells', 'save_decomposition_figure']


def grid_cells(world: WorldInstance) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Place the world's poses on an integer grid.

    Returns:
        ``(ix, iy, spacing, origin)``: ``(n,)`` integer cell columns and rows, the
        cell size in metres (the world's spacing, or the shortest edge length) and
        the ``(2,)`` coordinates of cell ``(0, 0)``.
    """
    poses = world.poses[:, :2]  # a pose space with heading: its positions
    spacing = world.spacing
    if not spacing:
        if len(world.edges):
            lengths = np.linalg.norm(poses[world.edges[:, 0]] - poses[world.edges[:, 1]],
                                     axis=1)
            spacing = float(lengths[lengths > 0].min()) if np.any(lengths > 0) else 1.0
        else:
            spacing = 1.0
    origin = poses.min(axis=0) if len(poses) else np.zeros(2)
    cells = np.rint((poses - origin) / spacing).astype(np.int64)
    return cells[:, 0], cells[:, 1], float(spacing), origin


def draw_scene(ax: Axes, scene: Scene, show_features: bool = False) -> None:
    """Draw the perimeter (green), the obstacles (blue) and optionally the features."""
    from matplotlib.patches import Polygon

    ax.add_patch(Polygon(scene.perimeter, closed=True, fill=False, edgecolor='green',
                         linewidth=1.5, zorder=4))
    for obstacle in scene.obstacles:
        ax.add_patch(Polygon(obstacle, closed=True, facecolor='#c8d4ff', edgecolor='blue',
                             linewidth=1.0, zorder=4))
    if show_features and len(scene.features):
        pos = scene.features.positions
        ax.scatter(pos[:, 0], pos[:, 1], s=2, c='red', zorder=5, linewidths=0)


def draw_decomposition(ax: Axes, world: WorldInstance, regions: Sequence[Any], k: int,
                       uncovered: Sequence[int] | np.ndarray = (),
                       scene: Scene | None = None, title: str = '',
                       show_features: bool = False) -> None:
    """Draw a decomposition over its world on a matplotlib axes.

    Args:
        ax: the axes.
        world: the world instance the regions index.
        regions: objects with a ``poses`` sequence of pose indices (e.g.
            ``Region``), or plain index sequences.
        k: features per landmark (marks the poses with fewer than ``k`` features).
        uncovered: k-coverable pose indices left uncovered (drawn as crosses).
        scene: the polygon world, drawn on top when given.
        title: axes title.
        show_features: also draw the scene's features.
    """
    from matplotlib.collections import LineCollection
    from matplotlib.colors import to_rgba

    ix, iy, spacing, origin = grid_cells(world)
    n = world.n_poses
    width = int(ix.max()) + 1 if n else 1
    height = int(iy.max()) + 1 if n else 1
    image = np.ones((height, width, 4))
    image[..., 3] = 0.0
    counts = np.asarray(world.visible_counts)
    image[iy, ix] = to_rgba('#e6e6e6')
    coverable = counts >= k
    image[iy[coverable], ix[coverable]] = to_rgba('#bdbdbd')
    colours = region_colours(len(regions))
    pose_lists = [np.asarray(getattr(r, 'poses', r), dtype=np.int64) for r in regions]
    # Paint larger regions first so that small regions stay visible on top.
    order = np.argsort([-len(p) for p in pose_lists], kind='stable')
    segments = []
    segment_colours = []
    for index in order:
        members = pose_lists[index]
        if members.size == 0:
            continue
        blend = 0.55 * colours[index] + 0.45 * image[iy[members], ix[members]]
        blend[:, 3] = 1.0
        image[iy[members], ix[members]] = blend
        mask = np.zeros((height + 2, width + 2), dtype=bool)
        mask[iy[members] + 1, ix[members] + 1] = True
        region_segments = _mask_outline(mask)
        segments.append(region_segments)
        segment_colours.extend([colours[index] * [0.6, 0.6, 0.6, 1.0]] * len(region_segments))
    extent = (origin[0] - spacing / 2, origin[0] + (width - 0.5) * spacing,
              origin[1] - spacing / 2, origin[1] + (height - 0.5) * spacing)
    ax.imshow(image, origin='lower', extent=extent, interpolation='nearest', zorder=1)
    if segments:
        lines = np.concatenate(segments) * spacing + (origin - spacing / 2)
        ax.add_collection(LineCollection(lines, colors=segment_colours, linewidths=0.8,
                                         zorder=3))
    uncovered = np.asarray(uncovered, dtype=np.int64)
    if uncovered.size:
        pts = world.poses[uncovered]
        ax.scatter(pts[:, 0], pts[:, 1], marker='x', s=6, c='black', linewidths=0.6,
                   zorder=6, label='uncovered k-coverable')
    if scene is not None:
        draw_scene(ax, scene, show_features=show_features)
    ax.set_aspect('equal')
    ax.set_xlim(extent[0] - spacing, extent[1] + spacing)
    ax.set_ylim(extent[2] - spacing, extent[3] + spacing)
    ax.set_xlabel('x (m)')
    ax.set_ylabel('y (m)')
    if title:
        ax.set_title(title, fontsize=9)


def save_decomposition_figure(path: str | Path, world: WorldInstance, regions: Sequence[Any],
                              k: int, uncovered: Sequence[int] | np.ndarray = (),
                              scene: Scene | None = None, title: str = '',
                              size_inches: float = 7.0, dpi: int = 110) -> Path:
    """Draw one decomposition (see :func:`draw_decomposition`) into a PNG file.

    Returns:
        The path written.
    """
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(size_inches, size_inches))
    try:
        draw_decomposition(ax, world, regions, k, uncovered, scene=scene, title=title)
        fig.tight_layout()
        path = Path(path)
        fig.savefig(path, dpi=dpi)
    finally:
        plt.close(fig)
    return path


def _mask_outline(mask: np.ndarray) -> np.ndarray:
    """Cell-boundary segments of a padded boolean mask, in cell units.

    Cell ``(r, c)`` of the padded mask covers ``[c-1, c] x [r-1, r]`` in the
    unpadded cell-corner coordinates.

    Returns:
        ``(s, 2, 2)`` segments ``[[x0, y0], [x1, y1]]``.
    """
    vertical = mask[:, 1:] != mask[:, :-1]  # boundary between columns c and c+1
    rows, cols = np.nonzero(vertical)
    x = cols.astype(float)
    v = np.stack([np.stack([x, rows - 1.0], axis=1), np.stack([x, rows + 0.0], axis=1)],
                 axis=1)
    horizontal = mask[1:, :] != mask[:-1, :]
    rows, cols = np.nonzero(horizontal)
    y = rows.astype(float)
    h = np.stack([np.stack([cols - 1.0, y], axis=1), np.stack([cols + 0.0, y], axis=1)],
                 axis=1)
    return np.concatenate([v, h]) if len(v) or len(h) else np.zeros((0, 2, 2))

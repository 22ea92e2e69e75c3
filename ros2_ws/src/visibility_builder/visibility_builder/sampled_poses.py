"""Sampled poses and the pose graph G of an exploration.

Thesis Section 6.2.1 assumes "exactly one image per sampling position": images
taken at one position are integrated into one pose (the Room 408 data set took
four pinhole images, at headings 0, 90, 180 and 270 degrees, at every position of
a 25 cm grid; a panoramic exploration takes one). ``G = (V, E)`` is the graph of
the sampling poses, whose shortest-path distance bounds the pose pairs that
Algorithm 6.3 compares (its parameter gamma).

Steps:

1. **Positions**: frames whose base positions lie within ``position_tolerance`` of
   each other (single linkage) form one pose at their mean position. The base
   position is used, not the camera's: a robot turning in place stays where it is,
   while a camera mounted off its rotation axis moves on a circle. Grouping looks at
   positions only, not at time: a position visited twice is one pose.
2. **Lattice**: the spacing is the median nearest-neighbour distance; the lattice
   orientation the circular mean of the nearest-neighbour directions modulo 90
   degrees; the origin the circular mean of the positions modulo the spacing.
   Spacing and origin are then refined by least squares on the positions within
   ``grid_tolerance * spacing`` of a lattice point. A square lattice is assumed
   (one spacing), as the thesis's grid and the project's exploration bags have.
3. **Edges**: if at least ``min_grid_fraction`` of the poses lie on the lattice,
   they are joined to their lattice neighbours (``connectivity`` 4 or 8); a pose
   off the lattice (``grid`` row ``-1``) is joined to its ``knn`` nearest poses.
   Otherwise (positions off any grid) ``G`` is the symmetric ``knn``-nearest-
   neighbour graph, made connected by adding, while it has several components,
   the shortest edge from the smallest component to the rest: graph distances
   between the poses are then defined everywhere. A lattice graph is left as it is
   (a gap in a grid is a wall or an obstacle), with a warning if it falls apart.

**Heading pose space** (cameras that do not see all around): a pinhole
image sees a quarter of the room, so merging the headings of one position into one
pose (the rule above) gives poses whose features no single image shows. With
``headings`` sectors (``N``, or the exploration's own count of headings per position
when 0, the default, and the camera is not a panorama) a sampled pose is a (position,
heading sector) pair: one image per pose, as the thesis's Chapter 3 assumes. ``G``
joins the poses of neighbouring positions in the same sector and, with ``turns`` set
(below), the neighbouring sectors of one position: a turn on the spot is then an edge
like a step, the decomposition runs on ``G`` unchanged, and the rho-neighbourhood of a
pose spans rho sectors to either side (a region's landmark stays in view while the
robot turns by rho sectors).

**Sector width.** The sector width ``w = 360 / N`` degrees is the exploration's heading
step. A turning edge is worth having only if the views it joins share features: the
rho-neighbourhood of a pose holds views turned by up to ``rho * w`` either way, whose
common field is ``hfov - 2 rho w``. ``turns='auto'`` joins neighbouring sectors when
that common field keeps at least ``turn_overlap`` (three quarters) of the camera's
horizontal field ``hfov``, i.e. ``w <= hfov (1 - turn_overlap) / (2 rho)``: a 180 degree
fisheye needs 16 headings (22.5 degree sectors), a 90 degree pinhole 32; a 90 degree
pinhole turned by +-45 degrees (8 headings) keeps no common field at all, and a rho = 1
neighbourhood with turns would keep no feature. ``turns='always'`` joins them whatever
the width. The default, ``'never'``, keeps every sector a layer of its own, because
joining measured worse on every exploration tried (the fisheye room, ``docs/classes.md``:
8 headings 99.6 % -> 98.6 % posed, p95 3.88 -> 5.75 cm; 16 headings 99.8 % -> 96.3 %,
p95 3.14 -> 8.34 cm): a landmark that must stay in view through a turn either way has
to lie in the middle of the image, and classes matched across headings (Algorithm 6.3
then compares neighbouring sectors too, without which no class spans a turn) lose many
more features to the symmetry check. In layers the localizer crosses a sector by
switching to a region of the predicted heading
(:func:`landmark_localizer.switching.choose_region`). A panorama keeps the position-only
pose space.

Complexity: ``O(n log n)`` (k-d tree queries and sorts) for ``n`` frames.
"""
from __future__ import annotations

from dataclasses import dataclass
import logging
import math
from typing import Any

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from vbn_common.geometry.camera import camera_from_info, horizontal_fov
from visibility_builder.errors import VisibilityBuilderError

__all__ = ['PoseSampling', 'SamplingConfig', 'sample_poses']

_LOG = logging.getLogger(__name__)

# Lattice offsets of the neighbours (each undirected edge once).
_OFFSETS = {4: np.array([[1, 0], [0, 1]]), 8: np.array([[1, 0], [0, 1], [1, 1], [1, -1]])}


@dataclass(frozen=True)
class SamplingConfig:
    """Parameters of :func:`sample_poses`.

    Attributes:
        position_tolerance: frames whose positions are this close (metres, single
            linkage) are one sampled pose.
        grid_tolerance: largest distance of a pose from its lattice point, as a
            fraction of the spacing, for it to count as on the lattice.
        min_grid_fraction: the lattice is used when at least this fraction of the
            poses lie on it.
        connectivity: 4 or 8 lattice neighbours.
        knn: neighbours of each pose in the k-nearest-neighbour graph.
        headings: heading sectors of the pose space: 0 (the default) for the
            exploration's own count of headings per position (1 for a panorama), 1 for
            positions only (all headings of a position one pose, Section 6.2.1), N >= 2
            for N sectors.
        turns: whether ``G`` joins the neighbouring heading sectors of a position:
            ``'never'`` (the default, measured best), ``'auto'`` (by the sector-width
            rule of the module docstring) or ``'always'``.
        turn_overlap: the share of the camera's horizontal field that the views of a
            rho-neighbourhood must have in common for ``'auto'`` to join sectors.
    """

    position_tolerance: float = 0.02
    grid_tolerance: float = 0.1
    min_grid_fraction: float = 0.5
    connectivity: int = 4
    knn: int = 6
    headings: int = 0
    turns: str = 'never'
    turn_overlap: float = 0.75

    def __post_init__(self) -> None:
        """Reject invalid values with a :class:`VisibilityBuilderError`."""
        if not (math.isfinite(self.position_tolerance) and self.position_tolerance >= 0):
            raise VisibilityBuilderError(
                f'position_tolerance must be a non-negative number, got {self.position_tolerance}')
        if not 0 < self.grid_tolerance < 0.5:
            raise VisibilityBuilderError(
                f'grid_tolerance must be in (0, 0.5), got {self.grid_tolerance}')
        if not 0 <= self.min_grid_fraction <= 1:
            raise VisibilityBuilderError(
                f'min_grid_fraction must be in [0, 1], got {self.min_grid_fraction}')
        if self.connectivity not in _OFFSETS:
            raise VisibilityBuilderError(
                f'connectivity must be 4 or 8, got {self.connectivity}')
        if int(self.knn) != self.knn or self.knn < 1:
            raise VisibilityBuilderError(f'knn must be a positive integer, got {self.knn}')
        if int(self.headings) != self.headings or not 0 <= self.headings <= 72:
            raise VisibilityBuilderError(
                f'headings must be an integer 0..72, got {self.headings}')
        if self.turns not in ('auto', 'always', 'never'):
            raise VisibilityBuilderError(
                f"turns must be 'auto', 'always' or 'never', got {self.turns!r}")
        if not (math.isfinite(self.turn_overlap) and 0 <= self.turn_overlap < 1):
            raise VisibilityBuilderError(
                f'turn_overlap must be in [0, 1), got {self.turn_overlap}')


@dataclass(frozen=True)
class PoseSampling:
    """The sampled poses of an exploration and their graph ``G``.

    Poses are numbered in the order of their first frame.

    Attributes:
        positions: ``(n, 2)`` position of each pose in ``map`` (mean of its frames'
            base positions), metres.
        frames_of_pose: for each pose, the indices of its frames (in frame order).
        yaw: ``(n,)`` heading of each pose: the camera heading of its first frame
            (radians; for a panorama, the azimuth of its centre column).
        grid: ``(n, 2)`` int lattice cell ``(i, j)`` of each pose, ``-1`` off the lattice
            (all ``-1`` when no lattice was found); the smallest index on each axis is 0.
        spacing: lattice spacing in metres, ``None`` when no lattice was found.
        origin: ``(2,)`` position of cell ``(0, 0)``, ``None`` without a lattice.
        angle: lattice orientation in radians, ``(-pi/4, pi/4]``: cell ``(i, j)`` is at
            ``origin + spacing * R(angle) @ (i, j)``; ``None`` without a lattice.
        edges: ``(m, 2)`` int pose pairs ``i < j``, sorted, each once.
        graph: ``'grid4'``, ``'grid8'`` or ``'knn'``: how the edges were made
            (``'grid4'``/``'grid8'`` may include k-NN edges of off-lattice poses).
        headings: heading sectors (1: the position-only pose space).
        sector: ``(n,)`` int heading sector of each pose (0 with one sector); ``yaw``
            is then the sector's centre heading.
        turns: ``G`` joins the neighbouring sectors of each position (the module
            docstring's sector-width rule); False without sectors.
    """

    positions: np.ndarray
    frames_of_pose: tuple[tuple[int, ...], ...]
    yaw: np.ndarray
    grid: np.ndarray
    spacing: float | None
    origin: np.ndarray | None
    angle: float | None
    edges: np.ndarray
    graph: str
    headings: int = 1
    sector: np.ndarray | None = None
    turns: bool = False

    @property
    def n_poses(self) -> int:
        """Number of sampled poses."""
        return len(self.positions)

    def world_poses(self) -> np.ndarray:
        """Return the world instance's poses: positions, and headings if it has sectors.

        ``(n, 2)``, or ``(n, 3)`` with each pose's sector heading.
        """
        if self.headings == 1:
            return self.positions
        return np.column_stack([self.positions, self.yaw])

    def sector_grid(self) -> np.ndarray:
        """Return each pose's lattice cell with every heading sector on a tile of its own.

        The lattice filters of Section 6.2.2 (rings, blocks, convex trim) then work
        within one heading: sector ``s`` is shifted by ``s`` tiles along the first
        axis, two empty columns apart, so that no ring joins two sectors.
        """
        if self.headings == 1 or self.sector is None:
            return self.grid
        grid = self.grid.copy()
        on = (grid >= 0).all(axis=1)
        if on.any():
            grid[on, 0] += self.sector[on] * (int(grid[on, 0].max()) + 3)
        return grid


def sample_poses(exploration: Any, config: SamplingConfig | None = None,
                 rho: int = 1) -> PoseSampling:
    """Group the frames of an exploration into sampled poses and build the pose graph.

    Args:
        exploration: an :class:`~vbn_common.exploration.Exploration` (anything
            with ``base_poses()`` and ``camera_poses()`` returning ``(n, 3)`` arrays;
            its ``camera_info``, if any, gives the camera's field for the turns rule).
        config: tolerances and graph parameters (default :class:`SamplingConfig`).
        rho: the decomposition's overlap radius, for the sector-width rule of
            ``config.turns == 'auto'``.

    Returns:
        The poses, their frames, the lattice (if any) and the edges of ``G``.

    Raises:
        VisibilityBuilderError: no frames, or positions that are not finite.

    Example:
        >>> class Grid:  # 2 x 2 positions, 25 cm apart, one frame each
        ...     def base_poses(self):
        ...         return np.array([[0, 0, 0], [.25, 0, 0], [0, .25, 0], [.25, .25, 0]])
        ...     camera_poses = base_poses
        >>> sampling = sample_poses(Grid())
        >>> round(sampling.spacing, 9), sampling.grid.tolist(), sampling.edges.tolist()
        (0.25, [[0, 0], [1, 0], [0, 1], [1, 1]], [[0, 1], [0, 2], [1, 3], [2, 3]])
    """
    config = config or SamplingConfig()
    base = np.asarray(exploration.base_poses(), dtype=float).reshape(-1, 3)
    camera = np.asarray(exploration.camera_poses(), dtype=float).reshape(-1, 3)
    if len(base) == 0:
        raise VisibilityBuilderError('no frames to sample poses from')
    if not np.isfinite(base[:, :2]).all():
        raise VisibilityBuilderError('frame positions must be finite')
    labels = _group_positions(base[:, :2], config.position_tolerance)
    headings = _heading_count(exploration, labels, camera[:, 2], config.headings)
    if headings == 1:
        return _position_poses(base, camera, labels, config)
    turns = _join_turns(exploration, headings, rho, config)
    return _heading_poses(base, camera, labels, headings, turns, config)


def _join_turns(exploration: Any, headings: int, rho: int, config: SamplingConfig) -> bool:
    """Return whether ``G`` joins neighbouring sectors (the module's sector-width rule)."""
    if config.turns != 'auto':
        return config.turns == 'always'
    info = getattr(exploration, 'camera_info', None)
    if info is None:
        return False
    fov = horizontal_fov(camera_from_info(info))
    width = 2.0 * math.pi / headings
    common = fov - 2.0 * max(int(rho), 1) * width
    join = common >= config.turn_overlap * fov - 1e-9
    _LOG.info('%.1f degree heading sectors, %.0f degree camera: the views of a rho = %d '
              'neighbourhood share %.0f degrees, turns %s', math.degrees(width),
              math.degrees(fov), rho, max(math.degrees(common), 0.0),
              'are edges of G' if join else 'are not edges of G (sectors are layers)')
    return bool(join)


def _heading_count(exploration: Any, labels: np.ndarray, heading: np.ndarray,
                   setting: int) -> int:
    """Return the sectors of the pose space (1: positions only)."""
    if setting:
        return int(setting)
    info = getattr(exploration, 'camera_info', None)
    if info is None or getattr(info, 'distortion_model', '') == 'cylindrical':
        return 1
    # The exploration's own count: distinct headings (to a degree) per position, median.
    degrees = np.rint(np.degrees(np.mod(heading, 2 * np.pi))).astype(np.int64) % 360
    pairs = np.unique(np.stack([labels, degrees], axis=1), axis=0)
    return int(np.median(np.bincount(pairs[:, 0])))


def _position_poses(base: np.ndarray, camera: np.ndarray, labels: np.ndarray,
                    config: SamplingConfig) -> PoseSampling:
    """Section 6.2.1's pose space: one pose per position, all its frames together."""
    n = int(labels.max()) + 1
    order = np.argsort(labels, kind='stable')
    splits = np.flatnonzero(np.diff(labels[order])) + 1
    frames_of_pose = tuple(tuple(int(i) for i in group) for group in np.split(order, splits))
    counts = np.bincount(labels, minlength=n)
    positions = np.stack([np.bincount(labels, base[:, 0], n),
                          np.bincount(labels, base[:, 1], n)], axis=1) / counts[:, None]
    yaw = camera[[group[0] for group in frames_of_pose], 2]
    sizes = np.bincount(counts)
    if np.count_nonzero(sizes) > 1:
        usual = int(np.argmax(sizes))
        _LOG.warning('%d of %d pose(s) have a number of frames other than the usual %d',
                     n - int(sizes[usual]), n, usual)
    grid, spacing, origin, angle, edges, graph = _position_graph(positions, config)
    _LOG.info('%d frames -> %d sampled poses; %s graph, %d edges, spacing %s', len(base), n,
              graph, len(edges), 'none' if spacing is None else f'{spacing:.4f} m')
    return PoseSampling(positions=positions, frames_of_pose=frames_of_pose, yaw=yaw, grid=grid,
                        spacing=spacing, origin=origin, angle=angle, edges=edges, graph=graph,
                        sector=np.zeros(n, dtype=np.int64))


def _heading_poses(base: np.ndarray, camera: np.ndarray, labels: np.ndarray, headings: int,
                   turns: bool, config: SamplingConfig) -> PoseSampling:
    """Return the heading pose space: a pose per (position, heading sector) (module doc)."""
    n_positions = int(labels.max()) + 1
    counts = np.bincount(labels, minlength=n_positions)
    centres = np.stack([np.bincount(labels, base[:, 0], n_positions),
                        np.bincount(labels, base[:, 1], n_positions)], axis=1) / counts[:, None]
    width = 2.0 * np.pi / headings
    # Sectors centred on the exploration's headings: the circular mean of the headings
    # modulo one sector width is the offset of sector 0.
    folded = np.mod(camera[:, 2], width) * (2.0 * np.pi / width)
    offset = float(np.arctan2(np.sin(folded).mean(), np.cos(folded).mean())) * width / (2 * np.pi)
    sector = np.rint((camera[:, 2] - offset) / width).astype(np.int64) % headings
    key = labels * headings + sector
    # Poses in the order of their first frame.
    unique_keys, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    rank = np.empty(len(unique_keys), dtype=np.int64)
    rank[np.argsort(first, kind='stable')] = np.arange(len(unique_keys))
    pose_of_frame = rank[inverse.reshape(-1)]
    n = len(unique_keys)
    pose_key = np.empty(n, dtype=np.int64)
    pose_key[pose_of_frame] = key
    pose_position, pose_sector = pose_key // headings, pose_key % headings
    order = np.argsort(pose_of_frame, kind='stable')
    splits = np.flatnonzero(np.diff(pose_of_frame[order])) + 1
    frames_of_pose = tuple(tuple(int(i) for i in group) for group in np.split(order, splits))
    several = sum(len(f) > 1 for f in frames_of_pose)
    if several:
        _LOG.warning('%d of %d (position, heading) pose(s) have several frames: they are '
                     'merged', several, n)
    grid_of_position, spacing, origin, angle, position_edges, graph = _position_graph(
        centres, config)
    # Poses by (position, sector), -1 where the exploration took no image.
    table = np.full((n_positions, headings), -1, dtype=np.int64)
    table[pose_position, pose_sector] = np.arange(n)
    edges = [np.empty((0, 2), dtype=np.int64)]
    for a, b in position_edges:           # same sector, neighbouring positions
        both = (table[a] >= 0) & (table[b] >= 0)
        edges.append(np.stack([table[a, both], table[b, both]], axis=1))
    if turns:                             # same position, neighbouring sectors
        turned = np.roll(table, -1, axis=1)
        both = (table >= 0) & (turned >= 0)
        edges.append(np.stack([table[both], turned[both]], axis=1))
    edges = _unique_edges(np.concatenate(edges).astype(np.int64))
    n_components = _components(n, edges)[0]
    if n_components > (1 if turns else headings):
        _LOG.warning('the pose graph (%s x %d headings) has %d connected components', graph,
                     headings, n_components)
    _LOG.info('%d frames -> %d sampled poses at %d positions x %d headings (%.1f degree '
              'sectors%s); %s graph, %d edges, spacing %s', len(base), n, n_positions,
              headings, np.degrees(width), ', turns joined' if turns else '', graph,
              len(edges), 'none' if spacing is None else f'{spacing:.4f} m')
    yaw = np.remainder(offset + width * pose_sector + np.pi, 2 * np.pi) - np.pi
    return PoseSampling(positions=centres[pose_position], frames_of_pose=frames_of_pose,
                        yaw=yaw, grid=grid_of_position[pose_position], spacing=spacing,
                        origin=origin, angle=angle, edges=edges, graph=graph,
                        headings=headings, sector=pose_sector, turns=turns)


def _position_graph(positions: np.ndarray, config: SamplingConfig
                    ) -> tuple[np.ndarray, float | None, np.ndarray | None, float | None,
                               np.ndarray, str]:
    """Return ``(grid, spacing, origin, angle, edges, graph)`` of positions (steps 2, 3)."""
    n = len(positions)
    lattice = _fit_lattice(positions, config) if n >= 2 else None
    grid = np.full((n, 2), -1, dtype=np.int64)
    if lattice is None:
        edges = _knn_edges(positions, np.arange(n), config.knn)
        edges = _connect_components(positions, edges)
        spacing = origin = angle = None
        graph = 'knn'
    else:
        spacing, origin, angle, cells, on_grid = lattice
        grid[on_grid] = cells[on_grid]
        edges = np.concatenate([_lattice_edges(grid, on_grid, config.connectivity),
                                _knn_edges(positions, np.flatnonzero(~on_grid), config.knn)])
        graph = f'grid{config.connectivity}'
        if not on_grid.all():
            _LOG.info('%d of %d pose(s) lie off the %.3f m lattice: joined to their %d '
                      'nearest poses', int((~on_grid).sum()), n, spacing, config.knn)
    edges = _unique_edges(edges)
    n_components = _components(n, edges)[0]
    if n_components > 1:
        _LOG.warning('the pose graph (%s) has %d connected components', graph, n_components)
    return grid, spacing, origin, angle, edges, graph


def _group_positions(points: np.ndarray, tolerance: float) -> np.ndarray:
    """Label points by connected groups within ``tolerance``, in order of first point."""
    n = len(points)
    if tolerance > 0:
        _, labels = _components(n, cKDTree(points).query_pairs(tolerance, output_type='ndarray'))
    else:  # exactly equal positions only
        labels = np.unique(points, axis=0, return_inverse=True)[1].reshape(-1)
    # Renumber in order of each group's first frame.
    first = np.full(labels.max() + 1, n, dtype=np.intp)
    np.minimum.at(first, labels, np.arange(n))
    rank = np.empty_like(first)
    rank[np.argsort(first, kind='stable')] = np.arange(len(first))
    return rank[labels]


def _components(n: int, edges: np.ndarray) -> tuple[int, np.ndarray]:
    edges = np.asarray(edges, dtype=np.intp).reshape(-1, 2)
    adjacency = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    count, labels = connected_components(adjacency, directed=False)
    return int(count), labels


def _circular_mean(angles: np.ndarray) -> float:
    return float(np.arctan2(np.sin(angles).mean(), np.cos(angles).mean()))


def _fit_lattice(positions: np.ndarray, config: SamplingConfig
                 ) -> tuple[float, np.ndarray, float, np.ndarray, np.ndarray] | None:
    """Return ``(spacing, origin, angle, cells (n,2), on_grid (n,))`` or None."""
    n = len(positions)
    distance, neighbour = cKDTree(positions).query(positions, k=2)
    spacing = float(np.median(distance[:, 1]))
    if not spacing > 0:
        return None
    step = positions[neighbour[:, 1]] - positions
    # Directions modulo 90 degrees: 4 * theta folds the four lattice axes onto one.
    angle = _circular_mean(4.0 * np.arctan2(step[:, 1], step[:, 0])) / 4.0
    if abs(angle) < 1e-12:
        angle = 0.0
    c, s = math.cos(angle), math.sin(angle)
    local = positions @ np.array([[c, -s], [s, c]])  # rotate by -angle
    phase = 2.0 * np.pi * local / spacing
    offset = np.array([_circular_mean(phase[:, 0]), _circular_mean(phase[:, 1])])
    offset = offset * spacing / (2.0 * np.pi)
    tolerance = config.grid_tolerance
    cells, on_grid = _snap(local, offset, spacing, tolerance)
    if on_grid.sum() >= 2 and np.ptp(cells[on_grid], axis=0).any():
        # Least squares: local = offset + spacing * cell, both axes at once.
        g = cells[on_grid].astype(float)
        k = len(g)
        design = np.zeros((2 * k, 3))
        design[:k, 0], design[k:, 1] = 1.0, 1.0
        design[:, 2] = np.concatenate([g[:, 0], g[:, 1]])
        target = np.concatenate([local[on_grid, 0], local[on_grid, 1]])
        (ox, oy, fitted), *_ = np.linalg.lstsq(design, target, rcond=None)
        if fitted > 0:
            offset, spacing = np.array([ox, oy]), float(fitted)
            cells, on_grid = _snap(local, offset, spacing, tolerance)
    if on_grid.sum() < max(2, config.min_grid_fraction * n):
        _LOG.info('positions are not on a lattice: %d of %d within %.0f %% of a %.3f m '
                  'spacing', int(on_grid.sum()), n, 100 * tolerance, spacing)
        return None
    on_grid = _one_pose_per_cell(local, offset, spacing, cells, on_grid)
    low = cells[on_grid].min(axis=0)
    cells = cells - low
    origin_local = offset + spacing * low
    origin = np.array([c * origin_local[0] - s * origin_local[1],
                       s * origin_local[0] + c * origin_local[1]])
    return spacing, origin, angle, cells, on_grid


def _snap(local: np.ndarray, offset: np.ndarray, spacing: float,
          tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    scaled = (local - offset) / spacing
    cells = np.rint(scaled).astype(np.int64)
    residual = np.linalg.norm(scaled - cells, axis=1)
    return cells, residual <= tolerance


def _one_pose_per_cell(local: np.ndarray, offset: np.ndarray, spacing: float,
                       cells: np.ndarray, on_grid: np.ndarray) -> np.ndarray:
    """Where poses share a cell, keep the closest on the lattice; the others go off it."""
    index = np.flatnonzero(on_grid)
    residual = np.linalg.norm((local[index] - offset) / spacing - cells[index], axis=1)
    order = np.lexsort((residual, cells[index, 1], cells[index, 0]))
    sorted_cells = cells[index[order]]
    duplicate = np.zeros(len(order), dtype=bool)
    duplicate[1:] = (sorted_cells[1:] == sorted_cells[:-1]).all(axis=1)
    if duplicate.any():
        _LOG.warning('%d pose(s) share a lattice cell with a closer pose: taken off the lattice',
                     int(duplicate.sum()))
    kept = on_grid.copy()
    kept[index[order[duplicate]]] = False
    return kept


def _lattice_edges(grid: np.ndarray, on_grid: np.ndarray, connectivity: int) -> np.ndarray:
    """Edges between poses in neighbouring cells (sorted keys, binary search)."""
    index = np.flatnonzero(on_grid)
    if len(index) < 2:
        return np.empty((0, 2), dtype=np.int64)
    cells = grid[index]
    width = int(cells[:, 1].max()) + 3  # room for j - 1 and j + 1 without wrapping

    def key(c: np.ndarray) -> np.ndarray:
        return c[:, 0] * width + (c[:, 1] + 1)

    keys = key(cells)
    order = np.argsort(keys)
    sorted_keys = keys[order]
    edges = []
    for offset in _OFFSETS[connectivity]:
        target = key(cells + offset)
        pos = np.clip(np.searchsorted(sorted_keys, target), 0, len(keys) - 1)
        hit = sorted_keys[pos] == target
        edges.append(np.stack([index[hit], index[order[pos[hit]]]], axis=1))
    return np.concatenate(edges)


def _knn_edges(positions: np.ndarray, sources: np.ndarray, knn: int) -> np.ndarray:
    """Edges from each pose in ``sources`` to its ``knn`` nearest other poses."""
    n = len(positions)
    k = min(int(knn), n - 1)
    if k < 1 or len(sources) == 0:
        return np.empty((0, 2), dtype=np.int64)
    _, neighbours = cKDTree(positions).query(positions[sources], k=k + 1)
    neighbours = neighbours.reshape(len(sources), k + 1)
    pairs = np.stack([np.repeat(sources, k + 1), neighbours.reshape(-1)], axis=1)
    return pairs[pairs[:, 0] != pairs[:, 1]].astype(np.int64)


def _unique_edges(edges: np.ndarray) -> np.ndarray:
    edges = np.sort(np.asarray(edges, dtype=np.int64).reshape(-1, 2), axis=1)
    edges = edges[edges[:, 0] != edges[:, 1]]
    return np.unique(edges, axis=0) if len(edges) else edges.reshape(0, 2)


def _connect_components(positions: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Add, while there are several components, the shortest edge from the smallest one."""
    edges = _unique_edges(edges)
    n = len(positions)
    added = []
    count, labels = _components(n, edges)
    while count > 1:
        sizes = np.bincount(labels)
        small = int(np.argmin(sizes))
        inside = np.flatnonzero(labels == small)
        outside = np.flatnonzero(labels != small)
        distance, nearest = cKDTree(positions[outside]).query(positions[inside])
        best = int(np.argmin(distance))
        added.append([inside[best], outside[nearest[best]]])
        edges = _unique_edges(np.concatenate([edges, np.array(added[-1:], dtype=np.int64)]))
        count, labels = _components(n, edges)
    if added:
        _LOG.info('k-nearest-neighbour graph: added %d edge(s) to connect it', len(added))
    return edges

"""Tests of visibility_builder.sampled_poses: grouping, lattice inference, the pose graph."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from paths import REPO
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from landmark_db.scenes import resolve_scene
from vbn_common.exploration import read_exploration
from vbn_worlds.synthesis.bags import BagSpec, write_bag
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.sampled_poses import PoseSampling, SamplingConfig, sample_poses

ROOT = REPO
HEADINGS = np.radians([0.0, 90.0, 180.0, -90.0])


class Poses:
    """A stand-in for an Exploration: base poses, camera poses equal."""

    def __init__(self, poses: np.ndarray) -> None:
        self.poses = np.asarray(poses, dtype=float)

    def base_poses(self) -> np.ndarray:
        return self.poses

    def camera_poses(self) -> np.ndarray:
        return self.poses


def lattice_frames(rows: int, cols: int, spacing: float, origin: tuple[float, float],
                   skip: set[tuple[int, int]] = frozenset()) -> tuple[np.ndarray, list]:
    """Four headings at every cell (i along x, j along y), row by row."""
    frames, cells = [], []
    for i in range(rows):
        for j in range(cols):
            if (i, j) in skip:
                continue
            cells.append((i, j))
            for h in HEADINGS:
                frames.append((origin[0] + i * spacing, origin[1] + j * spacing, h))
    return np.array(frames), cells


def grid_edges(cells: list, connectivity: int) -> set[tuple[int, int]]:
    index = {c: k for k, c in enumerate(cells)}
    steps = [(1, 0), (0, 1)] + ([(1, 1), (1, -1)] if connectivity == 8 else [])
    out = set()
    for (i, j), k in index.items():
        for di, dj in steps:
            other = index.get((i + di, j + dj))
            if other is not None:
                out.add((min(k, other), max(k, other)))
    return out


def edge_set(sampling: PoseSampling) -> set[tuple[int, int]]:
    return {(int(a), int(b)) for a, b in sampling.edges}


def assert_well_formed(sampling: PoseSampling) -> None:
    edges = sampling.edges
    assert edges.dtype.kind == 'i' and edges.shape[1] == 2
    assert (edges[:, 0] < edges[:, 1]).all()
    assert len(np.unique(edges, axis=0)) == len(edges)
    assert sorted(f for group in sampling.frames_of_pose for f in group) == list(
        range(sum(len(g) for g in sampling.frames_of_pose)))


def n_components(sampling: PoseSampling) -> int:
    n, e = sampling.n_poses, sampling.edges
    return connected_components(coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])),
                                           shape=(n, n)), directed=False)[0]


# -- hand-made lattices --------------------------------------------------------------------
@pytest.mark.parametrize('connectivity, n_edges', [(4, 17), (8, 29)])
def test_full_3x4_lattice_with_four_headings(connectivity: int, n_edges: int) -> None:
    frames, cells = lattice_frames(3, 4, 0.5, (1.0, -2.0))
    sampling = sample_poses(Poses(frames), SamplingConfig(connectivity=connectivity))
    assert_well_formed(sampling)
    assert sampling.n_poses == 12
    assert sampling.frames_of_pose == tuple(tuple(range(4 * k, 4 * k + 4)) for k in range(12))
    assert sampling.positions == pytest.approx(frames[::4, :2], abs=1e-12)
    assert np.array_equal(sampling.yaw, np.zeros(12))
    assert sampling.spacing == pytest.approx(0.5, abs=1e-12)
    assert sampling.origin == pytest.approx([1.0, -2.0], abs=1e-12)
    assert sampling.angle == 0.0
    assert sampling.grid.tolist() == [list(c) for c in cells]
    assert sampling.graph == f'grid{connectivity}'
    assert len(sampling.edges) == n_edges
    assert edge_set(sampling) == grid_edges(cells, connectivity)


def test_lattice_with_a_missing_cell() -> None:
    frames, cells = lattice_frames(3, 4, 0.5, (1.0, -2.0), skip={(1, 1)})
    sampling = sample_poses(Poses(frames))
    assert sampling.n_poses == 11
    assert sampling.grid.tolist() == [list(c) for c in cells]
    assert edge_set(sampling) == grid_edges(cells, 4)
    assert len(sampling.edges) == 17 - 4
    # The missing cell leaves (0, 1), (1, 0), (1, 2), (2, 1) without it as a neighbour.
    assert all(cells.index(c) >= 0 for c in [(0, 1), (1, 0), (1, 2), (2, 1)])


def test_missing_corner_keeps_the_origin_from_the_data() -> None:
    # Without cell (0, 0), the origin is still the lattice's (0, 0), from the other cells.
    frames, cells = lattice_frames(3, 4, 0.5, (1.0, -2.0), skip={(0, 0)})
    sampling = sample_poses(Poses(frames))
    assert sampling.origin == pytest.approx([1.0, -2.0], abs=1e-12)
    assert sampling.grid.tolist() == [list(c) for c in cells]


def test_rotated_noisy_lattice() -> None:
    rng = np.random.default_rng(3)
    frames, cells = lattice_frames(6, 5, 0.25, (0.0, 0.0))
    angle = math.radians(30.0)
    rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    xy = frames[:, :2] @ rot.T + [2.0, 1.0]
    noise = np.repeat(rng.normal(0.0, 0.005, (len(cells), 2)), 4, axis=0)  # one per position
    sampling = sample_poses(Poses(np.column_stack([xy + noise, frames[:, 2]])))
    assert sampling.n_poses == 30 and sampling.graph == 'grid4'
    assert sampling.spacing == pytest.approx(0.25, abs=0.003)
    assert sampling.angle == pytest.approx(angle, abs=0.01)
    assert (sampling.grid >= 0).all()
    assert edge_set(sampling) == grid_edges([tuple(c) for c in sampling.grid], 4)
    assert len(sampling.edges) == 5 * 5 + 6 * 4


def test_off_lattice_pose_gets_knn_edges() -> None:
    frames, cells = lattice_frames(3, 4, 0.5, (0.0, 0.0))
    extra = np.array([[0.26, 0.24, 0.3]])  # between four cells
    sampling = sample_poses(Poses(np.vstack([frames, extra])), SamplingConfig(knn=3))
    assert sampling.graph == 'grid4' and sampling.n_poses == 13
    assert sampling.grid[12].tolist() == [-1, -1] and (sampling.grid[:12] >= 0).all()
    lattice = grid_edges(cells, 4)
    extra_edges = edge_set(sampling) - lattice
    assert lattice <= edge_set(sampling)
    assert {b for a, b in extra_edges} == {12} and len(extra_edges) == 3
    assert sampling.yaw[12] == 0.3


def test_random_cloud_gets_a_connected_symmetric_knn_graph() -> None:
    rng = np.random.default_rng(11)
    points = rng.uniform(0.0, 5.0, (80, 2))
    sampling = sample_poses(Poses(np.column_stack([points, rng.uniform(-3, 3, 80)])),
                            SamplingConfig(knn=4))
    assert_well_formed(sampling)
    assert sampling.graph == 'knn' and sampling.spacing is None and sampling.origin is None
    assert (sampling.grid == -1).all()
    assert n_components(sampling) == 1
    # Every pose is joined to its 4 nearest poses (symmetric union).
    distance = np.linalg.norm(points[:, None] - points[None], axis=2)
    np.fill_diagonal(distance, np.inf)
    nearest = np.argsort(distance, axis=1)[:, :4]
    edges = edge_set(sampling)
    assert all((min(i, j), max(i, j)) in edges for i in range(80) for j in nearest[i])
    degree = np.bincount(sampling.edges.reshape(-1), minlength=80)
    assert degree.min() >= 4


def test_two_far_clusters_are_bridged_by_the_shortest_edge() -> None:
    rng = np.random.default_rng(5)
    a = rng.uniform(0, 1, (10, 2))
    b = rng.uniform(0, 1, (10, 2)) + [50.0, 0.0]
    points = np.vstack([a, b])
    sampling = sample_poses(Poses(np.column_stack([points, np.zeros(20)])),
                            SamplingConfig(knn=3))
    assert sampling.graph == 'knn' and n_components(sampling) == 1
    crossing = [(i, j) for i, j in edge_set(sampling) if (i < 10) != (j < 10)]
    distance = np.linalg.norm(a[:, None] - b[None], axis=2)
    i, j = np.unravel_index(np.argmin(distance), distance.shape)
    assert crossing == [(int(i), int(j) + 10)]


def test_positions_within_tolerance_are_one_pose() -> None:
    frames = np.array([[0.0, 0.0, 0.0], [0.005, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 0.01, 2.0]])
    sampling = sample_poses(Poses(frames))
    assert sampling.frames_of_pose == ((0, 1, 3), (2,))
    assert sampling.positions[0] == pytest.approx([0.005 / 3, 0.01 / 3])
    assert sampling.yaw.tolist() == [0.0, 0.0]
    assert sampling.edges.tolist() == [[0, 1]]
    tight = sample_poses(Poses(frames), SamplingConfig(position_tolerance=0.001))
    assert tight.n_poses == 4


def test_single_pose_has_no_edges() -> None:
    sampling = sample_poses(Poses(np.array([[1.0, 1.0, 0.0]] * 4)))
    assert sampling.n_poses == 1 and sampling.frames_of_pose == ((0, 1, 2, 3),)
    assert sampling.edges.shape == (0, 2) and sampling.spacing is None


def test_bad_input() -> None:
    with pytest.raises(VisibilityBuilderError, match='no frames to sample poses from'):
        sample_poses(Poses(np.empty((0, 3))))
    with pytest.raises(VisibilityBuilderError, match='frame positions must be finite'):
        sample_poses(Poses(np.array([[0.0, math.nan, 0.0]])))
    with pytest.raises(VisibilityBuilderError, match='connectivity must be 4 or 8, got 6'):
        SamplingConfig(connectivity=6)
    with pytest.raises(VisibilityBuilderError, match='knn must be a positive integer, got 0'):
        SamplingConfig(knn=0)
    with pytest.raises(VisibilityBuilderError, match=r'grid_tolerance must be in \(0, 0.5\)'):
        SamplingConfig(grid_tolerance=0.7)


# -- bags ----------------------------------------------------------------------------------
@pytest.mark.parametrize('name, n_poses, spacing, shape', [
    ('room_exploration', 200, 0.25, [23, 11]),
    ('floor_exploration', 84, 1.25, [16, 8]),
])
def test_committed_bags(name: str, n_poses: int, spacing: float, shape: list[int]) -> None:
    exploration = read_exploration(ROOT / 'bags' / name)
    sampling = sample_poses(exploration)
    assert_well_formed(sampling)
    assert sampling.n_poses == n_poses and sampling.graph == 'grid4'
    assert all(len(group) == 1 for group in sampling.frames_of_pose)  # one panorama each
    assert sampling.spacing == pytest.approx(spacing, abs=1e-9)
    assert (sampling.grid >= 0).all() and (sampling.grid.max(axis=0) + 1).tolist() == shape
    assert sampling.positions == pytest.approx(
        sampling.origin + spacing * sampling.grid, abs=1e-9)
    # Every edge joins two positions one spacing apart; every such pair is an edge.
    lengths = np.linalg.norm(sampling.positions[sampling.edges[:, 0]]
                             - sampling.positions[sampling.edges[:, 1]], axis=1)
    assert lengths == pytest.approx(spacing, abs=1e-9)
    distance = np.linalg.norm(sampling.positions[:, None] - sampling.positions[None], axis=2)
    assert len(sampling.edges) == int((np.abs(distance - spacing) < 1e-6).sum()) // 2


def test_pinhole_exploration_bag_four_headings_as_one_pose(tmp_path: Path) -> None:
    # The Room 408 layout (four headings) in the position-only pose space (headings=1).
    spec = BagSpec(kind='exploration', camera='pinhole', width=32, height=24, spacing=1.5,
                   compression='jpeg', encoding='mono8', headings=4)
    write_bag(resolve_scene('room'), spec, tmp_path / 'pin')
    exploration = read_exploration(tmp_path / 'pin')
    sampling = sample_poses(exploration, SamplingConfig(headings=1))   # positions only
    n = sampling.n_poses
    assert len(exploration.frames) == 4 * n and n >= 4 and sampling.headings == 1
    assert sampling.frames_of_pose == tuple(tuple(range(4 * k, 4 * k + 4)) for k in range(n))
    headings = exploration.camera_poses()[:, 2].reshape(n, 4)
    assert np.degrees(np.unwrap(headings, axis=1)) == pytest.approx(
        np.tile([0.0, 90.0, 180.0, 270.0], (n, 1)), abs=1e-9)
    assert sampling.yaw == pytest.approx(np.zeros(n), abs=1e-12)
    assert sampling.spacing == pytest.approx(1.5, abs=1e-9) and sampling.graph == 'grid4'


def test_pinhole_exploration_bag_gives_a_heading_pose_space(tmp_path: Path) -> None:
    # Eight headings of a 90 degree pinhole, the exploration's own count (headings=0, the
    # default): a pose per (position, heading).
    spec = BagSpec(kind='exploration', camera='pinhole', width=32, height=24, spacing=1.5,
                   compression='jpeg', encoding='mono8', headings=8)
    write_bag(resolve_scene('room'), spec, tmp_path / 'pin')
    exploration = read_exploration(tmp_path / 'pin')
    sampling = sample_poses(exploration)
    n = sampling.n_poses
    assert sampling.headings == 8 and len(exploration.frames) == n and n % 8 == 0
    assert sampling.frames_of_pose == tuple((k,) for k in range(n))
    camera_heading = exploration.camera_poses()[:, 2]
    assert np.cos(sampling.yaw - camera_heading) == pytest.approx(np.ones(n), abs=1e-9)
    assert sampling.sector.tolist() == [k % 8 for k in range(n)]
    positions = sample_poses(exploration, SamplingConfig(headings=1))
    assert positions.n_poses == n // 8
    # Each lattice edge once per heading, and no turn: every sector a layer of its own.
    assert len(sampling.edges) == 8 * len(positions.edges)
    a, b = sampling.edges.T
    assert np.all(sampling.sector[a] == sampling.sector[b])
    assert np.linalg.norm(sampling.positions[a] - sampling.positions[b],
                          axis=1) == pytest.approx(1.5, abs=1e-9)
    assert sampling.grid.tolist() == np.repeat(positions.grid, 8, axis=0).tolist()
    assert_well_formed(sampling)


@pytest.mark.parametrize('camera, hfov, headings, rho, turns, joined', [
    ('fisheye', 180.0, 16, 1, 'auto', True),    # 22.5 degree sectors: 135 degrees common
    ('fisheye', 180.0, 8, 1, 'auto', False),    # 45 degree sectors: 90 of 180 common
    ('fisheye', 180.0, 16, 2, 'auto', False),   # a turn by +-45 degrees in the ball
    ('pinhole', 90.0, 8, 1, 'auto', False),     # +-45 degrees of a 90 degree camera
    ('pinhole', 90.0, 32, 1, 'auto', True),     # 11.25 degree sectors: 67.5 common
    ('pinhole', 90.0, 8, 1, 'always', True),
    ('fisheye', 180.0, 16, 1, 'never', False),
])
def test_turning_edges_join_neighbouring_sectors_by_the_sector_width_rule(
        tmp_path: Path, camera: str, hfov: float, headings: int, rho: int, turns: str,
        joined: bool) -> None:
    spec = BagSpec(kind='exploration', camera=camera, width=32, height=24, spacing=1.5,
                   hfov_deg=hfov, compression='jpeg', encoding='mono8', headings=headings)
    write_bag(resolve_scene('room'), spec, tmp_path / 'bag')
    exploration = read_exploration(tmp_path / 'bag')
    sampling = sample_poses(exploration, SamplingConfig(turns=turns), rho=rho)
    positions = sample_poses(exploration, SamplingConfig(headings=1))
    n_positions = positions.n_poses
    assert sampling.headings == headings and sampling.turns is joined
    a, b = sampling.edges.T
    same_position = np.linalg.norm(sampling.positions[a] - sampling.positions[b], axis=1) < 1e-9
    # Steps: each lattice edge once per sector, within the sector.
    assert np.count_nonzero(~same_position) == headings * len(positions.edges)
    assert np.all(sampling.sector[a[~same_position]] == sampling.sector[b[~same_position]])
    # Turns: each position's ring of sectors, neighbours one sector apart (mod N).
    turn = (sampling.sector[b[same_position]] - sampling.sector[a[same_position]]) % headings
    assert np.count_nonzero(same_position) == (headings * n_positions if joined else 0)
    assert np.all((turn == 1) | (turn == headings - 1))
    assert n_components(sampling) == (1 if joined else headings)
    assert_well_formed(sampling)


def test_turns_setting_is_checked() -> None:
    with pytest.raises(VisibilityBuilderError, match='turns'):
        SamplingConfig(turns='sometimes')
    with pytest.raises(VisibilityBuilderError, match='turn_overlap'):
        SamplingConfig(turn_overlap=1.0)

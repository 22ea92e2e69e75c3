"""Algorithm 6.3, verification and filters on the rendered room bag, against ground truth.

The renderer knows the wall point behind every keypoint, so each class's purity is
measured (vbn_bench.purity). The classes are those of the builder's
defaults: Algorithm 6.3 (feature exclusion), then the geometric verification. The
fast test uses a 10 x 6 window of the exploration lattice; the bench test the whole
bag (200 panoramas).
"""
from __future__ import annotations

from dataclasses import dataclass
import time

import numpy as np
from paths import REPO
import pytest

from landmark_db.scenes import resolve_scene
from vbn_bench.purity import class_purity, keypoint_wall_points
from vbn_common.exploration import read_exploration
from vbn_common.features import extract_many
from vbn_common.geometry.camera import make_camera
from vbn_worlds.render.renderer import Renderer
from visibility_builder.classes import ClassConfig, correspondence_classes
from visibility_builder.filters import FilterConfig, retain_good_features
from visibility_builder.verification import VerifyConfig, verify_classes

ROOM = REPO / 'bags' / 'room_exploration'


@dataclass
class RoomData:
    descriptors: list[np.ndarray]
    keypoints: list[np.ndarray]
    sizes: list[np.ndarray]
    wall_points: list[np.ndarray]
    poses: np.ndarray
    camera_poses: np.ndarray
    grid: np.ndarray
    edges: np.ndarray


def load_room(window: tuple[int, int] | None) -> RoomData:
    """Features and ground truth of the room bag, optionally of a lattice window only."""
    from visibility_builder.sampled_poses import sample_poses

    exploration = read_exploration(ROOM)
    sampling = sample_poses(exploration)
    keep = np.ones(sampling.n_poses, bool)
    if window is not None:
        keep = (sampling.grid[:, 0] < window[0]) & (sampling.grid[:, 1] < window[1])
    chosen = np.flatnonzero(keep)
    remap = np.full(sampling.n_poses, -1)
    remap[chosen] = np.arange(len(chosen))
    inside = keep[sampling.edges].all(axis=1)
    edges = remap[sampling.edges[inside]]
    frames = [sampling.frames_of_pose[p][0] for p in chosen]   # one panorama per pose
    features = extract_many([exploration.frames[f].image for f in frames], workers=2)
    assert all(not isinstance(f, str) for f in features)
    scene = resolve_scene('room')
    renderer = Renderer(scene, make_camera('panoramic'))
    poses = np.array([exploration.frames[f].base_pose for f in frames])
    return RoomData(
        descriptors=[f.descriptors.astype(np.float32) for f in features],
        keypoints=[f.keypoints for f in features],
        sizes=[f.sizes for f in features],
        wall_points=[keypoint_wall_points(renderer, poses[i], f.keypoints)
                     for i, f in enumerate(features)],
        poses=poses, camera_poses=np.array([exploration.frames[f].camera_pose for f in frames]),
        grid=sampling.grid[chosen], edges=edges)


def default_classes(data: RoomData):
    """Algorithm 6.3 and the geometric verification, as the builder runs them."""
    result = correspondence_classes(data.descriptors, data.edges, ClassConfig())
    return verify_classes(result, data.keypoints, data.sizes, list(data.camera_poses),
                          make_camera('panoramic'), VerifyConfig())


def purity_of(data: RoomData, labels, min_poses: int):
    return class_purity(labels, data.keypoints, data.wall_points, data.poses,
                        make_camera('panoramic'), resolve_scene('room').camera_height,
                        keypoint_sizes=data.sizes, min_poses=min_poses)


def filtered_labels(labels, result):
    """Per-pose labels of the filtered classes (-1 where the filters dropped the pose)."""
    column = np.full(len(result.sizes_before), -1)
    column[result.kept_classes] = np.arange(len(result.kept_classes))
    out = []
    for v, lab in enumerate(labels):
        new = np.where(lab >= 0, column[np.maximum(lab, 0)], -1)
        row = set(result.visibility[v].indices.tolist())
        out.append(np.array([c if c in row else -1 for c in new.tolist()], np.int64))
    return out


@pytest.fixture(scope='module')
def room_window() -> RoomData:
    return load_room((10, 6))


def test_room_window_classes_are_pure_and_widely_visible(room_window):
    data = room_window
    result = default_classes(data)
    kept = retain_good_features(result.visibility, data.grid, data.edges,
                                FilterConfig(min_poses=9))
    purity = purity_of(data, filtered_labels(result.labels, kept), min_poses=1)
    # measured: 229 classes, 1 impure (a window's classes are cut at its border);
    # without the verification 242, 5 impure
    assert purity.n_classes == len(kept.kept_classes) >= 180
    assert purity.impure_fraction <= 0.015
    assert np.median(kept.sizes_after) >= 15
    assert result.stats['excluded_geometry'] > 0
    # the filters only ever remove
    names = [s.name for s in kept.steps]
    assert names == ['input', 'min_poses', 'largest_component', 'convex_trim', 'min_block']
    assert all(a.entries >= b.entries for a, b in zip(kept.steps, kept.steps[1:]))


def test_purity_measure_flags_a_wrong_merge(room_window):
    # The measure itself: relabel one class's features as another class's.
    data = room_window
    result = default_classes(data)
    sizes = np.asarray(result.visibility.sum(axis=0)).ravel()
    big = np.argsort(-sizes)[:2]
    merged = []
    for lab in result.labels:
        lab = lab.copy()
        if not (lab == big[0]).any():
            lab[lab == big[1]] = big[0]
        merged.append(lab)
    before = purity_of(data, result.labels, min_poses=2)
    after = purity_of(data, merged, min_poses=2)
    assert big[0] not in set(before.impure_ids.tolist())
    assert big[0] in set(after.impure_ids.tolist())


@pytest.mark.bench
def test_room_bag_purity_and_counts():
    start = time.perf_counter()
    data = load_room(None)
    result = default_classes(data)
    kept = retain_good_features(result.visibility, data.grid, data.edges, FilterConfig())
    purity = purity_of(data, filtered_labels(result.labels, kept), min_poses=1)
    print(f'room: {result.stats}, filters {kept.counts_dict()}, impure '
          f'{purity.n_impure}/{purity.n_classes}, median visibility '
          f'{np.median(kept.sizes_after)}, {time.perf_counter() - start:.1f} s')
    # measured (docs/classes.md): 489 classes, 1 impure (0.20 %); the previous
    # defaults (class exclusion, tau 100, symmetry factor 2, no verification) 202, 0.50 %
    assert len(kept.kept_classes) >= 440
    assert purity.impure_fraction <= 0.005

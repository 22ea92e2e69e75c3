"""The rendered room gives SIFT many distinctive, stable features."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from landmark_db.scenes import resolve_scene
from vbn_common.geometry.camera import make_camera
from vbn_worlds.render.effects import ImageEffects, apply_effects
from vbn_worlds.render.renderer import Renderer
from vbn_worlds.render.textures import sample_photographs


@pytest.fixture(scope='module')
def room_renderer():
    return Renderer(resolve_scene('room'), make_camera('panoramic'))


def _features(renderer, pose):
    out = renderer.render(np.array(pose), encoding='mono8', with_points=True)
    keypoints, descriptors = cv2.SIFT_create().detectAndCompute(out.image, None)
    return out, keypoints, descriptors


def _true_points(out, keypoints):
    uv = np.array([k.pt for k in keypoints])
    cols = np.clip(np.round(uv[:, 0]).astype(int), 0, out.image.shape[1] - 1)
    rows = np.clip(np.round(uv[:, 1]).astype(int), 0, out.image.shape[0] - 1)
    return out.wall_points[rows, cols]


def test_photographs_ship_with_scikit_image():
    photos = sample_photographs()
    assert len(photos) >= 8
    assert all(p.dtype == np.uint8 and p.ndim == 3 and p.shape[2] == 3 for p in photos)


@pytest.mark.parametrize('pose_a, pose_b', [
    ((1.0, 1.5, 0.0), (1.25, 1.5, 0.0)),
    ((3.0, 0.8, 0.0), (3.2, 1.0, 0.5)),
])
def test_nearby_panoramas_share_many_correct_sift_matches(room_renderer, pose_a, pose_b):
    a, ka, da = _features(room_renderer, pose_a)
    b, kb, db = _features(room_renderer, pose_b)
    assert len(ka) > 300 and len(kb) > 300
    pairs = cv2.BFMatcher().knnMatch(da, db, k=2)
    good = [m for m, n in pairs if m.distance < 0.8 * n.distance]
    assert len(good) > 150
    pa = _true_points(a, [ka[m.queryIdx] for m in good])
    pb = _true_points(b, [kb[m.trainIdx] for m in good])
    error = np.linalg.norm(pa - pb, axis=1)
    correct = np.sum(error < 0.05)
    # most matches are the same wall point, by the renderer's ground truth
    assert correct > 0.7 * len(good)


def test_far_apart_views_of_different_walls_match_little(room_renderer):
    # Facing opposite ends of the room: ratio-test matches exist (repeated
    # textures), but few of them are the same wall point.
    a, ka, da = _features(room_renderer, (0.6, 1.5, 0.0))
    b, kb, db = _features(room_renderer, (5.4, 1.5, 0.0))
    pairs = cv2.BFMatcher().knnMatch(da, db, k=2)
    good = [m for m, n in pairs if m.distance < 0.8 * n.distance]
    pa = _true_points(a, [ka[m.queryIdx] for m in good])
    pb = _true_points(b, [kb[m.trainIdx] for m in good])
    assert len(good) < 0.5 * min(len(ka), len(kb))
    assert np.isfinite(pa).all(axis=1).sum() > 0 and np.isfinite(pb).all(axis=1).sum() > 0


def test_effects_are_seeded_and_change_the_image(room_renderer):
    effects = ImageEffects(exposure=0.2, blur_sigma=1.0, noise_sigma=3.0)
    pose = np.array([2.0, 1.0, 0.0])
    clean = room_renderer.render(pose).image
    one = room_renderer.render(pose, effects=effects, rng=np.random.default_rng(5)).image
    two = room_renderer.render(pose, effects=effects, rng=np.random.default_rng(5)).image
    three = room_renderer.render(pose, effects=effects, rng=np.random.default_rng(6)).image
    assert np.array_equal(one, two)
    assert not np.array_equal(one, three)
    assert np.mean(np.abs(one.astype(int) - clean.astype(int))) > 1.0
    untouched = apply_effects(clean, ImageEffects(), np.random.default_rng(0))
    assert np.array_equal(untouched, clean)


def test_mono_and_colour_renders_agree(room_renderer):
    pose = np.array([4.0, 2.2, 1.0])
    colour = room_renderer.render(pose).image
    mono = room_renderer.render(pose, encoding='mono8').image
    assert mono.shape == colour.shape[:2]
    expected = cv2.cvtColor(colour, cv2.COLOR_BGR2GRAY).astype(int)
    assert np.mean(np.abs(mono.astype(int) - expected)) < 2.0


def test_repeated_textures_make_ambiguous_features(room_renderer):
    # Tiled brick repeats the same patch along walls: some keypoints have a
    # near-identical descriptor at another wall point, which a ratio test must reject.
    out, keypoints, descriptors = _features(room_renderer, (1.0, 1.5, 0.0))
    points = _true_points(out, keypoints)
    ambiguous = 0
    for i, matches in enumerate(cv2.BFMatcher().knnMatch(descriptors, descriptors, k=3)):
        others = [m for m in matches if m.trainIdx != i]
        if others and others[0].distance < 150 and np.linalg.norm(
                points[i] - points[others[0].trainIdx]) > 0.3:
            ambiguous += 1
    assert ambiguous >= 20

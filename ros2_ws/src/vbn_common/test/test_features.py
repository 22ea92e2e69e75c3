from __future__ import annotations

import cv2
import numpy as np
import pytest

from vbn_common.errors import VbnCommonError
from vbn_common.features import (
    ImageFeatures,
    SiftConfig,
    extract_features,
    extract_features_scaled,
    extract_many,
)
from vbn_common.images import EncodedImage


def textured(seed: int = 0, shape: tuple[int, int] = (120, 160)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    image = cv2.resize(rng.integers(0, 256, (shape[0] // 8, shape[1] // 8), np.uint8),
                       (shape[1], shape[0]), interpolation=cv2.INTER_NEAREST)
    return cv2.GaussianBlur(image, (3, 3), 0)


def test_features_match_opencv_and_descriptors_are_lossless_uint8() -> None:
    image = textured()
    feats = extract_features(image)
    keypoints, descriptors = cv2.SIFT_create(
        nOctaveLayers=SiftConfig().n_octave_layers).detectAndCompute(image, None)
    assert len(feats) == len(keypoints) > 20
    assert feats.descriptors.dtype == np.uint8 and feats.descriptors.shape[1] == 128
    # OpenCV's float descriptors are integers in 0..255: the uint8 copy is exact.
    assert np.array_equal(np.sort(descriptors.astype(np.uint8).sum(axis=1)),
                          np.sort(feats.descriptors.astype(int).sum(axis=1)))
    assert np.all(np.diff(feats.responses) <= 0)  # strongest first


def test_cap_and_empty_image() -> None:
    assert len(extract_features(textured(), SiftConfig(n_features=10))) <= 12
    empty = extract_features(np.zeros((50, 50), np.uint8))
    assert len(empty) == 0 and empty.descriptors.shape == (0, 128)
    with pytest.raises(VbnCommonError, match='invalid SIFT settings'):
        SiftConfig(sigma=0)


def test_extract_many_in_order_with_undecodable_images_reported() -> None:
    images = []
    for seed in range(5):
        ok, png = cv2.imencode('.png', textured(seed))
        images.append(EncodedImage(compressed=True, data=png.tobytes(), format='png'))
    images.insert(2, EncodedImage(compressed=True, data=b'not an image', format='jpeg'))
    done: list[int] = []
    serial = extract_many(images, workers=1, progress=done.append)
    parallel = extract_many(images, workers=2)
    assert sum(done) == 6
    assert isinstance(serial[2], str) and 'jpeg' in serial[2].lower()
    for a, b in zip(serial, parallel, strict=True):
        if isinstance(a, ImageFeatures):
            assert np.array_equal(a.descriptors, b.descriptors)
            assert np.array_equal(a.keypoints, b.keypoints)
        else:
            assert a == b


def test_scaled_features_are_in_full_image_pixels_and_match_full_size_ones() -> None:
    image = cv2.resize(textured(3, (128, 256)), None, fx=2, fy=2,
                       interpolation=cv2.INTER_CUBIC)  # smooth enough to survive halving
    full = extract_features(image)
    half = extract_features_scaled(image, 0.5)
    assert 0 < len(half) < len(full)
    # Each half-size keypoint lies on a full-size one of about its size, and most of
    # their descriptors are each other's nearest neighbours (what voting relies on).
    d = np.linalg.norm(half.keypoints[:, None] - full.keypoints[None], axis=2)
    nearest = d.argmin(axis=1)
    close = d.min(axis=1) <= 2.0
    assert close.mean() > 0.8
    size_ratio = half.sizes[close] / full.sizes[nearest[close]]
    assert np.median(size_ratio) == pytest.approx(1.0, abs=0.15)
    dist = np.linalg.norm(half.descriptors[close, None].astype(float)
                          - full.descriptors[None].astype(float), axis=2)
    assert (dist.argmin(axis=1) == nearest[close]).mean() > 0.6
    same = extract_features_scaled(image, 1.0)
    assert np.array_equal(same.keypoints, full.keypoints)
    with pytest.raises(ValueError, match='scale must be in'):
        extract_features_scaled(image, 0.0)

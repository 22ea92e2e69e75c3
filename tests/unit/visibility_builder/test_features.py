from __future__ import annotations

import cv2
import numpy as np
import pytest

from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.features import ImageFeatures, SiftConfig, extract_features, extract_many
from visibility_builder.images import EncodedImage


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
    with pytest.raises(VisibilityBuilderError, match='invalid SIFT settings'):
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

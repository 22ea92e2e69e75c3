"""The patch alignment's warp and correlation check (vbn_common.patch_alignment)."""
from __future__ import annotations

import cv2
import numpy as np

from vbn_common.patch_alignment import _correlations, warp_patches


def test_correlations_are_those_of_the_bilinear_sample_at_the_found_pixel() -> None:
    """Against OpenCV's own sub-pixel sampling (getRectSubPix) at random offsets, and a
    linear ramp correlates 1 with itself wherever it is sampled."""
    rng = np.random.default_rng(0)
    n, tile, side = 12, 43, 29
    crops = cv2.GaussianBlur(rng.uniform(0, 255, (n * tile, tile)).astype(np.float32),
                             (0, 0), 2.0).reshape(n, tile, tile)
    templates = rng.uniform(0, 255, (n, tile, tile)).astype(np.float32)
    at = (tile // 2 + rng.uniform(-4.0, 4.0, (n, 2))).astype(np.float32)
    lo = (tile - side) // 2
    expected = [np.corrcoef(cv2.getRectSubPix(crops[i], (side, side), tuple(map(float, at[i])))
                            .ravel(), templates[i, lo:lo + side, lo:lo + side].ravel())[0, 1]
                for i in range(n)]
    np.testing.assert_allclose(_correlations(crops, at, templates, side), expected, atol=1e-3)
    ramp = np.add.outer(np.arange(tile), 2.0 * np.arange(tile)).astype(np.float32)
    ramps = np.repeat(ramp[None], 3, axis=0)
    offsets = np.array([[21.0, 21.0], [21.5, 20.25], [18.3, 23.9]], np.float32)
    np.testing.assert_allclose(_correlations(ramps, offsets, ramps, side), 1.0, atol=1e-5)


def test_warp_is_opencv_warp_affine_of_each_patch() -> None:
    """One remap for all patches gives each patch's own warpAffine (replicated border)
    within one grey level of OpenCV's fixed-point rounding; the identity map puts the
    patch itself at the tile's centre, and a map doubling it puts it on every other pixel."""
    rng = np.random.default_rng(3)
    n, side, tile = 40, 11, 21
    patches = cv2.GaussianBlur(rng.integers(0, 256, (n * side, side), dtype=np.uint8),
                               (3, 3), 0.8).reshape(n, side, side)
    maps = np.eye(2)[None] * rng.uniform(0.6, 1.6, (n, 1, 1)) + rng.normal(0, 0.2, (n, 2, 2))
    centre = (side - 1) / 2
    expected = np.stack([cv2.warpAffine(
        patches[i], np.c_[maps[i], tile // 2 - maps[i].sum(axis=1) * centre], (tile, tile),
        flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE) for i in range(n)])
    warped = warp_patches(patches, maps, tile)
    assert warped.shape == (n, tile, tile) and warped.dtype == np.float32
    assert np.abs(warped - expected).max() <= 1.0
    assert np.mean(warped != expected) < 0.01
    lo = (tile - side) // 2
    same = warp_patches(patches[:3], np.repeat(np.eye(2)[None], 3, axis=0), tile)
    np.testing.assert_array_equal(same[:, lo:lo + side, lo:lo + side], patches[:3])
    np.testing.assert_array_equal(same[:, :lo, lo:lo + side],
                                  np.repeat(patches[:3, :1], lo, axis=1))  # replicated
    doubled = warp_patches(patches[:2], np.repeat(2 * np.eye(2)[None], 2, axis=0), tile)
    c = tile // 2
    np.testing.assert_array_equal(doubled[:, c - 10:c + 11:2, c - 10:c + 11:2],
                                  patches[:2])
    assert warp_patches(patches[:0], maps[:0], tile).shape == (0, tile, tile)

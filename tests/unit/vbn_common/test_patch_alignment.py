"""The patch alignment's correlation check (vbn_common.patch_alignment)."""
from __future__ import annotations

import cv2
import numpy as np

from vbn_common.patch_alignment import _correlations


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

"""The patch alignment's warp and correlation check (vbn_common.patch_alignment)."""
from __future__ import annotations

import cv2
import numpy as np

from vbn_common.patch_alignment import _correlations, _match_brightness, warp_patches


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


def test_matched_templates_take_their_crops_mean_and_contrast_on_the_central_square() -> None:
    rng = np.random.default_rng(4)
    n, tile, size, side = 6, 41, 31, 21
    crops = rng.uniform(0, 255, (n, tile, tile)).astype(np.float32)
    templates = rng.uniform(50, 90, (n, size, size)).astype(np.float32)
    templates[0] = 70.0    # flat: its contrast counts as 1 (no division by zero)
    out = _match_brightness(templates, crops, side)
    inner = out[:, 5:26, 5:26]
    outer = crops[:, 10:31, 10:31]
    np.testing.assert_allclose(inner.mean(axis=(1, 2)), outer.mean(axis=(1, 2)), rtol=1e-5)
    np.testing.assert_allclose(inner[1:].std(axis=(1, 2)), outer[1:].std(axis=(1, 2)),
                               rtol=1e-4)
    np.testing.assert_allclose(out[0], outer[0].mean(), rtol=1e-5)
    # The whole template moves with its square: one gain and offset for every pixel.
    gain = (out[1, 0, 0] - out[1, 0, 1]) / (templates[1, 0, 0] - templates[1, 0, 1])
    np.testing.assert_allclose(out[1] - out[1, 5, 5], gain * (templates[1] - templates[1, 5, 5]),
                               atol=1e-3)


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


def test_image_tiles_are_the_squares_at_their_corners() -> None:
    """By hand on a 5 x 6 ramp, and against a fancy index of every pixel at random corners."""
    from vbn_common.patch_alignment import image_tiles

    image = np.arange(30, dtype=np.uint8).reshape(5, 6)
    tiles = image_tiles(image, np.array([[0, 0], [3, 2]]), 3)
    np.testing.assert_array_equal(tiles[0], [[0, 1, 2], [6, 7, 8], [12, 13, 14]])
    np.testing.assert_array_equal(tiles[1], [[15, 16, 17], [21, 22, 23], [27, 28, 29]])
    rng = np.random.default_rng(4)
    big = rng.integers(0, 256, (120, 160), dtype=np.uint8)
    corners = np.stack([rng.integers(0, 160 - 21, 50), rng.integers(0, 120 - 21, 50)], 1)
    span = np.arange(21)
    expected = big[corners[:, 1, None, None] + span[None, :, None],
                   corners[:, 0, None, None] + span[None, None, :]]
    np.testing.assert_array_equal(image_tiles(big, corners, 21), expected)
    image_tiles(big, corners, 21)[0, 0, 0] = 0   # a copy: the image is untouched
    assert big[corners[0, 1], corners[0, 0]] == expected[0, 0, 0]


def test_tile_mosaic_centres_smaller_tiles_in_their_cells() -> None:
    from vbn_common.patch_alignment import tile_mosaic

    tiles = np.stack([np.full((3, 3), 10.0), np.full((3, 3), 20.4), np.full((3, 3), 300.0)])
    mosaic = tile_mosaic(tiles, 2, 5)
    assert mosaic.shape == (10, 10) and mosaic.dtype == np.uint8
    np.testing.assert_array_equal(mosaic[1:4, 1:4], 10)
    np.testing.assert_array_equal(mosaic[1:4, 6:9], 20)
    np.testing.assert_array_equal(mosaic[6:9, 1:4], 255)   # clipped
    assert mosaic.sum() == 9 * (10 + 20 + 255)             # zero around them, and the empty cell
    np.testing.assert_array_equal(tile_mosaic(tiles, 2), tile_mosaic(tiles, 2, 3))


def _align_with_whole_tiles(image, patches, uv, maps, max_shift_px, min_correlation):  # noqa: ANN001, ANN202
    """align_patches as it was before, every template warped over its whole tile."""
    import math

    from vbn_common.patch_alignment import (
        MARGIN_PX,
        _correlations,
        _match_brightness,
        image_tiles,
        tile_mosaic,
    )

    n, side = len(patches), patches.shape[1]
    pixel, found = np.full((n, 2), np.nan), np.zeros(n, bool)
    tile = side + 2 * (MARGIN_PX + int(math.ceil(max_shift_px)))
    half = tile // 2
    corner = np.round(uv).astype(np.int64) - half
    h, w = image.shape
    rows = np.flatnonzero((corner[:, 0] >= 0) & (corner[:, 1] >= 0) &
                          (corner[:, 0] + tile <= w) & (corner[:, 1] + tile <= h))
    crops = image_tiles(image, corner[rows], tile).astype(np.float32)
    templates = _match_brightness(warp_patches(patches[rows], maps[rows], tile), crops, side)
    cols = int(math.ceil(math.sqrt(len(rows))))
    cell = np.stack([np.arange(len(rows)) % cols, np.arange(len(rows)) // cols], 1) * tile
    guess = (uv[rows] - corner[rows] + cell).astype(np.float32).reshape(-1, 1, 2)
    moved, status, _ = cv2.calcOpticalFlowPyrLK(
        tile_mosaic(templates, cols), tile_mosaic(crops, cols),
        (cell + half).astype(np.float32).reshape(-1, 1, 2), guess.copy(),
        winSize=(side - 2, side - 2), maxLevel=0, flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
        criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 20, 0.01))
    moved = moved.reshape(-1, 2)
    good = (status.ravel() == 1) & \
        (np.linalg.norm(moved - guess.reshape(-1, 2), axis=1) <= max_shift_px)
    good[good] = _correlations(crops[good], (moved - cell)[good], templates[good],
                               side - 2) >= min_correlation
    pixel[rows[good]] = (moved - cell + corner[rows])[good]
    found[rows[good]] = True
    return pixel, found


def test_warping_only_the_central_square_aligns_exactly_as_the_whole_tile() -> None:
    """Lucas-Kanade's window, the brightness and the correlation read only the central
    square of a template: the same pixels to the last bit, on blurred noise with patches
    cut near their predictions and turned, scaled and sheared."""
    from vbn_common.patch_alignment import align_patches

    rng = np.random.default_rng(5)
    found_any = 0
    for _ in range(12):
        image = cv2.GaussianBlur(rng.integers(0, 256, (240, 320)).astype(np.uint8), (0, 0),
                                 float(rng.uniform(1.0, 3.0)))
        side, n = int(rng.choice([15, 21, 31])), int(rng.integers(1, 40))
        xs, ys = rng.integers(30, 320 - 30 - side, n), rng.integers(30, 240 - 30 - side, n)
        patches = np.stack([image[y:y + side, x:x + side] for x, y in zip(xs, ys, strict=True)])
        uv = np.stack([xs + side // 2, ys + side // 2], 1) + rng.normal(0.0, 2.0, (n, 2))
        maps = np.eye(2)[None] * rng.uniform(0.8, 1.2, (n, 1, 1)) + \
            rng.normal(0.0, 0.05, (n, 2, 2))
        shift = float(rng.uniform(3.0, 9.0))
        pixel, found = align_patches(image, patches, uv, maps, shift, 0.5)
        expected, expected_found = _align_with_whole_tiles(image, patches, uv, maps, shift,
                                                           0.5)
        np.testing.assert_array_equal(found, expected_found)
        np.testing.assert_array_equal(pixel, expected)
        found_any += int(found.sum())
    assert found_any > 100

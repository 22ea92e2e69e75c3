"""Align small image patches in an image where an affine warp predicts them.

Not in the thesis. A scene point of the database keeps a patch of one exploration image
centred on the point, and the patch's axes (the 3-D steps of one patch pixel right and
down); a pose then predicts where the point lies in another image and the affine map of
its patch there. :func:`align_patches` finds each point's pixel from that prediction:

1. warp each patch by its map into a tile centred on the point;
2. cut the image's tile around the predicted pixel and bring the warped patch to that
   tile's mean and contrast (exposure and lighting differ between images);
3. one pyramidal Lucas-Kanade call over two mosaics of all tiles (OpenCV), from the
   prediction;
4. an alignment that moved more than ``max_shift_px`` from the prediction, or whose
   patch then correlates with the image below ``min_correlation``, fails.

The builder aligns each point's patch in the exploration images that saw it to
triangulate the point where its patch is (:mod:`visibility_builder.point_patches`); the
localizer aligns them in its frames (:mod:`landmark_localizer.scene_patches`). Both
measure the same thing: the pixel of the patch's centre.
"""
from __future__ import annotations

import math

import cv2
from numba import njit
import numpy as np

__all__ = ['MARGIN_PX', 'align_patches', 'image_tiles', 'patch_maps', 'tile_mosaic',
           'warp_patches']

#: Image pixels around each warped patch in the mosaics beyond the largest move, for the
#: alignment's window.
MARGIN_PX = 2


def patch_maps(ends: np.ndarray, seam_width: float | None = None) -> np.ndarray:
    """Return each patch's affine map from the pixels of its point and its two axis ends.

    Args:
        ends: ``(3, n, 2)`` the pixels of the points, of the points plus their right axis
            and plus their down axis.
        seam_width: a panorama's width (a step across its seam wraps), or None.

    Returns:
        ``(n, 2, 2)``: the image pixels one patch pixel right (column 0) and down
        (column 1) moves to.
    """
    maps = np.stack([ends[1] - ends[0], ends[2] - ends[0]], axis=2)
    if seam_width is not None:
        maps[:, 0] = (maps[:, 0] + seam_width / 2) % seam_width - seam_width / 2
    return maps


def image_tiles(image: np.ndarray, corners: np.ndarray, size: int) -> np.ndarray:
    """``(n, size, size)`` copies of the image's squares at ``corners`` (``(n, 2)`` x, y).

    Every square must lie inside the image. One gather through a strided view: a fancy
    index of every pixel took ten times as long (75 tiles of 55 px: 0.84 against 0.07 ms).
    """
    corners = np.asarray(corners, np.int64).reshape(-1, 2)
    view = np.lib.stride_tricks.sliding_window_view(image, (size, size))
    return view[corners[:, 1], corners[:, 0]]


def tile_mosaic(tiles: np.ndarray, cols: int, cell: int | None = None) -> np.ndarray:
    """``(n, s, s)`` tiles laid row by row on a ``cols x cols`` grid, as one uint8 image.

    ``cell``: the grid's spacing (odd, at least ``s``; the tiles centred in their cells,
    zero around them), or None for ``s``. Values rounded half to even and clipped to
    ``[0, 255]``.
    """
    size = tiles.shape[1]
    cell = size if cell is None else cell
    return _mosaic(np.ascontiguousarray(tiles, np.float32), int(cols), int(cell))


@njit(cache=True)
def _mosaic(tiles: np.ndarray, cols: int, cell: int) -> np.ndarray:
    size = tiles.shape[1]
    lo = (cell - size) // 2
    out = np.zeros((cols * cell, cols * cell), np.uint8)
    for i in range(tiles.shape[0]):
        top, left = (i // cols) * cell + lo, (i % cols) * cell + lo
        for y in range(size):
            for x in range(size):
                out[top + y, left + x] = np.uint8(min(max(np.rint(tiles[i, y, x]), 0.0), 255.0))
    return out


def warp_patches(patches: np.ndarray, maps: np.ndarray, tile: int) -> np.ndarray:
    """Warp each ``(s, s)`` patch by its ``2 x 2`` map into a ``tile`` square, centred.

    Args:
        patches: ``(n, s, s)`` uint8, ``s`` odd.
        maps: ``(n, 2, 2)`` the image pixels one patch pixel right (column 0) and down
            (column 1) moves to.
        tile: The side of the output (odd).

    Returns:
        ``(n, tile, tile)`` float32: the patch centre at the tile's centre.
    """
    n, side = patches.shape[:2]
    if not n:
        return np.zeros((0, tile, tile), np.float32)
    # Each tile pixel's patch pixel by the inverse map (a singular map samples the
    # patch's centre everywhere), clamped to the patch: a replicated border.
    maps = np.asarray(maps, np.float64)
    det = maps[:, 0, 0] * maps[:, 1, 1] - maps[:, 0, 1] * maps[:, 1, 0]
    scale = np.divide(1.0, det, out=np.zeros_like(det), where=det != 0)
    inverse = (np.stack([maps[:, 1, 1], -maps[:, 0, 1], -maps[:, 1, 0], maps[:, 0, 0]], 1)
               * scale[:, None]).astype(np.float32)
    source = _remap_sources(inverse, tile, side)
    # One remap over the patches stacked in a column: one call instead of one a patch.
    out = cv2.remap(np.ascontiguousarray(patches).reshape(n * side, side),
                    source.reshape(n * tile, tile, 2), None, cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(n, tile, tile).astype(np.float32)


@njit(cache=True)
def _remap_sources(inverse: np.ndarray, tile: int, side: int) -> np.ndarray:
    """``(n, tile, tile, 2)`` float32: each tile pixel's source in the stacked patches.

    The inverse map ``(a, b; c, d)`` of patch ``i`` (``inverse[i]``) takes the pixel
    ``(right, down)`` from the tile's centre to ``(a right + b down, c right + d down)``
    from the patch's centre, clamped to the patch, ``i`` patches down the stack; in
    float32, as numpy's broadcast computed it.
    """
    n = inverse.shape[0]
    centre, top = np.float32((side - 1) / 2), np.float32(side - 1)
    zero, half = np.float32(0.0), tile // 2
    source = np.empty((n, tile, tile, 2), np.float32)
    for i in range(n):
        a, b, c, d = inverse[i, 0], inverse[i, 1], inverse[i, 2], inverse[i, 3]
        below = np.float32(i) * np.float32(side)
        for y in range(tile):
            down = np.float32(y - half)
            for x in range(tile):
                right = np.float32(x - half)
                source[i, y, x, 0] = min(max(a * right + (b * down + centre), zero), top)
                source[i, y, x, 1] = min(max(c * right + (d * down + centre), zero), top) + below
    return source


def align_patches(image: np.ndarray, patches: np.ndarray, uv: np.ndarray, maps: np.ndarray,
                  max_shift_px: float, min_correlation: float = 0.75
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Find each patch's centre in ``image`` near where it is predicted (module docstring).

    Args:
        image: ``(h, w)`` uint8 grey image.
        patches: ``(n, s, s)`` uint8 patches, ``s`` odd, each centred on its point.
        uv: ``(n, 2)`` the predicted pixels of the centres.
        maps: ``(n, 2, 2)`` the predicted affine maps (see :func:`warp_patches`).
        max_shift_px: Largest move from the prediction, pixels.
        min_correlation: Least normalised correlation of the aligned patch with the image.

    Returns:
        ``(pixel (n, 2), found (n,))``: the aligned centres (NaN where not found).
    """
    n = len(patches)
    pixel = np.full((n, 2), np.nan)
    found = np.zeros(n, bool)
    if not n:
        return pixel, found
    side = patches.shape[1]
    tile = side + 2 * (MARGIN_PX + int(math.ceil(max_shift_px)))
    half = tile // 2
    h, w = image.shape[:2]
    corner = np.round(np.nan_to_num(uv, nan=-1e6)).astype(np.int64) - half
    rows = np.flatnonzero(np.all(np.isfinite(uv), axis=1) & np.all(np.isfinite(maps.reshape(
        n, 4)), axis=1) & (corner[:, 0] >= 0) & (corner[:, 1] >= 0) &
        (corner[:, 0] + tile <= w) & (corner[:, 1] + tile <= h))
    if not len(rows):
        return pixel, found
    # Only the central square of each warped patch is read: Lucas-Kanade's window (two
    # pixels narrower, from the tile's centre, whole pixels) with its derivatives, the
    # brightness and the correlation. Warping the whole tile cost 2.7 times as much.
    templates = warp_patches(patches[rows], maps[rows], side)
    crops = image_tiles(image, corner[rows], tile).astype(np.float32)
    templates = _match_brightness(templates, crops, side)
    cols = int(math.ceil(math.sqrt(len(rows))))
    cell = np.stack([np.arange(len(rows)) % cols, np.arange(len(rows)) // cols], 1) * tile
    start = (cell + half).astype(np.float32).reshape(-1, 1, 2)
    guess = (uv[rows] - corner[rows] + cell).astype(np.float32).reshape(-1, 1, 2)
    window = side - 2
    moved, status, _ = cv2.calcOpticalFlowPyrLK(
        tile_mosaic(templates, cols, tile), tile_mosaic(crops, cols), start, guess.copy(),
        winSize=(window, window), maxLevel=0, flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
        criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 20, 0.01))
    moved = moved.reshape(-1, 2)
    at = (moved - cell + corner[rows]).astype(float)
    good = (status.ravel() == 1) & np.all(np.isfinite(at), axis=1) & \
        (np.linalg.norm(moved - guess.reshape(-1, 2), axis=1) <= max_shift_px)
    in_tile = moved - cell
    good[good] = _correlations(crops[good], in_tile[good], templates[good],
                               window) >= min_correlation
    pixel[rows[good]] = at[good]
    found[rows[good]] = True
    return pixel, found


def _match_brightness(templates: np.ndarray, crops: np.ndarray, side: int) -> np.ndarray:
    """Templates brought to their crops' mean and contrast over the central ``side`` square.

    The templates and the crops are centred squares, of any sizes of at least ``side``.
    Compiled (:func:`_brightness_kernel`): as numpy calls, a fifth of a millisecond for
    75 tiles.
    """
    return _brightness_kernel(np.ascontiguousarray(templates, np.float32),
                              np.ascontiguousarray(crops, np.float32), side)


@njit(cache=True)
def _square_moments(tiles: np.ndarray, i: int, lo: int, side: int) -> tuple[float, float]:
    """Mean and standard deviation of tile ``i``'s ``side`` square from ``(lo, lo)``."""
    total = 0.0
    for y in range(lo, lo + side):
        for x in range(lo, lo + side):
            total += tiles[i, y, x]
    mean = total / (side * side)
    spread = 0.0
    for y in range(lo, lo + side):
        for x in range(lo, lo + side):
            spread += (tiles[i, y, x] - mean) ** 2
    return mean, math.sqrt(spread / (side * side))


@njit(cache=True)
def _brightness_kernel(templates: np.ndarray, crops: np.ndarray, side: int) -> np.ndarray:
    lo, at = (templates.shape[1] - side) // 2, (crops.shape[1] - side) // 2
    out = np.empty_like(templates)
    for i in range(templates.shape[0]):
        mean_t, std_t = _square_moments(templates, i, lo, side)
        mean_c, std_c = _square_moments(crops, i, at, side)
        gain = std_c / max(std_t, 1.0)
        for y in range(templates.shape[1]):
            for x in range(templates.shape[2]):
                out[i, y, x] = (templates[i, y, x] - mean_t) * gain + mean_c
    return out


def _correlations(crops: np.ndarray, at: np.ndarray, templates: np.ndarray, side: int
                  ) -> np.ndarray:
    """Normalised correlation of each template's central square with its crop at ``at``.

    The crop is sampled bilinearly (its edge repeated beyond it). Compiled
    (:func:`_correlation_kernel`).

    Args:
        crops: ``(n, t, t)`` the image's tiles.
        at: ``(n, 2)`` where each template's centre was found, in its tile's pixels.
        templates: ``(n, s, s)`` the warped patches, centred (``s`` odd, at least ``side``).
        side: The side of the compared square (odd).
    """
    if not len(crops):
        return np.zeros(0)
    return _correlation_kernel(np.ascontiguousarray(crops, np.float32),
                               np.ascontiguousarray(at, np.float64),
                               np.ascontiguousarray(templates, np.float32), side)


@njit(cache=True)
def _correlation_kernel(crops: np.ndarray, at: np.ndarray, templates: np.ndarray, side: int
                        ) -> np.ndarray:
    n, tile = crops.shape[0], crops.shape[1]
    lo = (templates.shape[1] - side) // 2
    out = np.empty(n)
    sample = np.empty((side, side))
    for i in range(n):
        bx, by = math.floor(at[i, 0]), math.floor(at[i, 1])
        fx, fy = at[i, 0] - bx, at[i, 1] - by
        x0, y0 = int(bx) - side // 2, int(by) - side // 2
        mean_s, mean_r = 0.0, 0.0
        for y in range(side):
            ya, yb = min(max(y0 + y, 0), tile - 1), min(max(y0 + y + 1, 0), tile - 1)
            for x in range(side):
                xa, xb = min(max(x0 + x, 0), tile - 1), min(max(x0 + x + 1, 0), tile - 1)
                top = crops[i, ya, xa] * (1 - fx) + crops[i, ya, xb] * fx
                bottom = crops[i, yb, xa] * (1 - fx) + crops[i, yb, xb] * fx
                sample[y, x] = top * (1 - fy) + bottom * fy
                mean_s += sample[y, x]
                mean_r += templates[i, lo + y, lo + x]
        mean_s /= side * side
        mean_r /= side * side
        ab, aa, bb = 0.0, 0.0, 0.0
        for y in range(side):
            for x in range(side):
                a = sample[y, x] - mean_s
                b = templates[i, lo + y, lo + x] - mean_r
                ab += a * b
                aa += a * a
                bb += b * b
        out[i] = ab / max(math.sqrt(aa * bb), 1e-9)
    return out

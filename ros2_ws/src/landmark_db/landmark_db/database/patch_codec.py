"""The scene points' exploration patches stored as JPEG mosaics (schema 5).

Beyond the thesis. A patch is ``s x s`` uint8 pixels (``s`` odd, 15 by default), cut
from the exploration image nearest where its point was seen; the localizer aligns it in
every tracked frame, brightness and contrast matched, by Lucas-Kanade
(:mod:`vbn_common.patch_alignment`). Stored whole, the patches were the largest part of
a database after the descriptors. Here they are tiled into mosaics of 64 x 64 tiles (a
tile is the patch padded by its edge pixels to the next multiple of 8, so that JPEG's
8 x 8 blocks never straddle two patches) and each mosaic is coded as a baseline
grey-scale JPEG. At quality 80 a 15 px patch takes about 55 bytes instead of 225, its
pixels about 2.6 grey levels (RMS) from the original on patches of about 32 levels of
spread; the localizer measured the same accuracy with them (docs/localization.md). At
70, the builder's default since patches go to points seen by 5 images, about 44 bytes.

The code is the stored form: a database keeps the code and the patches it decodes to
(:meth:`~landmark_db.database.points.ScenePoints.with_patch_code`), so coding once
more is never needed and what is read equals what was built.
"""
from __future__ import annotations

import cv2
import numpy as np

from landmark_db.errors import LandmarkDbError

__all__ = ['MOSAIC_TILES', 'decode_patches', 'encode_patches']

MOSAIC_TILES = 64
"""Tiles per mosaic row and rows per mosaic (at most 4,096 patches a JPEG)."""

_LENGTH = 4  # little-endian patch count, then byte count, before each JPEG of the code


def _tile(side: int) -> int:
    return -(-side // 8) * 8


def encode_patches(patches: np.ndarray, quality: int) -> bytes:
    """Return the JPEG mosaics of ``(n, s, s)`` uint8 patches at ``quality`` (1 to 100).

    Raises:
        LandmarkDbError: not ``(n >= 1, s, s)`` uint8, a quality outside 1..100, or
            OpenCV fails to code.
    """
    patches = np.asarray(patches)
    if patches.dtype != np.uint8 or patches.ndim != 3 or not len(patches) or \
            patches.shape[1] != patches.shape[2] or patches.shape[1] < 1:
        raise LandmarkDbError(f'patches to code must be (n >= 1, s, s) uint8, got '
                              f'{patches.dtype} {patches.shape}')
    if isinstance(quality, bool) or not isinstance(quality, (int, np.integer)) or \
            not 1 <= quality <= 100:
        raise LandmarkDbError(f'patch JPEG quality must be an integer 1..100, got {quality!r}')
    side = patches.shape[1]
    tile = _tile(side)
    padded = np.pad(patches, ((0, 0), (0, tile - side), (0, tile - side)), mode='edge')
    per_image = MOSAIC_TILES * MOSAIC_TILES
    out = bytearray()
    for start in range(0, len(padded), per_image):
        chunk = padded[start:start + per_image]
        rows = -(-len(chunk) // MOSAIC_TILES)
        grid = np.zeros((rows * MOSAIC_TILES, tile, tile), np.uint8)
        grid[:len(chunk)] = chunk
        grid[len(chunk):] = chunk[-1]  # fill the last row with a copy, not a hard edge
        mosaic = grid.reshape(rows, MOSAIC_TILES, tile, tile).transpose(0, 2, 1, 3) \
            .reshape(rows * tile, MOSAIC_TILES * tile)
        ok, jpeg = cv2.imencode('.jpg', mosaic, [cv2.IMWRITE_JPEG_QUALITY, int(quality),
                                                 cv2.IMWRITE_JPEG_OPTIMIZE, 1])
        if not ok:
            raise LandmarkDbError('OpenCV could not code the patches as JPEG')
        out += len(chunk).to_bytes(_LENGTH, 'little') + len(jpeg).to_bytes(_LENGTH, 'little') \
            + jpeg.tobytes()
    return bytes(out)


def decode_patches(code: bytes, n: int, side: int) -> np.ndarray:
    """Return the ``(n, side, side)`` uint8 patches of :func:`encode_patches`' code.

    Raises:
        LandmarkDbError: the code is damaged or holds another number or size of patches.
    """
    tile = _tile(side)
    per_image = MOSAIC_TILES * MOSAIC_TILES
    out = np.empty((n, side, side), np.uint8)
    at, done = 0, 0
    view = memoryview(code)
    while done < n:
        if at + 2 * _LENGTH > len(view):
            raise LandmarkDbError(f'the patch code ends after {done} of {n} patches')
        count = int.from_bytes(view[at:at + _LENGTH], 'little')
        length = int.from_bytes(view[at + _LENGTH:at + 2 * _LENGTH], 'little')
        at += 2 * _LENGTH
        if count != min(per_image, n - done):
            raise LandmarkDbError(f'the patch code holds {done + count} patches, not {n}')
        data = np.frombuffer(view[at:at + length], np.uint8)
        at += length
        mosaic = None
        if 0 < length == len(data):
            try:
                mosaic = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
            except cv2.error:
                mosaic = None
        rows = -(-count // MOSAIC_TILES)
        if mosaic is None or mosaic.shape != (rows * tile, MOSAIC_TILES * tile):
            raise LandmarkDbError(f'the patch code is damaged (its JPEG {done // per_image} '
                                  f'does not hold {count} patches of {side} px)')
        tiles = mosaic.reshape(rows, tile, MOSAIC_TILES, tile).transpose(0, 2, 1, 3) \
            .reshape(-1, tile, tile)
        out[done:done + count] = tiles[:count, :side, :side]
        done += count
    if at != len(view):
        raise LandmarkDbError(f'the patch code holds more than {n} patches')
    return out

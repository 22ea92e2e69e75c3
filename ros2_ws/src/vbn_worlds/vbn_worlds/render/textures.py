"""Wall textures for the renderer: photographs, procedural posters and repeated tiles.

SIFT needs texture that is distinctive (so that a feature is recognised from many
poses) and stable (the same wall point looks the same from nearby poses). Every wall
segment of the scene gets its own texture, laid out in metres: ``u`` is the arc
length along the wall (reading left to right as seen from the wall's free side) and
``v`` the height above the floor. A wall is a smooth painted background (few
features) with, chosen per wall by a generator seeded with ``(texture_seed, wall
index)``:

- posters: crops of the public-domain sample photographs that scikit-image ships
  (``skimage.data``: astronaut, camera, coffee, chelsea, rocket, hubble_deep_field,
  ...) and procedural posters (seeded shapes and letters drawn with OpenCV);
- repeated tiles: a band of identical tiles, or the sample brick photograph tiled,
  so that ambiguous, repeated features exist and the correspondence filters have
  something to reject.

All textures are packed into one atlas with a Gaussian mip pyramid
(:class:`WallAtlas`); the renderer samples it with ``cv2.remap`` at the level that
matches each column's pixel footprint, so distant walls do not alias.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import functools
import logging
import math

import cv2
import numpy as np

from landmark_db.scene import Scene

__all__ = ['Appearance', 'WallAtlas', 'build_wall_atlas', 'procedural_poster',
           'sample_photographs', 'visible_side_flip']

_LOG = logging.getLogger(__name__)

#: Sample photographs used as posters (all in the scikit-image wheel, no download).
PHOTO_NAMES = ('astronaut', 'camera', 'coffee', 'chelsea', 'rocket', 'hubble_deep_field',
               'immunohistochemistry', 'coins', 'clock', 'text', 'page', 'moon')

_MAX_STRIP = 8192
_MAX_ATLAS = 32000
_LETTERS = np.array(list('ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789'))


@functools.lru_cache(maxsize=1)
def sample_photographs() -> tuple[np.ndarray, ...]:
    """Return the scikit-image sample photographs as BGR ``uint8`` arrays.

    Photographs that this scikit-image cannot load offline are skipped with a
    warning; procedural posters then take their place.
    """
    try:
        from skimage import data
    except ImportError:  # pragma: no cover - scikit-image is a project requirement
        _LOG.warning('scikit-image is not installed: walls get procedural posters only')
        return ()
    photos = []
    for name in PHOTO_NAMES:
        try:
            image = np.asarray(getattr(data, name)())
        except Exception as error:  # noqa: BLE001 - any loader failure: skip the photo
            _LOG.warning('sample photograph %s unavailable: %s', name, error)
            continue
        if image.dtype != np.uint8:
            image = (255 * (image.astype(float) / max(float(image.max()), 1e-9))).astype(np.uint8)
        if image.ndim == 2:
            image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        else:
            image = cv2.cvtColor(image[..., :3], cv2.COLOR_RGB2BGR)
        photos.append(np.ascontiguousarray(image))
    return tuple(photos)


@functools.lru_cache(maxsize=1)
def _brick() -> np.ndarray | None:
    try:
        from skimage import data
        return cv2.cvtColor(np.asarray(data.brick()), cv2.COLOR_GRAY2BGR)
    except Exception:  # noqa: BLE001 - optional texture
        return None


def _colour(rng: np.random.Generator, lo: int = 0, hi: int = 256) -> tuple[int, int, int]:
    c = rng.integers(lo, hi, size=3)
    return int(c[0]), int(c[1]), int(c[2])


def procedural_poster(rng: np.random.Generator, width: int, height: int) -> np.ndarray:
    """Draw a seeded poster of shapes and letters.

    Args:
        rng: the generator that decides every shape.
        width: poster width, texels.
        height: poster height, texels.

    Returns:
        ``(height, width, 3)`` BGR ``uint8`` image.
    """
    scale = 2  # draw large, then shrink: anti-aliased edges
    w, h = width * scale, height * scale
    poster = np.empty((h, w, 3), np.uint8)
    poster[:] = _colour(rng, 0, 256)
    size = min(w, h)
    for _ in range(int(rng.integers(10, 22))):
        kind = int(rng.integers(0, 5))
        colour = _colour(rng)
        cx, cy = int(rng.integers(0, w)), int(rng.integers(0, h))
        r = int(rng.integers(size // 16, size // 4 + 2))
        if kind == 0:
            cv2.rectangle(poster, (cx - r, cy - r // 2), (cx + r, cy + r // 2), colour, -1)
        elif kind == 1:
            cv2.circle(poster, (cx, cy), r, colour, -1, cv2.LINE_AA)
        elif kind == 2:
            angles = np.sort(rng.uniform(0, 2 * math.pi, int(rng.integers(3, 7))))
            radii = rng.uniform(0.4, 1.0, angles.size) * r
            pts = np.stack([cx + radii * np.cos(angles), cy + radii * np.sin(angles)], 1)
            cv2.fillPoly(poster, [pts.astype(np.int32)], colour, cv2.LINE_AA)
        elif kind == 3:
            end = (int(rng.integers(0, w)), int(rng.integers(0, h)))
            cv2.line(poster, (cx, cy), end, colour, int(rng.integers(2, max(3, size // 30))),
                     cv2.LINE_AA)
        else:
            cv2.ellipse(poster, (cx, cy), (r, max(2, r // 2)), float(rng.uniform(0, 180)), 0,
                        360, colour, -1, cv2.LINE_AA)
    for _ in range(int(rng.integers(1, 4))):
        text = ''.join(rng.choice(_LETTERS, size=int(rng.integers(3, 8))))
        font = int(rng.choice([cv2.FONT_HERSHEY_SIMPLEX, cv2.FONT_HERSHEY_DUPLEX,
                               cv2.FONT_HERSHEY_TRIPLEX]))
        font_scale = size / 90.0 * float(rng.uniform(0.6, 1.2))
        org = (int(rng.integers(0, max(1, w // 3))), int(rng.integers(h // 6, h)))
        cv2.putText(poster, text, org, font, font_scale, _colour(rng),
                    max(1, int(font_scale * 2)), cv2.LINE_AA)
    return cv2.resize(poster, (width, height), interpolation=cv2.INTER_AREA)


def _photo_poster(rng: np.random.Generator, photo: np.ndarray, width: int,
                  height: int) -> np.ndarray:
    ph, pw = photo.shape[:2]
    aspect = width / height
    crop_w = pw * rng.uniform(0.55, 1.0)
    crop_h = crop_w / aspect
    if crop_h > ph:
        crop_h = ph * rng.uniform(0.7, 1.0)
        crop_w = crop_h * aspect
    crop_w, crop_h = max(8, int(min(crop_w, pw))), max(8, int(min(crop_h, ph)))
    x0 = int(rng.integers(0, pw - crop_w + 1))
    y0 = int(rng.integers(0, ph - crop_h + 1))
    crop = photo[y0:y0 + crop_h, x0:x0 + crop_w]
    interpolation = cv2.INTER_AREA if crop_w > width else cv2.INTER_CUBIC
    return cv2.resize(crop, (width, height), interpolation=interpolation)


def _tile_motif(rng: np.random.Generator, size: int) -> np.ndarray:
    tile = np.empty((size, size, 3), np.uint8)
    tile[:] = _colour(rng, 150, 256)
    edge = _colour(rng, 0, 120)
    cv2.rectangle(tile, (0, 0), (size - 1, size - 1), edge, max(1, size // 16))
    c = size // 2
    cv2.circle(tile, (c, c), size // 4, _colour(rng, 0, 200), -1, cv2.LINE_AA)
    cv2.line(tile, (size // 8, size // 8), (c, c), edge, max(1, size // 20), cv2.LINE_AA)
    return tile


def _plaster(rng: np.random.Generator, width: int, height: int, tpm: float) -> np.ndarray:
    base = np.array(_colour(rng, 140, 235), np.float32)
    coarse_w = max(2, int(width / tpm * 3) + 2)
    coarse_h = max(2, int(height / tpm * 3) + 2)
    noise = rng.normal(0.0, 5.0, size=(coarse_h, coarse_w)).astype(np.float32)
    noise = cv2.resize(noise, (width, height), interpolation=cv2.INTER_CUBIC)
    wall = base[None, None, :] + noise[..., None]
    return np.clip(wall, 0, 255).astype(np.uint8)


@dataclass(frozen=True)
class Appearance:
    """How the walls look on the day of a recording (a world that changed).

    The default is the scene as explored. Light: every wall's shade is multiplied by
    ``gain`` and by ``1 + side_strength * cos(angle between the wall's normal and the
    direction side_deg)`` (at least 0.2): windows or lamps on one side. Posters: the
    walls in ``rehung`` get other posters at other places (drawn with ``seed``), those
    in ``bare`` none; their paint, tiles and bricks stay.

    Attributes:
        gain: Global light gain (0.5 to 1.5 in the benchmark).
        side_deg: Direction the side light comes from, degrees in ``map``.
        side_strength: Its strength (0: none).
        rehung: Wall segment indices whose posters are replaced and moved.
        bare: Wall segment indices whose posters are taken down.
        seed: Seeds the rehung posters.
    """

    gain: float = 1.0
    side_deg: float = 0.0
    side_strength: float = 0.0
    rehung: tuple[int, ...] = ()
    bare: tuple[int, ...] = ()
    seed: int = 1

    def shade(self, normals: np.ndarray) -> np.ndarray:
        """Return each wall's light factor from its free-side unit normal ``(s, 2)``."""
        base = 0.82 + 0.18 * (normals @ np.array([math.cos(0.7), math.sin(0.7)]))
        side = np.array([math.cos(math.radians(self.side_deg)),
                         math.sin(math.radians(self.side_deg))])
        return self.gain * base * np.maximum(0.2, 1.0 + self.side_strength * (normals @ side))


def _wall_texture(rng: np.random.Generator, length: float, wall_height: float,
                  tpm: float, posters: np.random.Generator | None = None,
                  bare: bool = False) -> np.ndarray:
    """Compose one wall's texture: ``(rows, cols, 3)``, row 0 at the top of the wall.

    ``posters``: draw the posters from this generator instead of ``rng`` (rehung);
    ``bare``: no posters.
    """
    cols = max(1, int(math.ceil(length * tpm)))
    rows = max(1, int(math.ceil(wall_height * tpm)))
    wall = _plaster(rng, cols, rows, tpm)
    skirting = max(1, int(0.08 * tpm))
    wall[rows - skirting:] = _colour(rng, 20, 90)

    def place(image: np.ndarray, left_m: float, bottom_m: float, frame: bool = True) -> None:
        h, w = image.shape[:2]
        x0 = int(round(left_m * tpm))
        y1 = rows - int(round(bottom_m * tpm))
        y0 = y1 - h
        if y0 < 0 or x0 < 0 or x0 + w > cols:
            return
        wall[y0:y1, x0:x0 + w] = image
        if frame:
            cv2.rectangle(wall, (x0, y0), (x0 + w - 1, y1 - 1), (30, 30, 30),
                          max(1, int(0.015 * tpm)))

    style = rng.choice(['posters', 'posters', 'posters', 'tiles', 'brick'])
    if style == 'brick' and _brick() is not None:
        brick = cv2.resize(_brick(), (int(tpm * 1.0), int(tpm * 1.0)),
                           interpolation=cv2.INTER_AREA)
        reps = (rows // brick.shape[0] + 1, cols // brick.shape[1] + 1, 1)
        wall[:rows - skirting] = np.tile(brick, reps)[:rows - skirting, :cols]
    elif style == 'tiles':
        size = max(4, int(tpm * float(rng.uniform(0.2, 0.3))))
        motif = _tile_motif(rng, size)
        band_rows = int(rng.integers(3, 6))
        bottom = float(rng.uniform(0.5, 0.9))
        reps = (band_rows, cols // size + 1, 1)
        band = np.tile(motif, reps)[:, :cols]
        y1 = rows - int(bottom * tpm)
        y0 = max(0, y1 - band.shape[0])
        wall[y0:y1] = band[band.shape[0] - (y1 - y0):]

    if bare:
        return wall
    rng = rng if posters is None else posters
    photos = sample_photographs()
    x = float(rng.uniform(0.05, 0.4))
    while x < length - 0.15:
        width_m = min(float(rng.uniform(0.4, 1.0)), length - x - 0.05)
        if width_m < 0.2:
            break
        height_m = min(float(rng.uniform(0.4, 1.0)), wall_height - 0.3)
        bottom_m = float(rng.uniform(0.7, max(0.71, min(1.3, wall_height - height_m - 0.1))))
        w_tex, h_tex = max(4, int(width_m * tpm)), max(4, int(height_m * tpm))
        if style == 'tiles' or style == 'brick':
            # fewer posters on tiled walls: keep the repeated texture visible
            if rng.uniform() < 0.5:
                x += width_m + float(rng.uniform(0.3, 1.0))
                continue
        if photos and rng.uniform() < 0.35:
            photo = photos[int(rng.integers(0, len(photos)))]
            image = _photo_poster(rng, photo, w_tex, h_tex)
        else:
            image = procedural_poster(rng, w_tex, h_tex)
        place(image, x, bottom_m)
        x += width_m + float(rng.uniform(0.15, 0.7))
    return wall


def visible_side_flip(scene: Scene) -> np.ndarray:
    """Tell, per wall segment, whether its texture runs from ``end`` to ``start``.

    The texture reads left to right as seen from the segment's free side: the
    inside of the perimeter and the outside of each obstacle.

    Returns:
        ``(s,)`` bool, True when ``u = length * (1 - s)`` along the segment.
    """
    flips = []
    for i, polygon in enumerate(scene.polygons()):
        area = 0.5 * np.sum(polygon[:, 0] * np.roll(polygon[:, 1], -1)
                            - np.roll(polygon[:, 0], -1) * polygon[:, 1])
        ccw = area > 0
        # Free side on the left of start->end: the viewer facing the wall reads
        # from end to start.
        free_on_left = ccw if i == 0 else not ccw
        flips.append(np.full(len(polygon), free_on_left))
    return np.concatenate(flips)


@dataclass
class WallAtlas:
    """Every wall's texture packed into one image, with a Gaussian mip pyramid.

    Attributes:
        levels: BGR ``uint8`` atlas images, level ``l`` halves level ``l - 1``.
        mip: every level stacked vertically in one image (one ``cv2.remap`` samples
            any level): level ``l`` starts at row ``mip_rows[l]``, column 0.
        mip_rows: ``(n_levels,)`` first row of each level in ``mip``.
        texels_per_metre: texture resolution at level 0.
        wall_height: height of the walls, metres (texture row 0 is the top).
        origins: ``(s, 2)`` level-0 texel coordinates ``(x, y)`` of each wall's
            top-left corner (arc length 0, top of the wall).
        lengths: ``(s,)`` wall lengths, metres.
        flip: ``(s,)`` texture direction per wall (see :func:`visible_side_flip`).
        extents: ``(s, 2)`` texel width and height of each wall's texture.
        gain: The light's global gain (the floor and ceiling follow it).
    """

    levels: list[np.ndarray]
    mip: np.ndarray
    mip_rows: np.ndarray
    texels_per_metre: float
    wall_height: float
    origins: np.ndarray
    lengths: np.ndarray
    flip: np.ndarray
    extents: np.ndarray
    gain: float = 1.0
    _gray: np.ndarray | None = field(default=None, repr=False)

    def gray_mip(self) -> np.ndarray:
        """Return :attr:`mip` converted to grey (cached)."""
        if self._gray is None:
            self._gray = cv2.cvtColor(self.mip, cv2.COLOR_BGR2GRAY)
        return self._gray


def build_wall_atlas(scene: Scene, texels_per_metre: float = 160.0,
                     n_levels: int = 6, appearance: Appearance | None = None) -> WallAtlas:
    """Build every wall's texture from ``scene.texture_seed`` and pack them.

    Args:
        scene: the scene; its ``texture_seed`` and each wall's index seed the wall.
        texels_per_metre: level-0 resolution (reduced automatically for very long walls).
        n_levels: number of pyramid levels.
        appearance: light and posters of the day (default: as explored).

    Returns:
        The atlas. Deterministic for a given scene and arguments.
    """
    starts, ends, _ = scene.wall_segments()
    lengths = np.linalg.norm(ends - starts, axis=1)
    align = 2 ** (n_levels - 1)
    pad = 2 * align
    tpm = float(texels_per_metre)
    longest = float(lengths.max())
    if longest * tpm + 2 * pad > _MAX_ATLAS - align:  # cv2.remap needs < 32767 texels
        tpm = (_MAX_ATLAS - align - 2 * pad) / longest
    flip = visible_side_flip(scene)
    # Unit normal towards the free side: the left normal when the free side is left.
    normals = np.stack([-(ends - starts)[:, 1], (ends - starts)[:, 0]], 1) / np.maximum(
        lengths[:, None], 1e-12)
    normals[~flip] *= -1.0
    appearance = appearance or Appearance()
    shades = appearance.shade(normals)
    textures = []
    for j in range(len(lengths)):
        rng = np.random.default_rng([scene.texture_seed, j])
        posters = np.random.default_rng([scene.texture_seed, j, appearance.seed]) \
            if j in appearance.rehung else None
        texture = _wall_texture(rng, float(lengths[j]), scene.wall_height, tpm, posters,
                                j in appearance.bare)
        textures.append(np.clip(texture.astype(np.float32) * float(shades[j]), 0, 255)
                        .astype(np.uint8))
    # Pack into strips: each wall padded (edge replicated) and aligned to `align`.
    tex_rows = textures[0].shape[0]
    strip_h = _round_up(tex_rows + 2 * pad, align)
    widths = [_round_up(t.shape[1] + 2 * pad, align) for t in textures]
    strip_w = max(_MAX_STRIP, max(widths))
    origins = np.zeros((len(textures), 2))
    strips: list[list[int]] = [[]]
    used = 0
    for j, w in enumerate(widths):
        if used + w > strip_w:
            strips.append([])
            used = 0
        origins[j] = (used + pad, (len(strips) - 1) * strip_h + pad)
        strips[-1].append(j)
        used += w
    atlas_w = strip_w if len(strips) > 1 else _round_up(used, align)
    atlas = np.zeros((strip_h * len(strips), atlas_w, 3), np.uint8)
    for j, texture in enumerate(textures):
        x0, y0 = int(origins[j, 0]) - pad, int(origins[j, 1]) - pad
        padded = cv2.copyMakeBorder(texture, pad, strip_h - tex_rows - pad, pad,
                                    widths[j] - texture.shape[1] - pad, cv2.BORDER_REPLICATE)
        atlas[y0:y0 + strip_h, x0:x0 + widths[j]] = padded
    levels = [atlas]
    for _ in range(1, n_levels):
        levels.append(cv2.pyrDown(levels[-1]))
    mip_rows = np.cumsum([0] + [level.shape[0] for level in levels[:-1]])
    mip = np.zeros((int(mip_rows[-1]) + levels[-1].shape[0], atlas_w, 3), np.uint8)
    for row, level in zip(mip_rows, levels):
        mip[row:row + level.shape[0], :level.shape[1]] = level
    extents = np.array([[t.shape[1], t.shape[0]] for t in textures], dtype=float)
    return WallAtlas(levels, mip, mip_rows, tpm, scene.wall_height, origins, lengths, flip,
                     extents, appearance.gain)


def _round_up(value: int, multiple: int) -> int:
    return -(-int(value) // multiple) * multiple

"""The scene points of a landmark database: a sparse 3-D map beside the regions.

The thesis localizes only inside a region (Sections 7.4, 7.5), and a region needs k
features visible from every pose of a neighbourhood. A camera that does not see all
around (a pinhole turned towards a near wall) has parts of its pose space where no such
k exist, yet the exploration saw plenty there: features visible from a few poses only,
which the filters of Section 6.2.2 rightly keep out of the decomposition. The builder
knows where each exploration image was taken, so every correspondence class whose
member rays meet (the geometric check of ``visibility_builder.verification``) has a
scene point. :class:`ScenePoints` keeps them, one descriptor each, so the localizer can
compute a pose from 2D-3D matches where no region serves (its tracked features keep the
points of the region's model views, which polished the tracked poses better).

Coordinates: ``(x, y)`` in ``map``, ``z`` from the exploration camera's height (the
convention of the verification and of the localizer's rays). ``class_ids`` names the
database class of a point, or -1 for a point the filters did not keep.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from landmark_db.database.fields import (
    ArrayEquality,
    descriptor_array,
    float_array,
    int_array,
    set_field,
)
from landmark_db.database.patch_codec import decode_patches, encode_patches
from landmark_db.errors import LandmarkDbError

__all__ = ['SEEN_MARGIN_M', 'ScenePoints']

#: A scene point can be found again from within its images' spread (``seen_from``) plus
#: this, metres: SIFT finds a feature at the scales it was seen at. The localizer
#: searches a point only from there, and an update replaces the points its images show
#: from there.
SEEN_MARGIN_M = 0.15


@dataclass(frozen=True, eq=False)
class ScenePoints(ArrayEquality):
    """Triangulated scene points, each with one descriptor.

    Attributes:
        xyz: ``(n, 3)`` float64 points (``z`` from the camera height), metres.
        class_ids: ``(n,)`` int64 database class of each point, -1 for none; a class
            has at most one point.
        descriptors: ``(n, 128)`` uint8 SIFT descriptor of each point (its member
            nearest the members' mean).
        views: ``(n,)`` int64 exploration images that saw the point (at least 2).
        seen_from: ``(n, 3)`` float64 where the exploration saw the point from: the
            centre ``(x, y)`` of its images' camera positions and the largest distance
            of one of them from that centre (metres); NaN rows where unknown (a schema 2
            file). The localizer searches a point only from near where it was seen
            (SIFT finds a feature at the scales it was seen at).
        patches: ``(n, s, s)`` uint8 (``s`` odd) the image around each point in one
            exploration image that saw it, centred on the point's reprojection there
            (schema 4; ``None`` in older files): the localizer aligns it in every
            tracked frame. Rows of points with no patch are zero.
        patch_axes: ``(n, 2, 3)`` float32 the 3-D offsets from the point, on the plane
            through it facing that exploration camera, that move its projection one
            pixel right and one pixel down in the patch; NaN rows where a point has no
            patch. With them a frame's pose predicts the patch's affine warp.
        patch_code: the patches of the points that have one, in order, as the file
            stores them (:mod:`.patch_codec`, schema 5), or None: stored whole.
            :attr:`patches` is then what the code decodes to (checked).
    """

    xyz: np.ndarray
    class_ids: np.ndarray
    descriptors: np.ndarray
    views: np.ndarray
    seen_from: np.ndarray | None = None
    patches: np.ndarray | None = None
    patch_axes: np.ndarray | None = None
    patch_code: bytes | None = None

    def __post_init__(self) -> None:
        xyz = float_array(self.xyz, 'scene points', (None, 3))
        n = len(xyz)
        class_ids = int_array(self.class_ids, 'scene point classes', (n,))
        descriptors = descriptor_array(self.descriptors, 'scene point descriptors')
        views = int_array(self.views, 'scene point views', (n,))
        seen_from = np.full((n, 3), np.nan) if self.seen_from is None else \
            np.asarray(self.seen_from, np.float64)
        if seen_from.shape != (n, 3):
            raise LandmarkDbError(f'scene point seen_from has shape {seen_from.shape}, '
                                  f'expected ({n}, 3)')
        known = np.all(np.isfinite(seen_from), axis=1)
        if not (known.all() or not known.any()) or (known.any() and seen_from[:, 2].min() < 0):
            raise LandmarkDbError('scene point seen_from must be known for every point or '
                                  'none, with radii >= 0')
        if len(descriptors) != n:
            raise LandmarkDbError(f'{len(descriptors)} scene point descriptors for {n} points')
        if class_ids.size and class_ids.min() < -1:
            raise LandmarkDbError(f'scene point class {int(class_ids.min())} is not a class '
                                  f'or -1')
        named = class_ids[class_ids >= 0]
        if np.unique(named).size != named.size:
            raise LandmarkDbError('a class has two scene points')
        if views.size and views.min() < 2:
            raise LandmarkDbError('a scene point is seen by fewer than 2 views')
        patches, axes = _patch_arrays(self.patches, self.patch_axes, n)
        for name, value in (('xyz', xyz), ('class_ids', class_ids),
                            ('descriptors', descriptors), ('views', views),
                            ('seen_from', seen_from), ('patches', patches),
                            ('patch_axes', axes)):
            set_field(self, name, value)
        if self.patch_code is not None:
            if not isinstance(self.patch_code, bytes):
                raise LandmarkDbError(f'scene point patch_code must be bytes, got '
                                      f'{type(self.patch_code).__name__}')
            mask = self.patch_mask
            if not mask.any() or not np.array_equal(decode_patches(
                    self.patch_code, int(mask.sum()), patches.shape[1]), patches[mask]):
                raise LandmarkDbError('scene point patches differ from what their code '
                                      'decodes to')

    def compact(self, jpeg_quality: int | None) -> ScenePoints:
        """Return the points as schema 5 stores them in the fewest bytes, exactly.

        Points rounded to float32 (micrometres within a kilometre); where they were
        seen from rounded to float16 as an offset from the point and a radius (at most
        16 mm off within 32 m of the point, against the 0.15 m margin it is searched
        with); patch axes to float16 (a 2**-11 relative error: a thousandth of a pixel
        across a patch); the patches coded as JPEG at ``jpeg_quality`` (None: kept
        whole).
        """
        xyz = self.xyz.astype(np.float32).astype(np.float64)
        seen = self.seen_from
        if self.has_seen_from:
            with np.errstate(over='ignore'):
                offset = (seen[:, :2] - xyz[:, :2]).astype(np.float16).astype(np.float64)
                radius = seen[:, 2].astype(np.float16).astype(np.float64)
            if np.isfinite(offset).all() and np.isfinite(radius).all():
                seen = np.column_stack([xyz[:, :2] + offset, radius])
            else:  # (beyond float16, 65 km: float32, absolute)
                seen = seen.astype(np.float32).astype(np.float64)
        if not self.has_patches:
            return replace(self, xyz=xyz, seen_from=seen, patch_code=None)
        axes = self.patch_axes.astype(np.float16).astype(np.float32)
        patches, code = self.patches, self.patch_code  # (coded once, never again)
        if jpeg_quality is not None and code is None:
            mask = self.patch_mask
            code = encode_patches(patches[mask], jpeg_quality)
            patches = patches.copy()
            patches[mask] = decode_patches(code, int(mask.sum()), patches.shape[1])
        return replace(self, xyz=xyz, seen_from=seen, patches=patches, patch_axes=axes,
                       patch_code=code)

    @property
    def has_patches(self) -> bool:
        """Whether some point has a patch (a schema 4 file, or a new build)."""
        return bool(self.n_points) and bool(self.patch_mask.any())

    @property
    def patch_mask(self) -> np.ndarray:
        """``(n,)`` bool: the points that have a patch."""
        return np.all(np.isfinite(self.patch_axes.reshape(-1, 6)), axis=1)

    @property
    def has_seen_from(self) -> bool:
        """Whether :attr:`seen_from` is known (a schema 3 file, or a new build)."""
        return bool(self.n_points) and bool(np.isfinite(self.seen_from).all())

    @property
    def n_points(self) -> int:
        """Number of points."""
        return int(len(self.xyz))

    @classmethod
    def empty(cls) -> ScenePoints:
        """No point (a database built without them)."""
        return cls(np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros((0, 128), np.uint8),
                   np.zeros(0, np.int64))

    def class_points(self, n_classes: int) -> np.ndarray:
        """``(n_classes, 3)`` the point of each class, NaN where it has none."""
        out = np.full((n_classes, 3), np.nan)
        named = self.class_ids >= 0
        ids = self.class_ids[named]
        if ids.size and ids.max() >= n_classes:
            raise LandmarkDbError(f'scene point class {int(ids.max())} out of range '
                                  f'(there are {n_classes} classes)')
        out[ids] = self.xyz[named]
        return out


def _patch_arrays(patches: np.ndarray | None, axes: np.ndarray | None, n: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Check the patches and their axes (both or neither); none gives empty patches."""
    if (patches is None) != (axes is None):
        raise LandmarkDbError('scene point patches and patch axes come together')
    if patches is None:
        out = np.zeros((n, 0, 0), np.uint8), np.full((n, 2, 3), np.nan, np.float32)
    else:
        array = np.asarray(patches)
        if array.ndim != 3 or len(array) != n or array.shape[1] != array.shape[2] or \
                (array.shape[1] and array.shape[1] % 2 == 0):
            raise LandmarkDbError(f'scene point patches have shape {array.shape}, expected '
                                  f'({n}, s, s) with s odd')
        if array.dtype != np.uint8:
            raise LandmarkDbError(f'scene point patches must be uint8, got {array.dtype}')
        offsets = np.asarray(axes, np.float32)
        if offsets.shape != (n, 2, 3):
            raise LandmarkDbError(f'scene point patch axes have shape {offsets.shape}, '
                                  f'expected ({n}, 2, 3)')
        known = np.isfinite(offsets.reshape(n, 6))
        if not np.all(known.all(axis=1) | ~known.any(axis=1)):
            raise LandmarkDbError('a scene point patch axis is partly unknown')
        out = np.array(array, np.uint8), np.array(offsets)
    for array in out:
        array.setflags(write=False)
    return out

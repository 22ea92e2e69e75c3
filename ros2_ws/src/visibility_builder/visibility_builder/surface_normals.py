"""The surface each scene point lies on, from its neighbouring points.

Not in the thesis. A scene point's patch is warped into a frame by an affine map that
its axes predict (:mod:`.point_patches`); the axes lie on a plane through the point.
Taking that plane to face the patch view's camera (fronto-parallel) mispredicts the
warp wherever the surface is seen obliquely, and a template of the wrong shape is
aligned a few tenths of a pixel off its centre, differently from each viewpoint: on the
pinhole room the points' mean residual at the true poses was 0.17 px (median over
points), as large as a measurement's own scatter, and the same points pulled poses the
same way frame after frame. Axes on the true walls (known to the renderer) took the
pinhole room's p95 from 0.32 / 0.33 / 0.25 cm to 0.20 / 0.28 / 0.21 cm over three seeds.

The points themselves say where the surface is: a point's neighbours within ``radius``
(at most :data:`NEIGHBOURS` of them) fix a plane when enough of them lie on one. The fit
is total least squares about the neighbours' centroid, started on the :data:`FIRST`
nearest (near a corner, mostly the point's own wall) and trimmed over all of them in
:data:`TRIM_M` steps down to ``tolerance``; the plane is the point's surface where at
least :data:`MIN_SHARE` of the neighbours lie on it, they span an area, not a line
(:data:`MIN_SPAN_M`), and it passes within ``POINT_FACTOR x tolerance`` of the point
itself (a plane of the other wall of a corner does not). A point on a curved or
cluttered surface, at a corner, or alone, has no normal, and its patch keeps the plane
facing its view. The room's points lie 2 mm (median) off their walls; 85 to 91 % of
the patched ones get a normal (panoramic, fisheye and pinhole rooms), median 0.3 degrees
and p90 0.8 to 1 degree off the true wall's.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ['FIRST', 'MIN_SHARE', 'MIN_SPAN_M', 'NEIGHBOURS', 'POINT_FACTOR', 'TRIM_M',
           'surface_normals']

#: Nearest neighbours a point's plane is fitted to, within the radius: the room's points
#: lie a few centimetres apart and a few millimetres off their wall, so that 16 span too
#: little to fix a plane's tilt (the pinhole room's patched points: 5 % get a normal
#: from 16, 36 % from 64, 70 % from 128, 91 % from 256, median 0.34 degrees off).
NEIGHBOURS = 256
#: The nearest neighbours the first plane is fitted to.
FIRST = 32
#: Least share of the neighbours on the plane: fewer is clutter, or a corner where the
#: point's own wall has too few of them.
MIN_SHARE = 0.5
#: Points whose neighbours are fitted at once (bounds the memory: ``CHUNK x NEIGHBOURS``).
CHUNK = 4096
#: The plane must pass within this many ``tolerance`` of the point.
POINT_FACTOR = 2.0
#: The fit's trimming: after a fit to all neighbours, those within each of these distances
#: of the plane (metres) are fitted again, then those within ``tolerance``.
TRIM_M = (0.05, 0.02)
#: The kept neighbours' spread along the plane's second axis (RMS, metres): less is a line
#: of points (an edge, a pole), which fixes no plane.
MIN_SPAN_M = 0.03


def surface_normals(points: np.ndarray, radius: float = 0.3, tolerance: float = 0.01,
                    min_support: int = 6) -> np.ndarray:
    """Return each point's unit surface normal from its neighbours (NaN: none fits).

    Args:
        points: ``(n, 3)`` the points (NaN rows are ignored).
        radius: neighbours farther than this (metres) are not used.
        tolerance: a neighbour farther than this from the plane (metres) is not on it.
        min_support: least neighbours (the point not counted) on the plane.

    Returns:
        ``(n, 3)`` unit normals, of either sign; NaN where no plane fits.

    Example:
        >>> grid = np.stack(np.meshgrid(np.arange(5) * 0.05, np.arange(5) * 0.05), -1)
        >>> wall = np.column_stack([np.full(25, 2.0), grid.reshape(-1, 2)])  # x = 2
        >>> np.round(np.abs(surface_normals(wall)[12]), 6).tolist()
        [1.0, 0.0, 0.0]
    """
    points = np.asarray(points, float).reshape(-1, 3)
    out = np.full((len(points), 3), np.nan)
    rows = np.flatnonzero(np.all(np.isfinite(points), axis=1))
    if len(rows) <= min_support:
        return out
    xyz = points[rows]
    tree = cKDTree(xyz)
    k = min(NEIGHBOURS + 1, len(xyz))
    for first in range(0, len(xyz), CHUNK):
        these = np.arange(first, min(first + CHUNK, len(xyz)))
        distance, near = tree.query(xyz[these], k=k, distance_upper_bound=radius)
        valid = np.isfinite(distance[:, 1:])           # the point itself is first
        neighbours = xyz[np.where(valid, near[:, 1:], 0)]
        normal, centre, support, span = _fit(neighbours, valid, tolerance)
        # The plane must pass near the point itself: one fitted to the other wall of a
        # corner does not (nor one that a point far off its surface would get).
        near_plane = np.abs(np.einsum('ni,ni->n', xyz[these] - centre, normal)) <= \
            POINT_FACTOR * tolerance
        ok = (support >= np.maximum(min_support, MIN_SHARE * valid.sum(axis=1))) & \
            (span >= MIN_SPAN_M) & near_plane
        out[rows[these[ok]]] = normal[ok]
    return out


def _fit(neighbours: np.ndarray, valid: np.ndarray, tolerance: float
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fit the trimmed plane of each point's neighbours ``(c, k, 3)`` (``valid`` ``(c, k)``).

    Returns ``(normal (c, 3), centre (c, 3), support (c,), span (c,))``: the plane's unit
    normal and centroid, the neighbours on it and their RMS spread along its second axis.
    """
    # The first plane is the nearest neighbours' (near a corner, mostly the point's own
    # wall), then trimmed over all of them.
    weight = (valid & (np.arange(valid.shape[1]) < FIRST)).astype(float)
    for limit in (*TRIM_M, tolerance, None):
        support = weight.sum(axis=1)
        centre = (weight[:, None, :] @ neighbours)[:, 0] / np.maximum(support, 1.0)[:, None]
        offsets = neighbours - centre[:, None]
        values, vectors = np.linalg.eigh(
            (offsets * weight[..., None]).transpose(0, 2, 1) @ offsets)
        normal = vectors[:, :, 0]
        if limit is not None:
            weight = (valid & (np.abs(offsets @ normal[:, :, None])[..., 0] <= limit)
                      ).astype(float)
    span = np.sqrt(np.maximum(values[:, 1], 0.0) / np.maximum(support, 1.0))
    return normal, centre, support, span

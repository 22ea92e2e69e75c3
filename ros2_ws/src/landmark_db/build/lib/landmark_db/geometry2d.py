"""Planar segment geometry shared by the simulator, the scene and the renderer's synthesis.

Every function works on numpy arrays of 2-D points, broadcast or batched, and has
one home here: the Chapter 8 simulator (pose grid, obstacle placement, visibility),
:class:`~landmark_db.scene.Scene` (distance to the walls) and
``visibility_builder``'s bag synthesis (exploration grid, run trajectories) all
import them from this module.

Two crossing predicates exist on purpose, with different boundary rules:

- :func:`segments_cross`: a *proper* crossing, strictly inside both segments
  (touching or collinear segments do not cross); used for polygon clearances;
- :func:`segments_blocked`: a sight line blocked by a wall, strictly inside the
  sight line and anywhere on the wall including its end points (a line through an
  obstacle's corner is blocked); used for visibility and pose-graph edges.
"""
from __future__ import annotations

import numpy as np

__all__ = [
    'nearest_segment_distance',
    'point_segment_distance',
    'segment_distance',
    'segments_blocked',
    'segments_cross',
]

_POINT_CHUNK = 20_000  # points per chunk of nearest_segment_distance
_PAIR_CHUNK_CELLS = 8_000_000  # segments x walls per chunk of segments_blocked
_T_EPS = 1e-9


def point_segment_distance(points: np.ndarray, starts: np.ndarray,
                           ends: np.ndarray) -> np.ndarray:
    """Return the distance from points to segments, broadcast over leading axes.

    Args:
        points: ``(..., 2)`` points.
        starts: ``(..., 2)`` segment start points.
        ends: ``(..., 2)`` segment end points (a zero-length segment is its point).

    Returns:
        ``(...)`` distances, the broadcast shape of the three arguments without the
        last axis. For example ``points[:, None]`` against ``(s, 2)`` segments gives
        ``(n, s)``.
    """
    points = np.asarray(points, dtype=float)
    starts = np.asarray(starts, dtype=float)
    d = np.asarray(ends, dtype=float) - starts
    t = np.clip(np.sum((points - starts) * d, axis=-1)
                / np.maximum(np.sum(d * d, axis=-1), 1e-300), 0.0, 1.0)
    return np.linalg.norm(points - (starts + t[..., None] * d), axis=-1)


def nearest_segment_distance(points: np.ndarray, starts: np.ndarray,
                             ends: np.ndarray) -> np.ndarray:
    """Return each point's distance to the nearest of a set of segments.

    Args:
        points: ``(n, 2)`` points.
        starts: ``(s, 2)`` segment start points.
        ends: ``(s, 2)`` segment end points.

    Returns:
        ``(n,)`` distances (``inf`` when there is no segment).
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    out = np.full(points.shape[0], np.inf)
    if len(starts) == 0:
        return out
    for lo in range(0, points.shape[0], _POINT_CHUNK):
        chunk = points[lo:lo + _POINT_CHUNK, None, :]
        out[lo:lo + _POINT_CHUNK] = point_segment_distance(chunk, starts, ends).min(axis=1)
    return out


def segments_cross(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray,
                   b1: np.ndarray) -> np.ndarray:
    """Tell whether segments ``a0-a1`` and ``b0-b1`` cross properly (broadcast).

    Args:
        a0: ``(..., 2)`` first segments' start points.
        a1: ``(..., 2)`` first segments' end points.
        b0: ``(..., 2)`` second segments' start points.
        b1: ``(..., 2)`` second segments' end points.

    Returns:
        ``(...)`` bool, True where each segment's end points lie strictly on opposite
        sides of the other's line (touching and collinear segments give False).
    """
    def cross(o: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        return ((p[..., 0] - o[..., 0]) * (q[..., 1] - o[..., 1])
                - (p[..., 1] - o[..., 1]) * (q[..., 0] - o[..., 0]))

    a0, a1, b0, b1 = (np.asarray(v, dtype=float) for v in (a0, a1, b0, b1))
    d1 = cross(b0, b1, a0)
    d2 = cross(b0, b1, a1)
    d3 = cross(a0, a1, b0)
    d4 = cross(a0, a1, b1)
    return (d1 * d2 < 0) & (d3 * d4 < 0)


def segment_distance(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray,
                     b1: np.ndarray) -> np.ndarray:
    """Return the distance between segments ``a0-a1`` and ``b0-b1`` (broadcast).

    Args:
        a0: ``(..., 2)`` first segments' start points.
        a1: ``(..., 2)`` first segments' end points.
        b0: ``(..., 2)`` second segments' start points.
        b1: ``(..., 2)`` second segments' end points.

    Returns:
        ``(...)`` distances; 0 for segments that cross (:func:`segments_cross`).
    """
    dist = np.minimum.reduce([point_segment_distance(a0, b0, b1),
                              point_segment_distance(a1, b0, b1),
                              point_segment_distance(b0, a0, a1),
                              point_segment_distance(b1, a0, a1)])
    return np.where(segments_cross(a0, a1, b0, b1), 0.0, dist)


def segments_blocked(p: np.ndarray, q: np.ndarray, wall_starts: np.ndarray,
                     wall_ends: np.ndarray, skip_wall: np.ndarray | None = None) -> np.ndarray:
    """Tell which segments ``p[i] -> q[i]`` cross any wall segment.

    A crossing counts when it lies strictly between the segment's end points and
    anywhere on the wall, end points included.

    Args:
        p: ``(n, 2)`` segment starts.
        q: ``(n, 2)`` segment ends.
        wall_starts: ``(w, 2)`` wall segment starts.
        wall_ends: ``(w, 2)`` wall segment ends.
        skip_wall: optional ``(n,)`` wall index to ignore for each segment (the wall
            a feature lies on), or -1.

    Returns:
        ``(n,)`` bool, True where the segment is blocked.
    """
    p = np.asarray(p, dtype=float).reshape(-1, 2)
    q = np.asarray(q, dtype=float).reshape(-1, 2)
    n, w = p.shape[0], wall_starts.shape[0]
    blocked = np.zeros(n, dtype=bool)
    if n == 0 or w == 0:
        return blocked
    s = wall_ends - wall_starts  # (w, 2)
    step = max(1, _PAIR_CHUNK_CELLS // w)
    wall_index = np.arange(w)
    for lo in range(0, n, step):
        a = p[lo:lo + step]
        r = q[lo:lo + step] - a  # (c, 2)
        ax = wall_starts[None, :, 0] - a[:, None, 0]  # (c, w)
        ay = wall_starts[None, :, 1] - a[:, None, 1]
        denom = r[:, None, 0] * s[None, :, 1] - r[:, None, 1] * s[None, :, 0]
        t_num = ax * s[None, :, 1] - ay * s[None, :, 0]
        u_num = ax * r[:, None, 1] - ay * r[:, None, 0]
        # Divide-free form of 0 < t < 1 and 0 <= u <= 1, valid for either sign of denom.
        sign = np.sign(denom)
        abs_denom = np.abs(denom)
        t_s = t_num * sign
        u_s = u_num * sign
        hit = ((abs_denom > 1e-12) & (t_s > _T_EPS * abs_denom)
               & (t_s < (1 - _T_EPS) * abs_denom) & (u_s >= -1e-12 * abs_denom)
               & (u_s <= (1 + 1e-12) * abs_denom))
        if skip_wall is not None:
            hit &= wall_index[None, :] != skip_wall[lo:lo + step, None]
        blocked[lo:lo + step] = hit.any(axis=1)
    return blocked

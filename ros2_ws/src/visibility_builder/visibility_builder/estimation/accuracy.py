"""Estimated image poses judged against the ground truth, after an SE(2) alignment.

Estimated poses live in a frame of their own (the odometry's at the first image), so
they are compared with the truth as evo and SfM benchmarks compare trajectories: the
rigid planar motion that best maps the estimated positions onto the true ones (Umeyama
without scale, least squares) is applied first.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vbn_common.geometry.frames import wrap_angle

__all__ = ['PoseErrors', 'align_se2', 'centre_errors_sim3', 'pose_errors', 'similarity_scale']


@dataclass(frozen=True)
class PoseErrors:
    """Errors of estimated poses against the truth (metres, degrees)."""

    count: int
    position_median: float
    position_p95: float
    position_max: float
    heading_median_deg: float
    heading_max_deg: float

    def line(self) -> str:
        """Return the figures as one line."""
        return (f'{self.count} poses: position median {100 * self.position_median:.2f} cm, '
                f'p95 {100 * self.position_p95:.2f} cm, max {100 * self.position_max:.2f} cm;'
                f' heading median {self.heading_median_deg:.3f} deg, max '
                f'{self.heading_max_deg:.3f} deg')


def _umeyama(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    """Rotation, scale and the two means that best map the points ``a`` onto ``b``.

    Umeyama's least squares over ``(n, d)`` finite rows: ``b ~ scale R (a - ma) + mb``.
    """
    ma, mb = a.mean(axis=0), b.mean(axis=0)
    u, singular, vt = np.linalg.svd((a - ma).T @ (b - mb))
    d = np.ones(a.shape[1])
    d[-1] = np.sign(np.linalg.det(vt.T @ u.T))
    rotation = vt.T @ np.diag(d) @ u.T
    return rotation, float(np.sum(singular * d) / np.sum((a - ma) ** 2)), ma, mb


def _finite_rows(estimate: np.ndarray, truth: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    estimate = np.asarray(estimate, float)
    truth = np.asarray(truth, float)
    return estimate, truth, np.isfinite(estimate).all(axis=1) & np.isfinite(truth).all(axis=1)


def align_se2(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Return ``estimate`` (n, 3) moved by the planar rigid motion that best fits ``truth``.

    Rows with NaN in either are ignored for the fit and stay NaN.
    """
    estimate, truth, ok = _finite_rows(estimate, truth)
    out = np.full_like(estimate, np.nan)
    if ok.sum() < 2:
        return out
    r, _, ma, mb = _umeyama(estimate[ok, :2], truth[ok, :2])
    angle = float(np.arctan2(r[1, 0], r[0, 0]))
    good = np.isfinite(estimate).all(axis=1)
    out[good, :2] = (estimate[good, :2] - ma) @ r.T + mb
    out[good, 2] = wrap_angle(estimate[good, 2] + angle)
    return out


def pose_errors(estimate: np.ndarray, truth: np.ndarray, align: bool = True) -> PoseErrors:
    """Position and heading errors of ``estimate`` against ``truth`` (aligned first)."""
    moved = align_se2(estimate, truth) if align else np.asarray(estimate, float)
    ok = np.isfinite(moved).all(axis=1) & np.isfinite(truth).all(axis=1)
    if not ok.any():
        nan = float('nan')
        return PoseErrors(0, nan, nan, nan, nan, nan)
    position = np.linalg.norm(moved[ok, :2] - truth[ok, :2], axis=1)
    heading = np.degrees(np.abs(wrap_angle(moved[ok, 2] - truth[ok, 2])))
    return PoseErrors(int(ok.sum()), float(np.median(position)),
                      float(np.percentile(position, 95)), float(position.max()),
                      float(np.median(heading)), float(heading.max()))


def similarity_scale(estimate: np.ndarray, truth: np.ndarray) -> float:
    """Return the scale of the similarity that best maps ``estimate`` onto ``truth``.

    One when the estimate has the true scale; ``1.002`` when it came out 0.2 % small
    (Umeyama's scale over the planar positions finite in both; NaN with fewer than two).
    """
    estimate, truth, ok = _finite_rows(estimate, truth)
    if ok.sum() < 2:
        return float('nan')
    return _umeyama(estimate[ok, :2], truth[ok, :2])[1]


def centre_errors_sim3(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Return the distances of ``estimate``'s 3-D points from ``truth``'s after a similarity.

    Umeyama's rotation, translation and scale over the rows finite in both; the other
    rows NaN. For structure from motion without a known length (its scale is free).
    """
    estimate, truth, ok = _finite_rows(estimate, truth)
    out = np.full(len(estimate), np.nan)
    if ok.sum() < 3:
        return out
    r, scale, ma, mb = _umeyama(estimate[ok], truth[ok])
    out[ok] = np.linalg.norm(scale * (estimate[ok] - ma) @ r.T + mb - truth[ok], axis=1)
    return out

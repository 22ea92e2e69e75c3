"""Integrity of a run: whether the published covariance bounds the error.

A navigation stack survives a localizer that says "I am lost"; it does not survive one
that claims centimetres while it is most of a metre off. Per run, against the ground
truth:

- **posed**: the share of frames with a pose;
- **accuracy**: translation median and p95, heading median, and the poses more than
  :data:`FAR_M` off (a "confident wrong pose");
- **within 3 sigma**: the share of poses whose position error lies inside the 3-sigma
  ellipse of its covariance (squared Mahalanobis distance at most
  :data:`CHI2_2DOF_3SIGMA`, the 2-DoF chi-square quantile of 99.73 %) and whose heading
  error is within 3 of its standard deviations; the target is at least
  :data:`INTEGRITY_SHARE` over every run;
- **start-up**: frames from the first until the first correct pose (within
  :data:`CORRECT_M`), with no initial pose given;
- **recovery**: after each teleport of a kidnapped run, frames until a correct pose
  (:func:`~vbn_bench.localization.evaluation.recovery_frames`).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
import math
from typing import Any

import numpy as np

from vbn_bench.localization.evaluation import associate, find_teleports, recovery_frames
from vbn_common.geometry.frames import wrap_angle

__all__ = ['CHI2_2DOF_3SIGMA', 'CORRECT_M', 'FAR_M', 'INTEGRITY_SHARE', 'IntegrityFigures',
           'integrity_figures']

#: The 99.73 % quantile of the chi-square distribution with two degrees of freedom.
CHI2_2DOF_3SIGMA = -2.0 * math.log(1.0 - 0.9973)
#: A pose this far off is a confident wrong pose, metres.
FAR_M = 0.5
#: A pose within this of the truth is correct (start-up, recovery), metres.
CORRECT_M = 0.05
#: The share of poses within their 3-sigma bounds the targets ask for.
INTEGRITY_SHARE = 0.99


@dataclass(frozen=True)
class IntegrityFigures:
    """One run's integrity (module docstring).

    Attributes:
        frames: Frames of the run.
        poses: Frames with a pose (and a ground truth to judge it).
        posed: ``poses / frames``.
        median_m: Translation error median, metres (NaN without poses).
        p95_m: ... 95th percentile.
        heading_median_deg: Heading error median, degrees.
        far: Poses more than :data:`FAR_M` off.
        within_position: Share of poses inside their 3-sigma position ellipse.
        within_heading: Share within 3 sigma in heading.
        within: Share within both.
        worst_far_sigma_m: The largest standard deviation claimed by a pose more than
            :data:`FAR_M` off (NaN: none such).
        startup_frames: Frames until the first correct pose (None: never).
        recovery: Per teleport, frames until a correct pose (None: never).
    """

    frames: int
    poses: int
    posed: float
    median_m: float
    p95_m: float
    heading_median_deg: float
    far: int
    within_position: float
    within_heading: float
    within: float
    worst_far_sigma_m: float
    startup_frames: int | None
    recovery: list[int | None] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        """Return the figures as a JSON-ready dict."""
        return asdict(self)


def integrity_figures(frame_stamps_ns: np.ndarray, poses: np.ndarray,
                      covariances: np.ndarray, truth_stamps_ns: np.ndarray,
                      truth_poses: np.ndarray) -> IntegrityFigures:
    """Return a run's integrity figures.

    Args:
        frame_stamps_ns: (n,) every frame's stamp, sorted.
        poses: (n, 3) each frame's ``base_link`` pose, NaN rows where none.
        covariances: (n, 3, 3) their covariances of ``(x, y, yaw)`` (ignored where no
            pose).
        truth_stamps_ns: (m,) sorted ground-truth stamps.
        truth_poses: (m, 3) the ground truth.

    Example:
        >>> stamps = np.arange(3)
        >>> poses = np.array([[np.nan] * 3, [1.0, 0.0, 0.0], [2.6, 0.0, 0.0]])
        >>> cov = np.tile(np.diag([1e-4, 1e-4, 1e-4]), (3, 1, 1))
        >>> truth = np.array([[0.0, 0.0, 0.0], [1.01, 0.0, 0.0], [2.0, 0.0, 0.0]])
        >>> f = integrity_figures(stamps, poses, cov, stamps, truth)
        >>> f.poses, f.far, f.within, f.startup_frames
        (2, 1, 0.5, 2)
    """
    stamps = np.asarray(frame_stamps_ns, np.int64)
    poses = np.asarray(poses, float).reshape(-1, 3)
    covariances = np.asarray(covariances, float).reshape(-1, 3, 3)
    truth_stamps_ns = np.asarray(truth_stamps_ns, np.int64)
    truth_poses = np.asarray(truth_poses, float).reshape(-1, 3)
    rows, truth_rows = associate(stamps, truth_stamps_ns)
    has = np.isfinite(poses[rows]).all(axis=1)
    rows, truth_rows = rows[has], truth_rows[has]
    diff = poses[rows, :2] - truth_poses[truth_rows, :2]
    heading = np.abs(wrap_angle(poses[rows, 2] - truth_poses[truth_rows, 2]))
    error = np.linalg.norm(diff, axis=1)
    cov = covariances[rows]
    ok_cov = np.isfinite(cov).all(axis=(1, 2)) & (np.linalg.det(cov[:, :2, :2]) > 0) & \
        (cov[:, 2, 2] > 0)
    mahalanobis = np.full(len(rows), np.inf)
    heading_z = np.full(len(rows), np.inf)
    if ok_cov.any():
        mahalanobis[ok_cov] = np.einsum('ni,nij,nj->n', diff[ok_cov],
                                        np.linalg.inv(cov[ok_cov, :2, :2]), diff[ok_cov])
        heading_z[ok_cov] = heading[ok_cov] / np.sqrt(cov[ok_cov, 2, 2])
    inside = mahalanobis <= CHI2_2DOF_3SIGMA
    inside_heading = heading_z <= 3.0
    far = error > FAR_M
    sigma = np.sqrt(np.maximum(cov[:, 0, 0], cov[:, 1, 1]))

    def share(mask: np.ndarray) -> float:
        return float(mask.mean()) if len(mask) else math.nan

    correct = np.flatnonzero(error <= CORRECT_M)
    startup = int(rows[correct[0]]) + 1 if len(correct) else None
    recovery = [recovery_frames(stamps, poses, truth_stamps_ns, truth_poses,
                                int(truth_stamps_ns[k]), CORRECT_M)
                for k in find_teleports(truth_stamps_ns, truth_poses)]
    return IntegrityFigures(
        frames=len(stamps), poses=len(rows), posed=len(rows) / max(len(stamps), 1),
        median_m=float(np.median(error)) if len(error) else math.nan,
        p95_m=float(np.percentile(error, 95)) if len(error) else math.nan,
        heading_median_deg=math.degrees(float(np.median(heading))) if len(heading)
        else math.nan,
        far=int(far.sum()), within_position=share(inside), within_heading=share(inside_heading),
        within=share(inside & inside_heading),
        worst_far_sigma_m=float(sigma[far].max()) if far.any() else math.nan,
        startup_frames=startup, recovery=recovery)

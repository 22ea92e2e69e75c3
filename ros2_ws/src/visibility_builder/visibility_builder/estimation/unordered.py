"""Poses of unordered photographs from a hand-held camera (thesis 6.1, the general path).

A robot's exploration comes with odometry and a floor (:mod:`.pipeline`); a set of
photographs taken by hand has neither: the motion between views is general (six degrees
of freedom), nothing orders the views, and nothing gives the scale. This is the thesis's
Section 6.1 as written for that case:

1. SIFT of every image (``precise_upscale``), every pair of images matched
   (Algorithm 6.1: pairs with at least ``min_matches`` mutual matches), its motion by
   the essential matrix (:func:`~vbn_common.geometry.essential.general_essential`).
2. Rotations (6.1.3, :func:`~.rotations.fit_rotations`: the heaviest spanning tree,
   then Gauss-Newton on the spheres); pairs missing the tree's guess, then the fit, by
   more than four of their own and four robust standard deviations are dropped and the
   fit repeated.
3. Positions (6.1.4, :func:`~.positions.fit_positions`): the null vector of the
   directions' system in three dimensions, at unit scale.
4. Beyond the thesis: bundle adjustment over the pairs' tracks
   (:func:`~.refinement.refine_general`).

The result is up to a similarity (no odometry, no known distance): it is judged after a
similarity alignment, as structure-from-motion benchmarks judge theirs.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math
import time

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from vbn_common.features import ImageFeatures
from vbn_common.geometry.camera import CameraModel
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.estimation.positions import fit_positions
from visibility_builder.estimation.refinement import refine_general, tracks_from_pairs
from visibility_builder.estimation.rotations import (
    far_misses,
    fit_rotations,
    matrix_to_quat,
    pair_misses,
    quat_to_matrix,
)
from visibility_builder.estimation.view_pairs import PairMotion, PairSettings, measure_pair

__all__ = ['UnorderedEstimate', 'estimate_unordered']


@dataclass
class UnorderedEstimate:
    """Camera poses of unordered images, up to a similarity.

    Attributes:
        rotations: ``(n, 3, 3)`` each camera's planar frame (REP 103 axes of the
            camera: ``x`` along the optical axis, ``z`` up in the image) into the world.
        thesis_centres: ``(n, 3)`` camera centres by 6.1.3 and 6.1.4 alone (NaN where
            no pair reaches).
        centres: ``(n, 3)`` after the bundle adjustment (or the thesis's without it).
        pairs: The measured pairs.
        kept_rotation: ``(len(pairs),)`` bool.
        kept_direction: ``(len(pairs),)`` bool.
        refused: Pairs refused, by reason.
        times: Seconds per step.
        observations: Observations in the bundle adjustment (0 without it).
        rms_px: Their final RMS reprojection error.
    """

    rotations: np.ndarray
    thesis_centres: np.ndarray
    centres: np.ndarray
    pairs: list[PairMotion]
    kept_rotation: np.ndarray
    kept_direction: np.ndarray
    refused: dict[str, int] = field(default_factory=dict)
    times: dict[str, float] = field(default_factory=dict)
    observations: int = 0
    rms_px: float = math.nan


def estimate_unordered(features: list[ImageFeatures], camera: CameraModel,
                       settings: PairSettings | None = None, refine: bool = True,
                       max_rotation_error_deg: float = 0.5) -> UnorderedEstimate:
    """Estimate the poses of unordered images of one camera (module docstring).

    Args:
        features: Every image's SIFT features.
        camera: The camera (one for all images).
        settings: Pair settings (default: the essential-matrix solver).
        refine: Bundle-adjust the result.
        max_rotation_error_deg: Pairs within this of the rotation fit are never dropped.

    Returns:
        The estimate.

    Raises:
        VisibilityBuilderError: fewer than two images or no pair that overlaps.
    """
    n = len(features)
    if n < 2:
        raise VisibilityBuilderError(f'{n} image(s): pose estimation needs at least two')
    settings = settings or PairSettings(method='general_essential')
    times: dict[str, float] = {}
    refused: dict[str, int] = {}
    t = time.perf_counter()
    pairs: list[PairMotion] = []
    for i in range(n):
        for j in range(i + 1, n):
            motion, why = measure_pair(i, j, features[i], features[j], camera, settings,
                                       moved=True)
            if motion is None:
                key = why.split(':')[0] if ':' in why else why.split(' ', 1)[-1]
                refused[key] = refused.get(key, 0) + 1
            elif np.isfinite(motion.rotation_std) and motion.has_direction:
                pairs.append(motion)
    times['pairs'] = time.perf_counter() - t
    if not pairs:
        raise VisibilityBuilderError('no two images overlap: no pair of images has '
                                     f'{settings.min_matches} matches that one motion explains')
    t = time.perf_counter()
    ij = np.array([(p.i, p.j) for p in pairs], np.int64)
    rel = np.array([matrix_to_quat(p.rotation) for p in pairs])
    std = np.array([p.rotation_std for p in pairs])
    kept = np.ones(len(pairs), bool)
    # The heaviest spanning tree's guess judges the pairs first: a least-squares fit
    # over every pair is pulled by the wrong ones, and judged against it the right pairs
    # of the views it pulled look wrong (the fountain's last two views lost every pair).
    # The anchor: a view of the largest group the pairs join (one stray photograph must
    # not be the reference of the rest).
    _, group = connected_components(coo_matrix((np.ones(len(ij)), (ij[:, 0], ij[:, 1])),
                                               shape=(n, n)), directed=False)
    anchor = int(np.flatnonzero(group == np.argmax(np.bincount(group)))[0])
    guess = fit_rotations(n, ij, rel, 1.0 / std ** 2, anchor=anchor, iterations=0)
    for iteration in range(8):
        if iteration:
            fit = fit_rotations(n, ij[kept], rel[kept], 1.0 / std[kept] ** 2, anchor=anchor)
        else:
            fit = guess
        q = fit.quaternions
        bad = far_misses(pair_misses(q, ij, rel), std, kept, math.radians(max_rotation_error_deg))
        if not bad.any() and iteration:
            break               # the least squares ran and dropped nothing more
        kept &= ~bad
    to_world = np.transpose(quat_to_matrix(q), (0, 2, 1))        # camera i into world
    times['rotations'] = time.perf_counter() - t
    t = time.perf_counter()
    use = kept & np.isfinite(q[ij[:, 0]]).all(axis=1) & np.isfinite(q[ij[:, 1]]).all(axis=1)
    idx = np.flatnonzero(use)
    if not len(idx):
        raise VisibilityBuilderError('no pair of images kept a direction: the views cannot be '
                                     'placed')
    dirs = np.array([to_world[pairs[k].i] @ pairs[k].direction for k in idx]).reshape(-1, 3)
    dstd = np.array([pairs[k].direction_std for k in idx])
    positions = fit_positions(n, ij[idx], dirs, 1.0 / np.maximum(dstd, 1e-4) ** 2,
                              anchor=anchor)
    kept_direction = np.zeros(len(pairs), bool)
    kept_direction[idx[positions.kept]] = True
    thesis = positions.positions
    times['positions'] = time.perf_counter() - t
    centres = thesis.copy()
    observations, rms = 0, math.nan
    solved = np.isfinite(thesis).all(axis=1) & np.isfinite(q).all(axis=1)
    if refine and solved.sum() >= 2:
        t = time.perf_counter()
        chosen = [pairs[k] for k in np.flatnonzero(kept_direction)
                  if solved[pairs[k].i] and solved[pairs[k].j]]
        rows, _ = tracks_from_pairs([len(f) for f in features],
                                    np.array([(p.i, p.j) for p in chosen], np.int64),
                                    [p.features for p in chosen])
        if len(rows):
            rows = rows[np.argsort(rows[:, 1], kind='stable')]      # image by image
            uv = np.concatenate([features[i].keypoints[rows[rows[:, 1] == i, 2]]
                                 for i in range(n)]).astype(float)
            refined = refine_general(to_world, thesis, rows[:, :2], uv, camera, solved)
            centres = np.where(solved[:, None], refined.centres, np.nan)
            to_world = np.where(solved[:, None, None], refined.rotations, to_world)
            observations, rms = refined.observations, refined.rms_px
        times['refine'] = time.perf_counter() - t
    return UnorderedEstimate(to_world, thesis, centres, pairs, kept, kept_direction, refused,
                             times, observations, rms)

"""The views' rotations, then their positions, from the measured pairs (thesis 6.1.3, 6.1.4).

:func:`fit_views` is steps 4, 5 and 7 of :mod:`.pipeline`:

- **Rotations** (6.1.3, :mod:`.rotations`) over the pairs' relative rotations and the
  odometry's turns between consecutive images (weighted by their own uncertainty, so
  that views no pair joins stay connected). For a planar robot the least-absolute
  angles (:func:`~.rotations.planar_l1_angles`) start the fit and the pairs they leave
  far off are dropped first; then pairs missing the fit by more than four of their
  standard deviations and four robust standard deviations of all pairs' misses are
  dropped and the fit repeated.
- **Bearings** refitted under the fitted turns (:func:`~.view_pairs.bearings_given_turns`,
  planar pairs), carried into the world by the fitted rotations.
- **Positions** (6.1.4, :mod:`.positions`) over stations: the thesis's directions alone
  (null vector, scaled by the odometry's path length); the linear joint system of
  directions and odometry displacements (which reaches views the directions leave
  free); and the robust non-linear fit of the bearings and the odometry seeded by one
  of them (in the plane: the robot is on a floor, whether or not its camera tilts)
  (:func:`~.positions.refine_planar_positions`: the linear fits' shrinkage removed).
  The last is the estimate (``camera``), the first is reported beside it (``thesis``).
"""
from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from vbn_common.features import ImageFeatures
from vbn_common.geometry.frames import compose_poses, wrap_angle
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.estimation.odometry_path import step_stds, straight_steps
from visibility_builder.estimation.positions import fit_positions, refine_planar_positions
from visibility_builder.estimation.rotations import (
    far_misses,
    fit_rotations,
    matrix_to_quat,
    pair_misses,
    planar_l1_angles,
    quat_from_yaw,
    quat_to_matrix,
    quat_yaw,
)
from visibility_builder.estimation.view_pairs import (
    PairMotion,
    PairSettings,
    bearings_given_turns,
)

if TYPE_CHECKING:
    from visibility_builder.estimation.pipeline import EstimationSettings

__all__ = ['TILT_STD', 'fit_views']

#: How far a shaking camera's views tilt from level, radians (the odometry's turns and the
#: bundle adjustment's planar priors allow this much pitch and roll).
TILT_STD = 0.03

_LOG = logging.getLogger(__name__)


def fit_views(n: int, station: np.ndarray, odom_base: np.ndarray, mount: np.ndarray,
         measured: dict[tuple[int, int], PairMotion], settings: EstimationSettings,
         refit: tuple[list[ImageFeatures], object, PairSettings] | None = None,
         steps: np.ndarray | None = None) -> dict[str, object]:
    """Rotations, then positions (with and without odometry), in the ``map`` frame.

    ``refit``: ``(features, camera, pair settings)`` to refit each pair's bearing under
    the fitted rotations (planar pairs), or None to take the pairs' own. ``steps``:
    ``(n - 1, 2)`` path length and turning between consecutive images
    (:func:`~.odometry_path.odometry_steps`; None: the straight lines).
    """
    pairs = list(measured.values())
    odom_cam = np.array([compose_poses(p, mount) for p in odom_base])
    # -- rotations (6.1.3): image pairs plus the odometry's turns ---------------------------
    ij = np.array([(p.i, p.j) for p in pairs], np.int64).reshape(-1, 2)
    rel = np.array([matrix_to_quat(p.rotation) for p in pairs]).reshape(-1, 4)
    w = np.array([1.0 / p.rotation_std ** 2 for p in pairs])
    turn = wrap_angle(np.diff(odom_cam[:, 2]))
    if steps is None:
        steps = straight_steps(odom_base)
    _, odo_std = step_stds(steps, settings)
    odo_ij = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    odo_rel = quat_from_yaw(-turn)             # camera i's planar frame into i+1's
    std = np.array([p.rotation_std for p in pairs])
    kept = np.ones(len(pairs), bool)
    floor = math.radians(settings.max_rotation_error_deg)
    guess = None
    general = any(p.method == 'general_essential' for p in pairs)
    if general:
        # A shaking camera: the odometry's turn says nothing of the views' tilts.
        odo_std = np.maximum(odo_std, TILT_STD)
        tree = fit_rotations(n, np.concatenate([ij, odo_ij]), np.concatenate([rel, odo_rel]),
                             np.concatenate([w, 1.0 / odo_std ** 2]), anchor=0, iterations=0)
        if len(pairs):
            # Judged against the heaviest tree first (see unordered.py).
            kept = ~far_misses(pair_misses(tree.quaternions, ij, rel), std, kept, floor)
    else:
        # A planar robot: the robust (L1) angles start the fit, their far misses dropped.
        start = np.concatenate([[0.0], np.cumsum(quat_yaw(odo_rel))])
        angles = planar_l1_angles(n, np.concatenate([ij, odo_ij]),
                                  np.concatenate([quat_yaw(rel), quat_yaw(odo_rel)]),
                                  np.sqrt(np.concatenate([w, 1.0 / odo_std ** 2])), start)
        guess = quat_from_yaw(angles)
        if len(pairs):
            miss = np.abs(wrap_angle(angles[ij[:, 1]] - angles[ij[:, 0]] - quat_yaw(rel)))
            kept = ~far_misses(miss, std, kept, floor)
    for _ in range(6):
        all_ij = np.concatenate([ij[kept], odo_ij])
        all_rel = np.concatenate([rel[kept], odo_rel])
        all_w = np.concatenate([w[kept], 1.0 / odo_std ** 2])
        rot = fit_rotations(n, all_ij, all_rel, all_w, anchor=0, guess=guess)
        bad = far_misses(pair_misses(rot.quaternions, ij, rel), std, kept, floor)
        if not bad.any():
            break
        kept &= ~bad
    # The fit's world is camera 0's planar frame. A shaking camera's first view is tilted:
    # the world is levelled so that the views' mean up is vertical. Then map -> camera 0
    # is its odometry heading, and yaw_i the heading of camera i's forward axis.
    to_world = np.transpose(quat_to_matrix(rot.quaternions), (0, 2, 1))
    if general:
        to_world = _levelling(to_world[:, :, 2]) @ to_world
    yaw = np.arctan2(to_world[:, 1, 0], to_world[:, 0, 0])
    turn_map = float(odom_cam[0, 2] - yaw[0])
    to_world = quat_to_matrix(quat_from_yaw(turn_map)) @ to_world
    yaw = wrap_angle(yaw + turn_map)
    # -- positions (6.1.4) over stations -----------------------------------------------------
    has_dir = np.array([p.has_direction for p in pairs], bool) & kept
    idx = np.flatnonzero(has_dir & (station[ij[:, 0]] != station[ij[:, 1]])) \
        if len(pairs) else np.zeros(0, np.int64)
    s_ij = station[ij[idx]] if len(idx) else np.zeros((0, 2), np.int64)
    dirs = np.array([to_world[pairs[k].i] @ pairs[k].direction for k in idx]).reshape(-1, 3)
    dstd = np.array([pairs[k].direction_std for k in idx])
    # The robot is on a floor whatever its camera did: positions in the plane.
    if not general and len(idx) and refit is not None:
        # Each bearing refitted under the fitted turn (view_pairs.bearings_given_turns).
        chosen = [pairs[k] for k in idx]
        features, camera, pair_settings = refit
        bearing, dstd = bearings_given_turns(
            chosen, np.array([yaw[p.j] - yaw[p.i] for p in chosen]), features, camera,
            pair_settings)
        heading = yaw[ij[idx, 0]] + bearing
        dirs = np.stack([np.cos(heading), np.sin(heading), np.zeros(len(idx))], axis=1)
    dirs = dirs[:, :2]
    dirs /= np.maximum(np.linalg.norm(dirs, axis=1, keepdims=True), 1e-12)
    n_st = int(station.max()) + 1
    first_of = np.array([np.flatnonzero(station == s)[0] for s in range(n_st)])
    st_odom = odom_base[first_of]
    length = np.linalg.norm(st_odom[s_ij[:, 1], :2] - st_odom[s_ij[:, 0], :2], axis=1) \
        if len(idx) else np.zeros(0)
    w_dir = 1.0 / (np.maximum(dstd, 1e-4) * np.maximum(length, 0.05)) ** 2
    # Odometry displacements between consecutive stations, into the world frame.
    a_st, b_st = np.arange(n_st - 1), np.arange(1, n_st)
    delta = st_odom[b_st, :2] - st_odom[a_st, :2]
    base_yaw_est = yaw[first_of] - mount[2]
    turn_to_world = base_yaw_est[a_st] - st_odom[a_st, 2]
    c, s = np.cos(turn_to_world), np.sin(turn_to_world)
    disp = np.stack([c * delta[:, 0] - s * delta[:, 1], s * delta[:, 0] + c * delta[:, 1]], 1)
    # A station step's path: its images' steps between the two stations' first images.
    cum = np.concatenate([np.zeros((1, 2)), np.cumsum(steps, axis=0)])
    o_std, _ = step_stds(cum[first_of[b_st]] - cum[first_of[a_st]], settings)
    odometry = (np.stack([a_st, b_st], 1), disp, 1.0 / o_std ** 2)
    max_angle = math.radians(settings.max_direction_error_deg)
    combined = fit_positions(n_st, s_ij, dirs, w_dir, anchor=0, odometry=odometry,
                             max_angle=max_angle)
    kept_direction = np.zeros(len(pairs), bool)
    kept_direction[idx[combined.kept]] = True
    # The thesis's system: directions alone, scaled by the odometry's path length.
    thesis_pos = np.full((n_st, 2), np.nan)
    if len(idx):
        try:
            alone = fit_positions(n_st, s_ij, dirs, w_dir, anchor=0, max_angle=max_angle)
            steps = np.linalg.norm(np.diff(alone.positions[:, :2], axis=0), axis=1)
            odo_steps = np.linalg.norm(delta, axis=1)
            ok = np.isfinite(steps)
            if ok.any() and steps[ok].sum() > 0:
                thesis_pos = alone.positions * (odo_steps[ok].sum() / steps[ok].sum())
        except VisibilityBuilderError as error:
            _LOG.warning('positions from the directions alone: %s', error)
    joint_pos = combined.positions
    if len(idx):
        # The linear fits' bias removed: bearings and odometry, non-linear and robust.
        seed = thesis_pos if np.isfinite(thesis_pos).all() else combined.positions
        if np.isfinite(seed).all():
            joint_pos, miss = refine_planar_positions(
                seed, s_ij, np.arctan2(dirs[:, 1], dirs[:, 0]), dstd, odometry)
            kept_direction[:] = False
            kept_direction[idx[miss <= 3.0 * dstd]] = True
    components, piece = _components(n_st, station[ij[kept_direction]] if len(idx) else s_ij)
    origin = odom_cam[0, :2]

    def place(positions: np.ndarray) -> np.ndarray:
        out = np.full((n, 3), np.nan)
        xy = positions[station, :2] + origin
        out[:, :2] = xy
        out[:, 2] = wrap_angle(yaw)
        out[~np.isfinite(xy).all(axis=1)] = np.nan
        return out

    # Positions are the cameras' (mount included): the first camera at its odometry pose.
    return {'camera': place(joint_pos), 'thesis': place(thesis_pos),
            'kept_rotation': kept, 'kept_direction': kept_direction,
            'components': components, 'pieces': piece[station]}


def _components(n: int, edges: np.ndarray) -> tuple[list[int], np.ndarray]:
    """Return the stations' component sizes (largest first) and each one's component.

    Components are numbered by size, the largest 0.
    """
    if len(edges) == 0:
        return [1] * n, np.arange(n)
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    count, labels = connected_components(graph, directed=False)
    sizes = np.bincount(labels, minlength=count)
    order = np.argsort(-sizes, kind='stable')
    rank = np.empty(count, np.int64)
    rank[order] = np.arange(count)
    return sizes[order].tolist(), rank[labels]


def _levelling(ups: np.ndarray) -> np.ndarray:
    """Return the rotation that turns the mean of the ``(n, 3)`` unit ``ups`` to ``+z``."""
    mean = np.nanmean(ups, axis=0)
    mean /= np.linalg.norm(mean)
    axis = np.cross(mean, [0.0, 0.0, 1.0])
    sine, cosine = float(np.linalg.norm(axis)), float(mean[2])
    if sine < 1e-12:
        return np.eye(3)
    k = axis / sine
    skew = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + sine * skew + (1.0 - cosine) * skew @ skew

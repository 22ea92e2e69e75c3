"""Figure of a localizer run: estimated and true trajectories over the regions.

The database's decomposition is drawn by :func:`visibility_builder.plotting.draw_decomposition`
(regions in colour over the pose grid, and the scene's walls and obstacles when the
scene is known); over it, the ground truth as a black line, the published poses as
dots coloured by their position error, and the frames without a pose as grey crosses
at their true position. Uses matplotlib's Agg backend.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from landmark_db.database import LandmarkDatabase
from vbn_bench.localization.evaluation import associate, find_teleports

#: Errors below this are drawn at it: the colour scale is logarithmic, centimetres.
_SCALE_MIN_CM = 0.1

__all__ = ['error_scale_cm', 'save_trajectory_figure']


def save_trajectory_figure(path: str | os.PathLike[str], database: LandmarkDatabase,
                           truth_stamps_ns: np.ndarray, truth_poses: np.ndarray,
                           pose_stamps_ns: np.ndarray, poses: np.ndarray,
                           frame_stamps_ns: np.ndarray | None = None, scene: Any = None,
                           title: str = '', dpi: int = 110) -> Path:
    """Draw the run over the database's regions into a PNG file.

    Args:
        path: PNG file to write.
        database: The landmark database localized against.
        truth_stamps_ns: (m,) sorted ground-truth stamps.
        truth_poses: (m, 3) ground truth.
        pose_stamps_ns: (p,) stamps of the published poses.
        poses: (p, 3) published poses.
        frame_stamps_ns: (n,) every frame's stamp, to mark those without a pose.
        scene: The polygon scene (``landmark_db.scenes.resolve_scene``) or None.
        title: Figure title.
        dpi: Resolution.

    Returns:
        The path written.
    """
    import matplotlib

    matplotlib.use('Agg')
    from matplotlib.colors import LogNorm
    import matplotlib.pyplot as plt

    from visibility_builder.plotting import draw_decomposition

    truth = np.asarray(truth_poses, float).reshape(-1, 3)
    est = np.asarray(poses, float).reshape(-1, 3)
    fig, ax = plt.subplots(figsize=(9, 6))
    try:
        draw_decomposition(ax, database.to_world_instance(),
                           [r.poses for r in database.regions], database.info.k,
                           database.uncovered, scene=scene, title=title)
        if len(truth):
            # A teleport (kidnapping) breaks the line rather than drawing a jump.
            line = np.insert(truth[:, :2], find_teleports(truth_stamps_ns, truth), np.nan,
                             axis=0)
            ax.plot(line[:, 0], line[:, 1], '-', color='black', linewidth=1.0, zorder=7,
                    label='ground truth')
        if len(est):
            rows, truth_rows = associate(pose_stamps_ns, truth_stamps_ns)
            error = np.full(len(est), np.nan)
            error[rows] = np.linalg.norm(est[rows, :2] - truth[truth_rows, :2], axis=1)
            # The scale reaches the largest error (a 20 cm outlier must not look like
            # 5 cm), logarithmic so that millimetres stay apart; poses without a true
            # pose at their stamp are grey.
            known = np.isfinite(error)
            if np.any(~known):
                ax.scatter(est[~known, 0], est[~known, 1], color='grey', s=7, zorder=8)
            if np.any(known):
                cm = np.maximum(error[known] * 100, _SCALE_MIN_CM)
                norm = LogNorm(*error_scale_cm(error[known]))
                dots = ax.scatter(est[known, 0], est[known, 1], c=cm, cmap='viridis',
                                  norm=norm, s=7, zorder=8, label='localizer')
                fig.colorbar(dots, ax=ax, shrink=0.6,
                             label=f'position error (cm; max {float(cm.max()):.1f})')
        if frame_stamps_ns is not None and len(truth):
            frames = np.asarray(frame_stamps_ns, np.int64)
            with_pose, _ = associate(frames, np.sort(np.asarray(pose_stamps_ns, np.int64)),
                                     0.001)
            missing = np.setdiff1d(np.arange(len(frames)), with_pose)
            rows, truth_rows = associate(frames[missing], truth_stamps_ns)
            if len(rows):
                ax.scatter(truth[truth_rows, 0], truth[truth_rows, 1], marker='x', s=20,
                           c='grey', zorder=9, label=f'no pose ({len(missing)} frames)')
        ax.legend(loc='upper right', fontsize=7)
        fig.tight_layout()
        path = Path(path)
        fig.savefig(path, dpi=dpi)
    finally:
        plt.close(fig)
    return path


def error_scale_cm(errors_m: np.ndarray) -> tuple[float, float]:
    """Return the colour scale ``(low, high)`` of position errors, centimetres.

    ``high`` is the largest error, so that no error is drawn smaller than it is;
    ``low`` is 0.1 cm (the scale is logarithmic).
    """
    top = float(np.nanmax(errors_m)) * 100 if np.any(np.isfinite(errors_m)) else 0.0
    return _SCALE_MIN_CM, max(top, 2 * _SCALE_MIN_CM)

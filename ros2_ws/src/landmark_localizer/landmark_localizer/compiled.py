"""Every compiled kernel of a tracked frame, loaded before the first frame.

Not in the thesis. numba compiles a kernel on its first call, or loads the machine
code it cached on an earlier run (``cache=True``): a few milliseconds a kernel from the
cache, seconds without it. :func:`warm_up` makes those first calls on tiny inputs when
the localizer starts, so that neither a node's first tracked frames nor a benchmark's
latency carry them.
"""
from __future__ import annotations

import numpy as np

from landmark_localizer.angular_kernels import (
    angular_errors,
    coarse_inliers,
    gauss_newton,
    normal_equations,
)
from landmark_localizer.index import _optical_points
from landmark_localizer.planar_kernels import refine_planar
from landmark_localizer.tilt_kernels import refine_tilted_in_place
from landmark_localizer.tracking import _nearest_keypoint, disc_mask
from vbn_common.geometry import lens
from vbn_common.patch_alignment import _correlations, _match_brightness, tile_mosaic, warp_patches

__all__ = ['warm_up']


def warm_up() -> None:
    """Call every kernel once with the argument types the localizer passes."""
    state, rays = np.zeros(6), np.full((3, 3), 3 ** -0.5)
    points = rays * 2.0 + [0.1, 0.2, 0.3]
    gauss_newton(state.copy(), rays, points, 0.1, np.ones(3), np.arange(3), np.zeros(3),
                 np.zeros(6), 1, 1e-4, 1e-5)
    normal_equations(state, rays, points, 0.1, np.ones(3), np.empty((6, 6)), np.empty(6))
    angular_errors(state, rays, points)
    coarse_inliers(np.zeros((1, 3)), rays, points, 0.1, 0.01, 0.01)
    refine_planar(np.zeros(3), np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.5]]),
                  np.array([0, 1, 1]), rays, rays, 0.01, 1, np.empty(3), np.empty((3, 3)))
    refine_tilted_in_place(np.zeros(6), np.eye(3), np.zeros(3), np.ones(3), rays, rays, 0.01,
                           np.ones(6), 1, np.empty(3), np.empty((3, 6)))
    _optical_points(np.zeros(6), np.ones((2, 3)), np.eye(3))
    disc_mask(5, 5, 2.0, 2.0, 1.5)
    _nearest_keypoint(np.zeros((1, 2), np.float32), np.zeros(2, np.float32),
                      np.zeros((1, 128), np.float32), np.zeros((1, 128), np.float32),
                      np.zeros(2, np.float32), 1.0)
    lens.equidistant_theta(np.array([0.1]), np.zeros(4), 1.5)
    lens.brown_invert(np.ones((1, 2)), 1.0, 1.0, 0.0, 0.0, np.zeros(8))
    lens.brown_project(np.ones((1, 3)), 1.0, 1.0, 0.0, 0.0, np.zeros(8), 1.0)
    tiles = np.zeros((1, 5, 5), np.float32)
    _match_brightness(tiles, tiles, 3)
    _correlations(tiles, np.full((1, 2), 2.0, np.float32), tiles, 3)
    tile_mosaic(tiles, 1)
    warp_patches(np.zeros((1, 3, 3), np.uint8), np.eye(2)[None], 5)

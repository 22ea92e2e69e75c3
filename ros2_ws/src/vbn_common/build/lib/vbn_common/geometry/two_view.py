"""Relative motion between a model view and the current view (thesis Sections 7.3 to 7.5).

Four solvers of the thesis, one module each, each a function of point correspondences
that returns a :class:`~vbn_common.geometry.motion.RelativeMotion`;
:func:`relative_motion` converts pixels with the project's camera models and picks
the solver by the camera's kind (a ``method`` argument overrides it):

- :mod:`.panoramic_planar` (7.5.2, "Computing T and theta"): the closed form for
  cylindrical panoramas under planar motion. Each pair of correspondences gives a
  quadratic in ``r`` (eq. 7.15) and two candidate rotations (eq. 7.16).
- :mod:`.pinhole_planar` (7.5.1): the planar essential matrix, four unknowns
  ``(e12, e21, e23, e32)`` linear in at least four correspondences, rotation and
  translation read from it without the usual four-fold ambiguity.
- :mod:`.essential` (7.4): Hartley's normalised eight-point algorithm inside RANSAC
  and the textbook decomposition with the cheirality test, for any camera.
- :mod:`.linear_combination` (7.3): Basri and Rivlin's scheme under weak
  perspective, from two model views and the current one (pinhole only).

Conventions (shared with :mod:`vbn_common.geometry.localize`):

- Inputs are unit rays in the camera's optical frame (``z`` forward, ``x`` right,
  ``y`` down), as :meth:`CameraModel.unproject
  <vbn_common.geometry.camera.CameraModel.unproject>` returns them: the
  *model* view's rays and the *current* view's rays, row ``i`` of both the same
  scene point.
- The result is the current camera's pose in the model camera's *planar* frame
  (REP 103: ``x`` forward, ``y`` left, angles counter-clockwise seen from above):
  ``theta`` is the current camera's yaw minus the model camera's yaw and
  ``direction`` the unit vector from the model camera to the current camera. Two
  views fix the translation only up to its length, so
  ``compose_poses(model_pose, (s * direction[0], s * direction[1], theta))`` is the
  current camera's pose in ``map`` for some unknown ``s > 0``.
- Thresholds and residuals are angles in radians: the Sampson approximation of the
  epipolar error on the unit sphere (about one pixel divided by the focal length in
  pixels: 1 px is 6.1e-3 rad on a 1024-pixel-wide panorama).

The planar methods (and the general one, which ignores that the motion is planar)
work in the optical frame with the epipolar constraint ``p_cur^T E p_model = 0``,
``E = [T]x R``, ``X_cur = R X_model + T``, as the thesis writes them.

The solvers share :mod:`.epipolar` (planar and optical motions, Sampson errors,
cheirality, the parallax test, the polish and the covariance) and :mod:`.ransac` (one
batched MSAC loop).

Limits: points on one plane (a single wall filling a pinhole view) leave the
essential matrices ambiguous; the general eight-point method needs a longer baseline
than the planar ones for the same accuracy (five unknowns instead of two). Speed:
everything is vectorised numpy on small matrices, where OpenBLAS threads only
contend; run with ``OPENBLAS_NUM_THREADS=1`` (measured 5 to 100 times faster on the
loaded 2-core machine, see ``docs/localization.md``).
"""
from __future__ import annotations

import logging
import math

import numpy as np

from vbn_common.errors import VbnCommonError
from vbn_common.geometry.camera import CameraModel, pixels_per_radian
from vbn_common.geometry.essential import general_essential
from vbn_common.geometry.motion import RelativeMotion, TwoViewConfig
from vbn_common.geometry.panoramic_planar import panoramic_planar_motion
from vbn_common.geometry.pinhole_planar import pinhole_planar_essential

__all__ = ['DEFAULT_METHOD', 'METHODS', 'relative_motion']

_LOG = logging.getLogger(__name__)

#: Names of the two-view methods of :func:`relative_motion`.
METHODS = ('panoramic_planar', 'pinhole_planar', 'general_essential')
#: Default method per camera kind (the database's camera model picks the method).
DEFAULT_METHOD = {'panoramic': 'panoramic_planar', 'pinhole': 'pinhole_planar',
                  'fisheye': 'pinhole_planar'}


def relative_motion(uv_model: np.ndarray, uv_current: np.ndarray, camera: CameraModel, *,
                    method: str | None = None, config: TwoViewConfig | None = None,
                    rng: np.random.Generator | int | None = None,
                    current_camera: CameraModel | None = None) -> RelativeMotion:
    """Estimate the motion from a model view to the current view from matched pixels.

    Converts pixels to rays with ``camera`` (the same model for both views) and
    pixel thresholds to angles with its focal length (the coarser of the two cameras'
    when ``current_camera`` is given: a residual carries both views' noise), then
    calls the method:
    ``camera.kind`` picks it (``'panoramic'`` -> :func:`panoramic_planar_motion`,
    ``'pinhole'`` -> :func:`pinhole_planar_essential`) unless ``method`` names one of
    :data:`METHODS`.

    Args:
        uv_model: ``(n, 2)`` pixel coordinates in the model view.
        uv_current: ``(n, 2)`` pixel coordinates of the same points in the current view.
        camera: the camera model of both views (of the model view when
            ``current_camera`` is given).
        current_camera: the current view's camera when it is another (a run camera at
            another resolution); of the same kind.
        method: ``None`` (by camera kind), or a name from :data:`METHODS`.
        config: thresholds and RANSAC settings (default :class:`TwoViewConfig`).
        rng: random generator or seed.

    Returns:
        The motion (module conventions).

    Raises:
        VbnCommonError: an unknown method, a method that needs another camera,
            or the method's own errors.
    """
    config = config or TwoViewConfig()
    method = method or DEFAULT_METHOD.get(camera.kind)
    if method not in METHODS:
        raise VbnCommonError(f'unknown two-view method {method!r} (expected one of '
                             f'{", ".join(METHODS)})')
    uv_model = np.asarray(uv_model, dtype=float).reshape(-1, 2)
    uv_current = np.asarray(uv_current, dtype=float).reshape(-1, 2)
    rays_model = camera.unproject(uv_model)
    rays_current = (current_camera or camera).unproject(uv_current)
    f = pixels_per_radian(camera)
    if current_camera is not None:
        f = min(f, pixels_per_radian(current_camera))
    common = {'threshold': config.threshold_px / f, 'noise_floor': config.noise_floor_px / f,
              'min_parallax': config.min_parallax_px / f,
              'min_parallax_ratio': config.min_parallax_ratio, 'rng': rng}
    if method == 'panoramic_planar':
        if camera.kind != 'panoramic':
            raise VbnCommonError(f'panoramic_planar needs a panoramic camera, got '
                                 f'{camera.kind!r}')
        return panoramic_planar_motion(
            rays_model, rays_current, min_elevation=math.radians(config.min_elevation_deg),
            max_pairs=config.max_pairs, refine=config.refine, **common)
    ransac = {'max_iterations': config.max_iterations, 'confidence': config.confidence}
    if method == 'pinhole_planar':
        motion = pinhole_planar_essential(rays_model, rays_current, refine=config.refine,
                                          **ransac, **common)
    else:
        motion = general_essential(rays_model, rays_current, **ransac, **common)
    _LOG.debug('%s: %d of %d inliers, residual %.2f px', method, int(motion.inliers.sum()),
               len(uv_model), motion.residual * f)
    return motion

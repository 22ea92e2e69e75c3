"""Rendering through a lens or a tilted mount: distortion, fisheyes, pitch.

The column renderer (:mod:`.renderer`) needs a camera in which a vertical wall line is
one image column: an undistorted pinhole or the cylindrical panorama. A distorted
pinhole or a fisheye is rendered by a *source* camera of that kind with the same
optical centre and axis, resampled once per frame with ``cv2.remap`` through maps
computed once: each target pixel's ray (:meth:`CameraModel.unproject`, the lens's
inverse) projected into the source.

- Distorted pinhole (``plumb_bob``, ``rational_polynomial``): the source is the
  undistorted pinhole with the same focal lengths, widened to hold every target ray
  (barrel distortion pulls a wider view into the image), so the centre keeps its
  resolution.
- A tilted mount (:class:`~vbn_common.geometry.mount.TiltedCamera`): the same, with
  the rays in the level camera frame (a taller panorama for a tilted panorama).
- Fisheye (``equidistant``): the source is a cylindrical panorama with as many pixels
  per radian as the fisheye's centre (``fx``), covering elevations up to
  :data:`MAX_ELEVATION_DEG`; rays steeper than that (the floor and the ceiling right
  above and below the camera, which are flat-shaded) take the nearest source row.

Pixels beyond the lens model (the corners of a wide fisheye, which no ray reaches) are
black and show no wall point. The ground truth follows the same maps:
:meth:`LensRenderer.pixel_to_wall_point` asks the source for the wall point of the
ray's source pixel, and ``with_points`` resamples the source's points with
nearest-neighbour lookups.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from landmark_db.scene import Scene
from vbn_common.geometry.camera import CameraModel, PanoramicCamera, PinholeCamera
from vbn_common.geometry.mount import TiltedCamera
from vbn_worlds.errors import WorldsError
from vbn_worlds.render.effects import ImageEffects, apply_effects
from vbn_worlds.render.renderer import Occluders, Renderer, Rendering
from vbn_worlds.render.textures import WallAtlas

__all__ = ['MAX_ELEVATION_DEG', 'LensRenderer', 'make_renderer']

#: Steepest elevation a fisheye's source panorama covers, degrees.
MAX_ELEVATION_DEG = 72.0
_MAX_SOURCE_SIDE = 8192


def make_renderer(scene: Scene, camera: CameraModel, atlas: WallAtlas | None = None,
                  margin_deg: float = 0.0) -> Renderer | LensRenderer:
    """Return the column renderer, or a :class:`LensRenderer` for a lens it cannot draw.

    ``margin_deg`` > 0: a lens renderer whose frames may tilt by up to that much more
    (:meth:`LensRenderer.render`'s ``tilt``; vibration).
    """
    if camera.kind == 'fisheye' or getattr(camera, 'distorted', False) or \
            isinstance(camera, TiltedCamera) or margin_deg > 0:
        return LensRenderer(scene, camera, atlas, margin_deg)
    return Renderer(scene, camera, atlas)


def _source_camera(camera: CameraModel, rays: np.ndarray, margin_deg: float = 0.0
                   ) -> CameraModel:
    """Return the column camera the target's rays are resampled from (module doc)."""
    extra = math.tan(math.radians(margin_deg))
    if camera.kind == 'fisheye':
        f = float(camera.fx)  # type: ignore[attr-defined]
        width = int(math.ceil(2.0 * math.pi * f))
        half = f * math.tan(math.radians(MAX_ELEVATION_DEG))
        height = int(2 * math.ceil(half) + 2)
        if max(width, height) > _MAX_SOURCE_SIDE:
            raise WorldsError(f'fisheye too fine to render: a {width} x {height} '
                                         f'source panorama')
        return PanoramicCamera(width, height)
    if camera.kind == 'panoramic':   # a tilted panorama: a taller level one
        slope = np.abs(rays[:, 1]) / np.maximum(np.hypot(rays[:, 0], rays[:, 2]), 1e-9)
        f_y = camera.width / (2.0 * math.pi)
        half = f_y * min(float(slope.max()) + extra, math.tan(math.radians(MAX_ELEVATION_DEG)))
        return PanoramicCamera(camera.width, int(2 * math.ceil(half) + 4))
    if camera.kind != 'pinhole':
        raise WorldsError(f'no lens renderer for a {camera.kind} camera')
    fx, fy = float(camera.fx), float(camera.fy)  # type: ignore[attr-defined]
    x, y = rays[:, 0] / rays[:, 2], rays[:, 1] / rays[:, 2]
    margin_x, margin_y = 2.0 + fx * extra * 2.0, 2.0 + fy * extra * 2.0
    left, right = fx * x.min() - margin_x, fx * x.max() + margin_x
    top, bottom = fy * y.min() - margin_y, fy * y.max() + margin_y
    width, height = int(math.ceil(right - left)) + 1, int(math.ceil(bottom - top)) + 1
    if max(width, height) > _MAX_SOURCE_SIDE:
        raise WorldsError(f'the lens distortion spreads the view over a {width} '
                                     f'x {height} source image: too strong to render')
    return PinholeCamera(width, height, fx, fy, -left, -top)


def _round_trips(camera: CameraModel, uv: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """Return which pixels' rays project back onto them (within 1e-3 pixels)."""
    back, _ = camera.project(rays)
    return np.all(np.abs(back - uv) < 1e-3, axis=1)


class LensRenderer:
    """Render a distorted pinhole, a fisheye or a tilted camera through a column camera.

    Args:
        scene: the floor plan.
        camera: the target camera (module docstring).
        atlas: wall textures; built from the scene when ``None``.
        margin_deg: the source also covers frames tilted this much more (vibration).
    """

    def __init__(self, scene: Scene, camera: CameraModel,
                 atlas: WallAtlas | None = None, margin_deg: float = 0.0) -> None:
        self.scene = scene
        self.camera = camera
        u, v = np.meshgrid(np.arange(camera.width, dtype=float),
                           np.arange(camera.height, dtype=float))
        pixels = np.column_stack([u.ravel(), v.ravel()])
        # The untilted lens's rays, kept for frames with a tilt of their own.
        self._lens = camera.camera if isinstance(camera, TiltedCamera) else camera
        self._lens_rays = self._lens.unproject(pixels)
        rays = camera.unproject(pixels)
        self.source = _source_camera(camera, rays, margin_deg)
        self.inner = Renderer(scene, self.source, atlas)
        self.atlas = self.inner.atlas
        self._shape = (camera.height, camera.width)
        # Pixels beyond the lens model (a wide fisheye's corners): no ray comes back to
        # them; a real lens leaves them dark.
        self._outside = ~_round_trips(self._lens, pixels, self._lens_rays).reshape(
            self._shape)
        self._map_x, self._map_y = self._maps(rays)

    def _maps(self, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        uv, _ = self.source.project(rays)
        # Rays the source cannot show (straight up or down) go off its rows: the
        # nearest row (BORDER_REPLICATE) is the floor or the ceiling there.
        uv = np.where(np.isfinite(uv), uv, -1e6)
        map_x = uv[:, 0].reshape(self._shape).astype(np.float32)
        map_y = np.clip(uv[:, 1], -1.0, self.source.height).reshape(self._shape).astype(
            np.float32)
        return map_x, map_y

    def render(self, pose: np.ndarray, *, encoding: str = 'bgr8',
               effects: ImageEffects | None = None, rng: np.random.Generator | None = None,
               with_points: bool = False, tilt: np.ndarray | None = None,
               occluders: Occluders | None = None) -> Rendering:
        """Render the target camera's image from ``pose`` (as :meth:`Renderer.render`).

        ``tilt``: this frame's own tilt of the lens (:mod:`vbn_common.geometry.mount`),
        in place of the camera's (vibration); it should stay within the margin.
        ``rho`` and ``segment`` are the source camera's, per source column.
        """
        map_x, map_y = (self._map_x, self._map_y) if tilt is None else \
            self._maps(self._lens_rays @ np.asarray(tilt, float).reshape(3, 3).T)
        source = self.inner.render(pose, encoding=encoding, with_points=with_points,
                                   occluders=occluders)
        # Past the source's last row or column: the nearest (a panorama's projection
        # already wraps its columns; rows past the top and bottom are ceiling and floor).
        image = cv2.remap(source.image, map_x, map_y, cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_REPLICATE)
        image[self._outside] = 0
        if effects is not None and effects.active:
            if rng is None:
                raise WorldsError('image effects need a random generator')
            image = apply_effects(image, effects, rng)
        points = None
        if with_points and source.wall_points is not None:
            points = cv2.remap(source.wall_points, map_x, map_y,
                               cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                               borderValue=(np.nan,) * 3)
            points[self._outside] = np.nan
        return Rendering(image, source.rho, source.segment, points)

    def pixel_to_wall_point(self, pose: np.ndarray, u: np.ndarray | float,
                            v: np.ndarray | float) -> np.ndarray:
        """Return the 3-D ``map`` points the target pixels show (NaN: floor, ceiling)."""
        u = np.atleast_1d(np.asarray(u, dtype=float))
        v = np.atleast_1d(np.asarray(v, dtype=float))
        rays = self.camera.unproject(np.column_stack([u.ravel(), v.ravel()]))
        uv, ok = self.source.project(rays)
        ok &= _round_trips(self.camera, np.column_stack([u.ravel(), v.ravel()]), rays)
        points = self.inner.pixel_to_wall_point(pose, np.where(ok, uv[:, 0], 0.0),
                                                np.where(ok, uv[:, 1], 0.0))
        points[~ok] = np.nan
        return points

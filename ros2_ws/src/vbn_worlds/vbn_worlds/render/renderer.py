"""A 2.5-D ray-casting renderer of a scene's extruded walls (thesis Section 7.5).

The floor plan's perimeter and obstacles become vertical walls of ``wall_height``
metres between a floor and a ceiling plane; the camera sits at ``camera_height`` on
a robot that moves in the plane (the planar-motion setting of Section 7.5). Because
the camera neither pitches nor rolls, a vertical wall line projects to one image
column for both camera models (:mod:`vbn_common.geometry.camera`), so rendering is

1. one horizontal ray per image column, intersected with every wall segment at once
   (``(columns, segments)`` arrays): the nearest hit gives the wall, the arc length
   along it and the horizontal range ``rho``;
2. per pixel, the height ``z = camera_height - (v - y0) * c * rho / f_y`` of the wall
   point the row sees (``c`` is the column's depth-per-range factor): rows with
   ``0 <= z <= wall_height`` show the wall, others the floor or the ceiling;
3. the wall texture sampled at ``(arc length, height)`` from the mip level that
   matches the column's pixel footprint, with ``cv2.remap`` (bilinear, blended
   between two levels).

The floor and ceiling are flat-shaded by distance (featureless on purpose: the
ground truth of :meth:`Renderer.pixel_to_wall_point` covers walls only). The same
ray cast gives the ground truth: the 3-D point each pixel shows.

:class:`Occluders` are what a world holds beyond its walls: furniture lower
than the walls and people walking through the view, as vertical faces with a top
height and a colour. A second ray cast against them paints, over the walls, the pixels
where the nearest of them stands in front of the wall and below its top (one layer:
what an occluder hides of another behind it is drawn as wall). They are not walls of
the map: the ground truth shows no wall point there.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import cv2
import numpy as np

from landmark_db.scene import Scene
from vbn_common.geometry.camera import CameraModel
from vbn_worlds.errors import WorldsError
from vbn_worlds.render.effects import ImageEffects, apply_effects
from vbn_worlds.render.textures import WallAtlas, build_wall_atlas

__all__ = ['Occluders', 'Renderer', 'Rendering', 'cast_rays']

_FLOOR_BGR = np.array([62.0, 84.0, 104.0], np.float32)
_CEILING_BGR = np.array([228.0, 230.0, 232.0], np.float32)


def cast_rays(origin: np.ndarray, angles: np.ndarray, starts: np.ndarray,
              ends: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Intersect horizontal rays from one origin with every wall segment.

    Args:
        origin: ``(2,)`` ray origin in ``map``, metres.
        angles: ``(n,)`` ray directions in ``map``, radians (counter-clockwise from x).
        starts: ``(s, 2)`` segment start points.
        ends: ``(s, 2)`` segment end points.

    Returns:
        ``(rho, segment, s)``: per ray the distance to the nearest hit (``inf``
        when nothing is hit), the hit segment's index (-1 for none) and the hit's
        position along the segment in ``[0, 1]`` (from start to end).
    """
    d = np.stack([np.cos(angles), np.sin(angles)], axis=1)  # (n, 2)
    e = ends - starts  # (s, 2)
    ap = starts - np.asarray(origin, dtype=float)[None, :]  # (s, 2)
    denom = d[:, 0, None] * e[None, :, 1] - d[:, 1, None] * e[None, :, 0]
    # Near-parallel rays give huge or infinite quotients; the hit mask below drops them.
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        t = (ap[:, 0] * e[:, 1] - ap[:, 1] * e[:, 0])[None, :] / denom
        s = (ap[None, :, 0] * d[:, 1, None] - ap[None, :, 1] * d[:, 0, None]) / denom
    hit = (np.abs(denom) > 1e-12) & (t > 1e-9) & (s >= 0.0) & (s <= 1.0)
    t = np.where(hit, t, np.inf)
    segment = np.argmin(t, axis=1)
    rows = np.arange(len(angles))
    rho = t[rows, segment]
    s_hit = np.where(np.isfinite(rho), s[rows, segment], 0.0)
    segment = np.where(np.isfinite(rho), segment, -1)
    return rho, segment, s_hit


@dataclass(frozen=True)
class Occluders:
    """Vertical faces in front of the walls, each up to its own height.

    Attributes:
        starts: ``(o, 2)`` face start points in ``map``, metres.
        ends: ``(o, 2)`` face end points.
        tops: ``(o,)`` heights of their top edges above the floor, metres.
        colours: ``(o, 3)`` BGR colours (shaded by a cloth-like weave when drawn).
    """

    starts: np.ndarray
    ends: np.ndarray
    tops: np.ndarray
    colours: np.ndarray

    @staticmethod
    def boxes(footprints: list[np.ndarray], tops: list[float],
              colours: list[tuple[float, float, float]]) -> Occluders:
        """Return the faces of upright prisms on ``(m, 2)`` footprint polygons."""
        starts = [np.asarray(f, float) for f in footprints]
        ends = [np.roll(f, -1, axis=0) for f in starts]
        count = [len(f) for f in starts]
        if not starts:
            return Occluders(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), np.zeros((0, 3)))
        return Occluders(np.concatenate(starts), np.concatenate(ends),
                         np.repeat(np.asarray(tops, float), count),
                         np.repeat(np.asarray(colours, float).reshape(-1, 3), count, axis=0))

    def __add__(self, other: Occluders) -> Occluders:
        return Occluders(*(np.concatenate([a, b]) for a, b in
                           zip((self.starts, self.ends, self.tops, self.colours),
                               (other.starts, other.ends, other.tops, other.colours))))

    def __len__(self) -> int:
        return len(self.tops)


@dataclass(frozen=True)
class Rendering:
    """One rendered image and what it shows.

    Attributes:
        image: ``(h, w)`` mono8 or ``(h, w, 3)`` bgr8 ``uint8`` image.
        rho: ``(w,)`` horizontal range to the wall hit by each column (``inf``: none).
        segment: ``(w,)`` index of that wall segment (-1: none).
        wall_points: ``(h, w, 3)`` ``float32`` ``map`` point shown by each pixel,
            NaN on the floor and ceiling; ``None`` unless requested.
    """

    image: np.ndarray
    rho: np.ndarray
    segment: np.ndarray
    wall_points: np.ndarray | None = None


class Renderer:
    """Render one scene through one camera model.

    Args:
        scene: the floor plan (walls extruded to ``scene.wall_height``).
        camera: a :class:`~vbn_common.geometry.camera.CameraModel`.
        atlas: wall textures; built from ``scene.texture_seed`` when ``None``.
    """

    def __init__(self, scene: Scene, camera: CameraModel,
                 atlas: WallAtlas | None = None) -> None:
        self.scene = scene
        self.camera = camera
        self.atlas = atlas if atlas is not None else build_wall_atlas(scene)
        self.starts, self.ends, _ = scene.wall_segments()
        edge = self.ends - self.starts
        lengths = np.linalg.norm(edge, axis=1)
        self._normals = np.stack([-edge[:, 1], edge[:, 0]], 1) / lengths[:, None]
        self.columns = np.arange(camera.width, dtype=float)
        self.alpha, self.depth_factor = camera.column_geometry(self.columns)
        if camera.kind == 'pinhole':
            self._dalpha = np.cos(self.alpha) ** 2 / camera.fx  # type: ignore[attr-defined]
        else:
            self._dalpha = np.full(camera.width, 2.0 * math.pi / camera.width)
        rows = np.arange(camera.height, dtype=np.float32)
        # k[v, u] = (v - y0) * c(u) / f_y: the drop in height per metre of range.
        self._k = ((rows[:, None] - camera.horizon_row)
                   * self.depth_factor[None, :].astype(np.float32) / camera.f_vertical)
        self._background_bgr = self._floor_and_ceiling()
        self._background_gray = cv2.cvtColor(self._background_bgr, cv2.COLOR_BGR2GRAY)

    def _floor_and_ceiling(self) -> np.ndarray:
        h_c = self.scene.camera_height
        up = self.scene.wall_height - h_c
        with np.errstate(divide='ignore'):
            floor_range = np.where(self._k > 0, h_c / self._k, np.inf)
            ceiling_range = np.where(self._k < 0, up / -self._k, np.inf)
        floor = _FLOOR_BGR[None, None, :] * (0.55 + 0.45 * np.exp(-floor_range / 5.0))[..., None]
        ceiling = _CEILING_BGR[None, None, :] * (
            0.8 + 0.2 * np.exp(-ceiling_range / 5.0))[..., None]
        image = np.where((self._k > 0)[..., None], floor, ceiling) * self.atlas.gain
        return np.clip(image, 0, 255).astype(np.uint8)

    def cast(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cast one ray per image column from ``pose`` (see :func:`cast_rays`)."""
        x, y, yaw = _pose(pose)
        return cast_rays(np.array([x, y]), yaw - self.alpha, self.starts, self.ends)

    def render(self, pose: np.ndarray, *, encoding: str = 'bgr8',
               effects: ImageEffects | None = None, rng: np.random.Generator | None = None,
               with_points: bool = False, occluders: Occluders | None = None) -> Rendering:
        """Render the image the camera sees from robot pose ``pose``.

        Args:
            pose: ``(x, y, yaw)`` of ``base_link`` in ``map`` (metres, radians).
            encoding: ``'bgr8'`` or ``'mono8'``.
            effects: per-frame photometric effects, drawn from ``rng``.
            rng: generator for ``effects`` (required when they are active).
            with_points: also return the per-pixel ground-truth wall points.
            occluders: furniture and people in front of the walls (module docstring).

        Returns:
            The :class:`Rendering`.
        """
        if encoding not in ('bgr8', 'mono8'):
            raise WorldsError(f'unknown image encoding {encoding!r} '
                                         '(expected bgr8 or mono8)')
        x, y, yaw = _pose(pose)
        atlas = self.atlas
        rho, segment, s = self.cast(pose)
        hit = segment >= 0
        seg = np.where(hit, segment, 0)
        # No hit (a gap in the walls): a far range keeps the arithmetic finite.
        depth = np.where(hit, rho * self.depth_factor, 1e6).astype(np.float32)
        h_c = self.scene.camera_height
        far = np.where(hit, rho, 1e6).astype(np.float32)
        z = h_c - self._k * far[None, :]  # (h, w) height of the wall point per pixel
        wall = (z >= 0.0) & (z <= self.scene.wall_height) & hit[None, :]
        # Texture coordinates at level 0 (texel centres at integers).
        tpm = atlas.texels_per_metre
        arc = np.where(atlas.flip[seg], 1.0 - s, s) * atlas.lengths[seg]
        tex_x = (atlas.origins[seg, 0] + arc * tpm - 0.5).astype(np.float32)
        tex_y = (atlas.origins[seg, 1][None, :]
                 + (self.scene.wall_height - z) * tpm - 0.5).astype(np.float32)
        # Mip level per column from the pixel footprint on the wall, in texels.
        ray = yaw - self.alpha
        cos_incidence = np.abs(np.cos(ray) * self._normals[seg, 0]
                               + np.sin(ray) * self._normals[seg, 1])
        foot_v = depth / self.camera.f_vertical * tpm
        foot_h = np.where(hit, rho, 0.0) * self._dalpha / np.maximum(cos_incidence, 0.05) * tpm
        footprint = np.maximum(foot_v, np.minimum(foot_h, 2.0 * foot_v))
        n_levels = len(atlas.levels)
        with np.errstate(divide='ignore'):
            level = np.clip(np.log2(np.maximum(footprint, 1e-6)), 0.0, n_levels - 1.0)
        mono = encoding == 'mono8'
        mip = atlas.gray_mip() if mono else atlas.mip
        background = self._background_gray if mono else self._background_bgr
        # Trilinear sampling: two bilinear remaps into the stacked pyramid, at the
        # levels just below and above each column's level, blended per column.
        lo = np.floor(level).astype(np.int64)
        hi = np.minimum(lo + 1, n_levels - 1)
        blend = (level - lo).astype(np.float32)
        tex_y = np.where(wall, tex_y, -1e4).astype(np.float32)
        samples = []
        for lv in (lo, hi):
            scale = (1.0 / (1 << lv)).astype(np.float32)
            map_x = np.broadcast_to((tex_x * scale)[None, :], wall.shape)
            map_y = tex_y * scale[None, :] + atlas.mip_rows[lv].astype(np.float32)[None, :]
            samples.append(cv2.remap(mip, np.ascontiguousarray(map_x), map_y,
                                     cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT))
        weight = blend[None, :, None] if not mono else blend[None, :]
        lo_image = samples[0].astype(np.float32)
        mixed = lo_image + (samples[1].astype(np.float32) - lo_image) * weight
        image = background.copy()
        mask = np.broadcast_to(wall[..., None], shape=image.shape) if not mono else wall
        np.copyto(image, (mixed + 0.5).astype(np.uint8), where=mask)
        if occluders is not None and len(occluders):
            covered = self._occlude(image, x, y, ray, np.where(hit, rho, np.inf), occluders)
            wall &= ~covered
        if effects is not None and effects.active:
            if rng is None:
                raise WorldsError('image effects need a random generator')
            image = apply_effects(image, effects, rng)
        points = None
        if with_points:
            points = self._wall_points(x, y, ray, rho, z, wall)
        return Rendering(image, rho, segment, points)

    def _occlude(self, image: np.ndarray, x: float, y: float, ray: np.ndarray,
                 rho: np.ndarray, occluders: Occluders) -> np.ndarray:
        """Paint the occluders in front of the walls; return the pixels they cover."""
        o_rho, o_seg, o_s = cast_rays(np.array([x, y]), ray, occluders.starts, occluders.ends)
        seg = np.where(o_seg >= 0, o_seg, 0)
        near = (o_seg >= 0) & (o_rho < rho)
        far = np.where(near, o_rho, 1e6).astype(np.float32)
        z = self.scene.camera_height - self._k * far[None, :]
        covered = near[None, :] & (z >= 0.0) & (z <= occluders.tops[seg][None, :])
        if not covered.any():
            return covered
        edge = occluders.ends[seg] - occluders.starts[seg]
        length = np.linalg.norm(edge, axis=1)
        normal = np.stack([-edge[:, 1], edge[:, 0]], axis=1) / np.maximum(length, 1e-9)[:, None]
        shade = 0.55 + 0.45 * np.abs(np.cos(ray) * normal[:, 0] + np.sin(ray) * normal[:, 1])
        # A weave: stripes along the face and across it, a few centimetres wide.
        arc = (o_s * length)[None, :]
        weave = 0.85 + 0.15 * np.sin(arc * 40.0) * np.cos(z * 55.0)
        light = (shade[None, :] * weave * self.atlas.gain)[..., None]
        colour = np.clip(occluders.colours[seg][None, :, :] * light, 0, 255)
        if image.ndim == 2:
            colour = colour @ np.array([0.114, 0.587, 0.299])
        image[covered] = (colour[covered] + 0.5).astype(np.uint8)
        return covered

    def _wall_points(self, x: float, y: float, ray: np.ndarray, rho: np.ndarray,
                     z: np.ndarray, wall: np.ndarray) -> np.ndarray:
        h, w = wall.shape
        points = np.full((h, w, 3), np.nan, np.float32)
        px = np.broadcast_to((x + rho * np.cos(ray))[None, :], (h, w))
        py = np.broadcast_to((y + rho * np.sin(ray))[None, :], (h, w))
        points[..., 0] = np.where(wall, px, np.nan)
        points[..., 1] = np.where(wall, py, np.nan)
        points[..., 2] = np.where(wall, z, np.nan)
        return points

    def pixel_to_wall_point(self, pose: np.ndarray, u: np.ndarray | float,
                            v: np.ndarray | float) -> np.ndarray:
        """Return the 3-D ``map`` point of the wall that pixel ``(u, v)`` shows.

        Args:
            pose: ``(x, y, yaw)`` of ``base_link`` in ``map``.
            u: column coordinate(s), may be fractional (a keypoint).
            v: row coordinate(s), same shape as ``u``.

        Returns:
            ``(n, 3)`` points ``(x, y, z)`` (``z`` above the floor), NaN where the
            pixel shows the floor or the ceiling or no wall.
        """
        x, y, yaw = _pose(pose)
        u = np.atleast_1d(np.asarray(u, dtype=float))
        v = np.atleast_1d(np.asarray(v, dtype=float))
        alpha, c = self.camera.column_geometry(u)
        ray = yaw - alpha
        rho, segment, _ = cast_rays(np.array([x, y]), ray, self.starts, self.ends)
        z = self.scene.camera_height - (v - self.camera.horizon_row) * c * rho / (
            self.camera.f_vertical)
        ok = (segment >= 0) & (z >= 0.0) & (z <= self.scene.wall_height)
        points = np.stack([x + rho * np.cos(ray), y + rho * np.sin(ray), z], axis=1)
        points[~ok] = np.nan
        return points


def _pose(pose: np.ndarray) -> tuple[float, float, float]:
    pose = np.asarray(pose, dtype=float).reshape(-1)
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        raise WorldsError(f'a pose is (x, y, yaw) with finite values, got {pose}')
    return float(pose[0]), float(pose[1]), float(pose[2])

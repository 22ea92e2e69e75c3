"""The structure-based peer's map: SIFT tracks of the exploration, triangulated.

What a user of hloc or pycolmap builds from an exploration whose image poses are known,
to localize against: SIFT on every exploration image; each image matched to its nearest
neighbours (Lowe's ratio test, then the epipolar constraint of the known poses); the
matches joined into tracks (connected components, a track that holds two features of one
image loses that image's); every track of two or more images triangulated with the known
poses (the linear mid-point of its rays, observations further than ``max_error_px`` from
the point dropped and the point solved again); every 3-D point kept with the descriptors
of all its observations. :mod:`.peer` localizes against it.

Geometry: as in :class:`~landmark_localizer.index.DatabaseIndex`, the map frame ``map``
with ``z`` measured from the exploration camera's height; a ray is the camera model's
(levelled by the mount, and by the frame's own tilt where the exploration knows it),
turned into ``map`` by the image's planar camera pose.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
import json
import logging
import math
import os
from pathlib import Path
import time

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from landmark_localizer.errors import LocalizerError
from vbn_common.features import SiftConfig, extract_many
from vbn_common.geometry.camera import CameraModel, camera_from_info, pixels_per_radian
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION, compose_poses, invert_pose
from vbn_common.geometry.mount import tilted

__all__ = ['MIN_POINTS', 'PeerMap', 'PeerMapConfig', 'build_peer_map', 'load_peer_map',
           'source_key', 'world_rays']

#: Fewest triangulated points a peer map is built with (an absolute pose needs a few,
#: FLANN's index at least one).
MIN_POINTS = 10

_LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class PeerMapConfig:
    """How the peer's map is built.

    Attributes:
        neighbours: Images each image is matched with (the nearest by position).
        radius_m: Only images within this distance are matched.
        max_turn_deg: Only images whose headings differ by less (cameras that do not
            see all around; a panorama matches at any heading).
        ratio: Lowe's ratio test.
        max_error_px: Largest angular error of an observation (epipolar, then of the
            triangulated point), in pixels of the camera's focal length.
        min_angle_deg: Least angle between two rays of a triangulated track.
    """

    neighbours: int = 8
    radius_m: float = 1.0
    max_turn_deg: float = 60.0
    ratio: float = 0.8
    max_error_px: float = 2.0
    min_angle_deg: float = 1.0


@dataclass(frozen=True)
class PeerMap:
    """Triangulated SIFT tracks with every observation's descriptor.

    Attributes:
        points: (p, 3) float64 points in ``map`` (``z`` from the camera's height).
        descriptors: (d, 128) uint8 descriptors of every observation.
        point_of: (d,) int32 point of each descriptor.
        representative: (p,) int64 row of each point's most central descriptor (the
            compact map keeps only these).
        camera_info: ``(width, height, distortion_model, d, k)`` of the camera.
        camera_tilt: (3, 3) the mount's tilt (identity when level).
        camera_mount: (3,) planar pose of the camera on ``base_link``.
        sift: SIFT settings used.
        images: Exploration images the map was built from.
        source: What it was built from (:func:`source_key`: the bag's files, their sizes
            and times, the settings); a cache is used only for the same.
    """

    points: np.ndarray
    descriptors: np.ndarray
    point_of: np.ndarray
    representative: np.ndarray
    camera_info: tuple
    camera_tilt: np.ndarray
    camera_mount: np.ndarray
    sift: SiftConfig
    images: int
    source: str = ''

    @property
    def nbytes(self) -> int:
        """Bytes of the map: the points (three float32) and every descriptor (uint8)."""
        return int(12 * len(self.points) + self.descriptors.nbytes + 4 * len(self.point_of))

    @property
    def compact_nbytes(self) -> int:
        """Bytes with one descriptor per point (:attr:`representative`)."""
        return int(12 * len(self.points) + 128 * len(self.points))

    def camera(self) -> CameraModel:
        """Return the exploration's camera model, with the mount's tilt."""
        width, height, model, d, k = self.camera_info
        return tilted(camera_from_info(_Info(int(width), int(height), str(model),
                                             np.asarray(d, float), np.asarray(k, float))),
                      self.camera_tilt)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write it as one ``.npz`` file (a cache for repeated benchmarks)."""
        width, height, model, d, k = self.camera_info
        s = self.sift
        np.savez(path, points=self.points, descriptors=self.descriptors,
                 point_of=self.point_of, representative=self.representative,
                 camera=np.array([width, height], np.int64), model=np.array(model),
                 d=np.asarray(d, float), k=np.asarray(k, float),
                 camera_tilt=self.camera_tilt, camera_mount=self.camera_mount,
                 images=np.array(self.images), source=np.array(self.source),
                 sift=np.array([s.n_features, s.n_octave_layers, s.contrast_threshold,
                                s.edge_threshold, s.sigma], float))


@dataclass(frozen=True)
class _Info:
    width: int
    height: int
    distortion_model: str
    d: np.ndarray
    k: np.ndarray


def load_peer_map(path: str | os.PathLike[str]) -> PeerMap:
    """Read a map written by :meth:`PeerMap.save`."""
    with np.load(path) as data:
        s = data['sift']
        sift = SiftConfig(n_features=int(s[0]), n_octave_layers=int(s[1]),
                          contrast_threshold=float(s[2]), edge_threshold=float(s[3]),
                          sigma=float(s[4]))
        width, height = (int(v) for v in data['camera'])
        return PeerMap(data['points'], data['descriptors'], data['point_of'],
                       data['representative'],
                       (width, height, str(data['model']), data['d'], data['k']),
                       data['camera_tilt'], data['camera_mount'], sift, int(data['images']),
                       str(data['source']) if 'source' in data else '')


def source_key(bag: str | os.PathLike[str], sift: SiftConfig, config: PeerMapConfig) -> str:
    """Return what a map is built from as one string: the bag's files and the settings.

    The bag's path, each of its files' name, size and modification time, and every SIFT
    and map setting: a rebuilt bag or a changed setting makes a different key.
    """
    path = Path(bag).resolve()
    files = sorted(p for p in path.rglob('*') if p.is_file()) if path.is_dir() else [path]
    stats = [(str(p.relative_to(path)) if path.is_dir() else p.name, st.st_size,
              st.st_mtime_ns) for p in files for st in [p.stat()]]
    return json.dumps({'bag': str(path), 'files': stats, 'sift': asdict(sift),
                       'map': asdict(config)}, sort_keys=True)


def world_rays(camera_pose: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """(n, 3) directions in ``map`` of levelled optical rays seen from a planar camera pose."""
    c, s = math.cos(camera_pose[2]), math.sin(camera_pose[2])
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ BASE_TO_CAMERA_ROTATION
    return np.asarray(rays, float) @ turn.T


def _pairs(poses: np.ndarray, config: PeerMapConfig, panoramic: bool) -> np.ndarray:
    """(m, 2) image pairs ``i < j`` to match: each image's nearest neighbours."""
    tree = cKDTree(poses[:, :2])
    k = min(len(poses), 4 * config.neighbours + 1)
    dist, idx = tree.query(poses[:, :2], k=k, distance_upper_bound=config.radius_m)
    pairs = set()
    for i in range(len(poses)):
        taken = 0
        for d, j in zip(dist[i], idx[i], strict=True):
            if not np.isfinite(d) or j == i or j >= len(poses):
                continue
            turn = abs((poses[j, 2] - poses[i, 2] + math.pi) % (2 * math.pi) - math.pi)
            if not panoramic and turn > math.radians(config.max_turn_deg):
                continue
            pairs.add((min(i, int(j)), max(i, int(j))))
            taken += 1
            if taken == config.neighbours:
                break
    return np.array(sorted(pairs), np.int64).reshape(-1, 2)


def _match_pair(desc_a: np.ndarray, desc_b: np.ndarray, ratio: float,
                matcher: cv2.BFMatcher) -> np.ndarray:
    """(m, 2) mutual nearest neighbours passing the ratio test both ways."""
    if len(desc_a) < 2 or len(desc_b) < 2:
        return np.zeros((0, 2), np.int64)
    ab = matcher.knnMatch(desc_a, desc_b, k=2)
    ba = matcher.knnMatch(desc_b, desc_a, k=1)
    back = np.array([m[0].trainIdx if m else -1 for m in ba])
    out = [(m[0].queryIdx, m[0].trainIdx) for m in ab
           if len(m) == 2 and m[0].distance < ratio * m[1].distance
           and back[m[0].trainIdx] == m[0].queryIdx]
    return np.array(out, np.int64).reshape(-1, 2)


def _epipolar_ok(da: np.ndarray, db: np.ndarray, oa: np.ndarray, ob: np.ndarray,
                 threshold: float) -> np.ndarray:
    """Whether ray pairs meet the known poses' epipolar constraint (and point forward)."""
    base = ob - oa
    length = float(np.linalg.norm(base))
    if length < 1e-3:  # one position, two headings: the same direction
        return np.einsum('ij,ij->i', da, db) > math.cos(threshold)
    normal = np.cross(da, base / length)
    norm = np.linalg.norm(normal, axis=1)
    ok = np.abs(np.einsum('ij,ij->i', normal, db)) <= threshold * np.maximum(norm, 1e-9)
    # The two rays must meet in front of both cameras: a mid-point check.
    w = np.cross(da, db)
    ww = np.einsum('ij,ij->i', w, w)
    ta = np.einsum('ij,ij->i', np.cross(base[None], db), w) / np.maximum(ww, 1e-12)
    tb = np.einsum('ij,ij->i', np.cross(base[None], da), w) / np.maximum(ww, 1e-12)
    return ok & (ta > 0) & (tb > 0)


def _triangulate(track: np.ndarray, origins: np.ndarray, dirs: np.ndarray, n_tracks: int
                 ) -> np.ndarray:
    """(n_tracks, 3) mid-points of each track's rays (NaN where not solvable)."""
    projector = np.eye(3)[None] - dirs[:, :, None] * dirs[:, None, :]
    a = np.zeros((n_tracks, 3, 3))
    b = np.zeros((n_tracks, 3))
    np.add.at(a, track, projector)
    np.add.at(b, track, np.einsum('nij,nj->ni', projector, origins))
    points = np.full((n_tracks, 3), np.nan)
    ok = np.abs(np.linalg.det(a)) > 1e-9
    points[ok] = np.linalg.solve(a[ok], b[ok][:, :, None])[:, :, 0]
    return points


def _errors(points: np.ndarray, track: np.ndarray, origins: np.ndarray, dirs: np.ndarray
            ) -> np.ndarray:
    """Angle between each observation's ray and the direction to its point (inf behind)."""
    to = points[track] - origins
    dist = np.linalg.norm(to, axis=1)
    cos = np.einsum('ij,ij->i', to, dirs) / np.maximum(dist, 1e-12)
    angle = np.arccos(np.clip(cos, -1.0, 1.0))
    return np.where(np.isfinite(angle) & (cos > 0), angle, np.inf)


def build_peer_map(bag: str | os.PathLike[str], sift: SiftConfig | None = None,
                   config: PeerMapConfig = PeerMapConfig(), workers: int | None = None,
                   cache: str | os.PathLike[str] | None = None) -> PeerMap:
    """Build the peer's map from an exploration bag with known image poses.

    Args:
        bag: The exploration bag (images with poses, as ``vbn build`` reads it).
        sift: SIFT settings (the landmark database's, for a fair comparison).
        config: Matching and triangulation settings.
        workers: Processes for SIFT (default every core).
        cache: An ``.npz`` file: read when it exists and was built from the same bag
            files with the same settings (:func:`source_key`), else written after
            building.

    Raises:
        LocalizerError: The bag cannot be read, or too few tracks triangulate.
    """
    sift = sift or SiftConfig()
    source = source_key(bag, sift, config) if Path(bag).exists() else ''
    if cache is not None and Path(cache).is_file() and source:
        cached = load_peer_map(cache)
        if cached.source == source:
            _LOG.info('peer map from %s', cache)
            return cached
    from vbn_common.exploration import read_exploration

    exploration = read_exploration(bag)
    start = time.perf_counter()
    found = extract_many([f.image for f in exploration.frames], sift, workers)
    base_camera = camera_from_info(exploration.camera_info)
    mount_tilt = exploration.camera_tilt
    poses, keypoints, descriptors, origins, dirs, view_of = [], [], [], [], [], []
    for frame, features in zip(exploration.frames, found, strict=True):
        if isinstance(features, str) or len(features) == 0:
            continue
        camera = tilted(base_camera, frame.camera_tilt if frame.camera_tilt is not None
                        else mount_tilt)
        pose = np.asarray(frame.camera_pose, float)
        view_of.append(np.full(len(features), len(poses), np.int64))
        poses.append(pose)
        keypoints.append(features.keypoints)
        descriptors.append(features.descriptors)
        dirs.append(world_rays(pose, camera.unproject(features.keypoints.astype(float))))
        origins.append(np.array([pose[0], pose[1], 0.0]))
    if len(poses) < 2:
        raise LocalizerError(f'{bag}: fewer than two exploration images with features')
    poses_a = np.array(poses)
    starts = np.cumsum([0] + [len(k) for k in keypoints])
    all_desc = np.concatenate(descriptors)
    all_dirs = np.concatenate(dirs)
    all_view = np.concatenate(view_of)
    focal = pixels_per_radian(base_camera)
    threshold = config.max_error_px / focal
    pairs = _pairs(poses_a, config, base_camera.kind == 'panoramic')
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    float_desc = [d.astype(np.float32) for d in descriptors]
    rows_a, rows_b = [], []
    for i, j in pairs:
        m = _match_pair(float_desc[i], float_desc[j], config.ratio, matcher)
        if not len(m):
            continue
        ok = _epipolar_ok(dirs[i][m[:, 0]], dirs[j][m[:, 1]], origins[i], origins[j],
                          threshold)
        rows_a.append(starts[i] + m[ok, 0])
        rows_b.append(starts[j] + m[ok, 1])
    n = len(all_desc)
    a = np.concatenate(rows_a) if rows_a else np.zeros(0, np.int64)
    b = np.concatenate(rows_b) if rows_b else np.zeros(0, np.int64)
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    member = np.zeros(n, bool)
    member[a], member[b] = True, True
    rows = np.flatnonzero(member)
    # A track holding two features of one image loses that image's.
    key = label[rows] * (len(poses) + 1) + all_view[rows]
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    rows = rows[counts[inverse] == 1]
    tracks, track = np.unique(label[rows], return_inverse=True)
    ray_origins = np.array(origins)[all_view[rows]]
    ray_dirs = all_dirs[rows]
    points = _triangulate(track, ray_origins, ray_dirs, len(tracks))
    keep = _errors(points, track, ray_origins, ray_dirs) <= threshold
    rows, track, ray_origins, ray_dirs = rows[keep], track[keep], ray_origins[keep], \
        ray_dirs[keep]
    points = _triangulate(track, ray_origins, ray_dirs, len(tracks))
    keep = _errors(points, track, ray_origins, ray_dirs) <= threshold
    rows, track, ray_dirs = rows[keep], track[keep], ray_dirs[keep]
    counts = np.bincount(track, minlength=len(tracks))
    # The widest angle between a track's rays: its angle to the mean ray, doubled.
    mean = np.zeros((len(tracks), 3))
    np.add.at(mean, track, ray_dirs)
    mean /= np.maximum(np.linalg.norm(mean, axis=1, keepdims=True), 1e-12)
    spread = np.zeros(len(tracks))
    np.maximum.at(spread, track, np.arccos(np.clip(
        np.einsum('ij,ij->i', ray_dirs, mean[track]), -1.0, 1.0)))
    good = (counts >= 2) & np.all(np.isfinite(points), axis=1) & \
        (2 * spread >= math.radians(config.min_angle_deg))
    if good.sum() < MIN_POINTS:
        raise LocalizerError(f'{bag}: only {int(good.sum())} SIFT tracks triangulate from '
                             f'{len(poses)} images (the peer map needs {MIN_POINTS}): are '
                             'the images textured, and their poses right?')
    new_id = np.cumsum(good) - 1
    take = good[track]
    rows, point_of = rows[take], new_id[track[take]]
    order = np.argsort(point_of, kind='stable')
    rows, point_of = rows[order], point_of[order]
    desc = all_desc[rows]
    representative = _representatives(desc, point_of, int(good.sum()))
    first = exploration.frames[0]
    mount = compose_poses(invert_pose(np.asarray(first.base_pose, float)),
                          np.asarray(first.camera_pose, float))
    info = exploration.camera_info
    result = PeerMap(points[good], desc, point_of.astype(np.int32), representative,
                     (info.width, info.height, info.distortion_model, info.d, info.k),
                     np.eye(3) if mount_tilt is None else np.asarray(mount_tilt, float),
                     mount, sift, len(poses), source)
    _LOG.info('peer map: %d images, %d image pairs, %d points with %d descriptors, '
              '%.2f MB (%.2f MB with one descriptor per point) in %.1f s', len(poses),
              len(pairs), len(result.points), len(desc), result.nbytes / 1e6,
              result.compact_nbytes / 1e6, time.perf_counter() - start)
    if cache is not None:
        result.save(cache)
    return result


def _representatives(desc: np.ndarray, point_of: np.ndarray, n_points: int) -> np.ndarray:
    """Row of each point's descriptor nearest to its observations' mean."""
    d = desc.astype(np.float32)
    mean = np.zeros((n_points, d.shape[1]), np.float32)
    np.add.at(mean, point_of, d)
    mean /= np.maximum(np.bincount(point_of, minlength=n_points), 1)[:, None]
    dist = np.einsum('ij,ij->i', d - mean[point_of], d - mean[point_of])
    order = np.lexsort((dist, point_of))
    first = np.concatenate([[True], np.diff(point_of[order]) != 0])
    out = np.zeros(n_points, np.int64)
    out[point_of[order][first]] = order[first]
    return out

"""How a database was built: the camera of its images and the build's settings.

:class:`CameraIntrinsics` is the exploration camera (its ``CameraInfo``), checked so
that the localizer can rebuild the camera model; :class:`BuildInfo` records the
decomposition's ``k``, ``rho``, ``sigma`` and algorithm, where the image poses came
from, the SIFT settings and every builder parameter, and when the database was made.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from datetime import UTC, datetime
import math
from typing import Any

import numpy as np

from landmark_db.database.fields import (
    ArrayEquality,
    check_str,
    check_utc,
    float_array,
    int_at_least,
    json_dict,
    positive_int,
    set_field,
)
from landmark_db.errors import LandmarkDbError

__all__ = ['CAMERA_KINDS', 'POSE_SOURCES', 'BuildInfo', 'CameraIntrinsics', 'utc_now_iso']


CAMERA_KINDS = ('panoramic', 'pinhole', 'fisheye')
POSE_SOURCES = ('ground_truth', 'tf', 'estimated')


def utc_now_iso() -> str:
    """Return the current UTC time as ISO 8601 (``2026-12-01T13:22:15+00:00``)."""
    return datetime.now(UTC).isoformat(timespec='seconds')


@dataclass(frozen=True, eq=False)
class CameraIntrinsics(ArrayEquality):
    """The camera the exploration images were taken with.

    Attributes:
        kind: ``'panoramic'`` or ``'pinhole'``.
        width: image width, pixels (> 0).
        height: image height, pixels (> 0).
        K: ``(3, 3)`` float64 intrinsic matrix (as in ``sensor_msgs/CameraInfo``).
        D: ``(n,)`` float64 distortion coefficients (may be empty).
        distortion_model: name of the distortion model (``'plumb_bob'``, ``'none'``...).
        frame_id: the camera's optical frame id.
    """

    kind: str
    width: int
    height: int
    K: np.ndarray
    D: np.ndarray
    distortion_model: str
    frame_id: str

    def __post_init__(self) -> None:
        if self.kind not in CAMERA_KINDS:
            raise LandmarkDbError(
                f'camera kind must be one of {", ".join(CAMERA_KINDS)}, got {self.kind!r}')
        set_field(self, 'width', positive_int(self.width, 'camera width'))
        set_field(self, 'height', positive_int(self.height, 'camera height'))
        set_field(self, 'K', float_array(self.K, 'camera K', (3, 3)))
        set_field(self, 'D', float_array(self.D, 'camera D', (None,)))
        check_str(self.distortion_model, 'camera distortion_model')
        check_str(self.frame_id, 'camera frame_id', nonempty=True)

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-ready dict (``K`` as nested lists, ``D`` as a list)."""
        return {'kind': self.kind, 'width': self.width, 'height': self.height,
                'K': self.K.tolist(), 'D': self.D.tolist(),
                'distortion_model': self.distortion_model, 'frame_id': self.frame_id}

    @staticmethod
    def from_dict(data: Any) -> CameraIntrinsics:
        """Build from :meth:`to_dict`'s structure.

        Raises:
            LandmarkDbError: on a missing or invalid field.
        """
        if not isinstance(data, dict):
            raise LandmarkDbError('camera must be an object')
        names = [f.name for f in fields(CameraIntrinsics)]
        missing = [name for name in names if name not in data]
        if missing:
            raise LandmarkDbError(f'camera has no {missing[0]!r}')
        return CameraIntrinsics(**{name: data[name] for name in names})


@dataclass(frozen=True, eq=False)
class BuildInfo(ArrayEquality):
    """How the database was built: every parameter needed to reproduce or judge it.

    Attributes:
        k: features per landmark (>= 1).
        rho: overlap radius of the decomposition, graph steps (>= 0).
        sigma: the decomposition's sigma (>= 0, Section 5.5).
        algorithm: decomposition algorithm name (``'best'``, ``'B2'``...).
        pose_source: where the sampled poses came from: ``'ground_truth'``, ``'tf'``
            or ``'estimated'``.
        source_bag: the exploration bag (path or name as given to the builder).
        created_utc: ISO 8601 creation time, UTC (see :func:`utc_now_iso`).
        camera: the camera model and intrinsics.
        frames: frame ids, keys ``'map'``, ``'base_link'``, ``'camera'`` (str -> str).
        sift: SIFT settings (JSON-able dict).
        parameters: every other build parameter (JSON-able dict).
        decomposition_seconds: wall-clock time of the decomposition (>= 0); reported
            by the exported decomposition JSON.

    ``frames``, ``sift`` and ``parameters`` are stored as their JSON round trip (tuples
    become lists, numpy scalars Python numbers), so a database compares equal to
    itself after writing and reading.
    """

    k: int
    rho: int
    sigma: int
    algorithm: str
    pose_source: str
    source_bag: str
    created_utc: str
    camera: CameraIntrinsics
    frames: dict[str, str]
    sift: dict[str, Any]
    parameters: dict[str, Any]
    decomposition_seconds: float = 0.0

    def __post_init__(self) -> None:
        set_field(self, 'k', int_at_least(self.k, 'k', 1))
        set_field(self, 'rho', int_at_least(self.rho, 'rho', 0))
        set_field(self, 'sigma', int_at_least(self.sigma, 'sigma', 0))
        check_str(self.algorithm, 'algorithm', nonempty=True)
        if self.pose_source not in POSE_SOURCES:
            raise LandmarkDbError(f'pose_source must be one of {", ".join(POSE_SOURCES)}, '
                                  f'got {self.pose_source!r}')
        check_str(self.source_bag, 'source_bag')
        check_utc(self.created_utc)
        if not isinstance(self.camera, CameraIntrinsics):
            raise LandmarkDbError(
                f'camera must be a CameraIntrinsics, got {type(self.camera).__name__}')
        frames = json_dict(self.frames, 'frames')
        bad = [key for key, value in frames.items() if not isinstance(value, str)]
        if bad:
            raise LandmarkDbError(f'frames[{bad[0]!r}] must be a frame id string, '
                                  f'got {frames[bad[0]]!r}')
        set_field(self, 'frames', frames)
        set_field(self, 'sift', json_dict(self.sift, 'sift'))
        set_field(self, 'parameters', json_dict(self.parameters, 'parameters'))
        seconds = self.decomposition_seconds
        if (isinstance(seconds, bool) or not isinstance(seconds, (int, float, np.number))
                or not math.isfinite(seconds) or seconds < 0):
            raise LandmarkDbError(
                f'decomposition_seconds must be a non-negative number, got {seconds!r}')
        set_field(self, 'decomposition_seconds', float(seconds))

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-ready dict of every field (``camera`` as its own dict)."""
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        values['camera'] = self.camera.to_dict()
        return values

    @staticmethod
    def from_dict(data: Any) -> BuildInfo:
        """Build from :meth:`to_dict`'s structure.

        Raises:
            LandmarkDbError: on a missing or invalid field.
        """
        if not isinstance(data, dict):
            raise LandmarkDbError('build info must be an object')
        names = [f.name for f in fields(BuildInfo)]
        missing = [name for name in names if name not in data]
        if missing:
            raise LandmarkDbError(f'build parameter {missing[0]!r} is missing')
        values = {name: data[name] for name in names}
        values['camera'] = CameraIntrinsics.from_dict(data['camera'])
        return BuildInfo(**values)

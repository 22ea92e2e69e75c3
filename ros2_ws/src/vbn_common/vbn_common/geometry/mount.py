"""A camera mounted with pitch and roll: rays in the level camera frame.

The planar solvers of Chapter 7 assume a camera whose optical ``y`` axis is the world's
downward vertical. A real mount pitches or rolls the camera by a degree or two (or on
purpose, looking down at the floor ahead). The *level camera frame* ``L`` has the same
origin and the heading of the optical axis, levelled: ``z`` forward along the optical
axis projected on the floor, ``y`` straight down, ``x`` right. The mount's tilt is the
rotation ``R`` with ``ray_L = R @ ray_optical``; it comes from ``base_link -> camera``
in ``/tf_static`` (:func:`level_tilt`) and is fixed for a robot.

:class:`TiltedCamera` wraps any camera model with its tilt: ``unproject`` returns rays
in ``L`` and ``project`` takes points in ``L``, so the builder, the two-view solvers and
the localizer see a level camera and a fixed pitch or roll costs nothing.

Angles (:func:`tilt_matrix`): ``R = R_x(pitch) @ R_z(roll)`` in the optical frame, with
``pitch`` positive when the camera looks up and ``roll`` a right-handed turn about the
optical axis (the image turns clockwise as seen by the camera).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from vbn_common.errors import VbnCommonError
from vbn_common.geometry.camera import CameraInfoFields, CameraModel
from vbn_common.tf_buffer import quaternion_matrices

__all__ = ['TiltedCamera', 'level_frame', 'level_frames', 'level_tilt', 'static_mount_tilt',
           'tilt_angles',
           'tilt_matrix', 'tilted']

#: Below this tilt (degrees) a camera counts as level.
LEVEL_DEG = 1e-6


def tilt_matrix(pitch_deg: float, roll_deg: float) -> np.ndarray:
    """Return ``R = R_x(pitch) @ R_z(roll)`` (module docstring), ``ray_L = R @ ray``."""
    p, r = math.radians(pitch_deg), math.radians(roll_deg)
    cp, sp, cr, sr = math.cos(p), math.sin(p), math.cos(r), math.sin(r)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]])
    rz = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])
    return rx @ rz


def tilt_angles(tilt: np.ndarray) -> tuple[float, float]:
    """Return ``(pitch, roll)`` in degrees of a tilt from :func:`tilt_matrix`."""
    tilt = np.asarray(tilt, float).reshape(3, 3)
    # R = [[cr, -sr, 0], [cp sr, cp cr, -sp], [sp sr, sp cr, cp]].
    pitch = math.atan2(-tilt[1, 2], tilt[2, 2])
    roll = math.atan2(tilt[0, 1] * -1.0, tilt[0, 0])
    return math.degrees(pitch), math.degrees(roll)


def level_frame(forward: np.ndarray) -> np.ndarray:
    """Return the level frame's axes ``[x y z]`` (columns, in the parent's coordinates).

    Args:
        forward: ``(3,)`` the optical axis in a parent frame whose ``z`` is up, or
            ``(n, 3)`` such axes for ``(n, 3, 3)`` frames.

    Raises:
        VbnCommonError: a camera looking straight up or down.
    """
    forward = np.asarray(forward, float)
    frames = level_frames(forward.reshape(-1, 3))
    if not np.all(np.isfinite(frames)):
        raise VbnCommonError('the camera looks straight up or down: no heading')
    return frames.reshape(forward.shape[:-1] + (3, 3))


def level_frames(forward: np.ndarray) -> np.ndarray:
    """Return ``(n, 3, 3)`` level frames of ``(n, 3)`` optical axes; NaN looking up or down."""
    forward = np.asarray(forward, float).reshape(-1, 3)
    horizontal = np.hypot(forward[:, 0], forward[:, 1])
    with np.errstate(invalid='ignore', divide='ignore'):
        scale = np.where(horizontal > 1e-6, 1.0 / horizontal, np.nan)
    z = np.column_stack([forward[:, 0] * scale, forward[:, 1] * scale,
                         np.zeros(len(forward))])
    y = np.broadcast_to([0.0, 0.0, -1.0], z.shape)
    return np.stack([np.cross(y, z), y, z], axis=2)


def level_tilt(base_to_camera: np.ndarray) -> np.ndarray:
    """Return the tilt ``R`` of an optical camera frame from its rotation on a level base.

    Args:
        base_to_camera: ``(3, 3)`` the camera frame's axes in ``base_link`` (the
            rotation of ``base_link -> camera``; optical convention, ``z`` forward).
    """
    rotation = np.asarray(base_to_camera, float).reshape(3, 3)
    return level_frame(rotation[:, 2]).T @ rotation


def static_mount_tilt(transforms: Any, base_frame: str, camera_frame: str
                      ) -> np.ndarray | None:
    """Return the tilt of ``base_frame -> camera_frame`` among ``TransformStamped``s.

    ``None`` when no such transform is there or it looks straight up or down.
    """
    for t in transforms:
        if (t.header.frame_id.lstrip('/') == base_frame.lstrip('/')
                and t.child_frame_id.lstrip('/') == camera_frame.lstrip('/')):
            q = t.transform.rotation
            rotation = quaternion_matrices(np.array([q.x, q.y, q.z, q.w], float))[0]
            if not np.all(np.isfinite(rotation)):
                return None
            try:
                return level_tilt(rotation)
            except VbnCommonError:
                return None
    return None


def tilted(camera: CameraModel, tilt: Any) -> CameraModel:
    """Return ``camera`` with its tilt, or itself when the tilt is (numerically) none."""
    if tilt is None:
        return camera
    tilt = np.asarray(tilt, float).reshape(3, 3)
    angle = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(tilt) - 1.0) / 2.0))))
    return camera if angle < LEVEL_DEG else TiltedCamera(camera, tilt)


class TiltedCamera(CameraModel):
    """A camera model seen through its mount's tilt (module docstring).

    Every attribute other than the ray mappings is the wrapped camera's (``kind``,
    ``width``, ``fx``, ``camera_info()``...).

    Args:
        camera: the untilted model (its own optical frame).
        tilt: ``(3, 3)`` rotation, ``ray_L = tilt @ ray_optical``.
    """

    def __init__(self, camera: CameraModel, tilt: np.ndarray) -> None:
        tilt = np.asarray(tilt, float).reshape(3, 3)
        if not (np.all(np.isfinite(tilt)) and np.allclose(tilt @ tilt.T, np.eye(3), atol=1e-6)
                and np.linalg.det(tilt) > 0):
            raise VbnCommonError(f'a camera tilt must be a rotation, got {tilt.tolist()}')
        self.camera = camera
        self.tilt = tilt

    def __getattr__(self, name: str) -> Any:
        if name in ('camera', 'tilt'):
            raise AttributeError(name)
        return getattr(self.camera, name)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, TiltedCamera) and other.camera == self.camera and \
            np.array_equal(other.tilt, self.tilt)

    def __hash__(self) -> int:
        return hash((self.camera, self.tilt.tobytes()))

    def __repr__(self) -> str:
        pitch, roll = tilt_angles(self.tilt)
        return f'TiltedCamera({self.camera!r}, pitch={pitch:.4f} deg, roll={roll:.4f} deg)'

    @property
    def width(self) -> int:  # type: ignore[override]
        """Return the image width."""
        return self.camera.width

    @property
    def height(self) -> int:  # type: ignore[override]
        """Return the image height."""
        return self.camera.height

    @property
    def kind(self) -> str:  # type: ignore[override]
        """Return the wrapped camera's kind."""
        return self.camera.kind

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        """Return unit rays in the level camera frame."""
        return self.camera.unproject(uv) @ self.tilt.T

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project points given in the level camera frame."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        return self.camera.project(points @ self.tilt)

    def column_geometry(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Raise: a tilted camera's columns are no vertical lines."""
        raise VbnCommonError('a tilted camera has no column geometry')

    def camera_info(self) -> CameraInfoFields:
        """Return the wrapped camera's CameraInfo fields (the tilt is in ``/tf_static``)."""
        return self.camera.camera_info()

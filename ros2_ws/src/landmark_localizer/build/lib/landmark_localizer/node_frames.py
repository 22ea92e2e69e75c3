"""The localizer node's message handling: odometry, CameraInfo, and one frame.

A mixin of :class:`~landmark_localizer.node.LocalizerNode` (ROS glue): the callbacks
that file odometry and check the CameraInfo (executor thread), and the processing of one
image (worker thread): stamps checked, decoded, checked against the camera, given with
the odometry of its stamp to ``Localizer.step``, the estimate published with
``map -> odom`` (REP 105: the correction that makes ``map -> odom -> base_link`` the
estimate).
"""
from __future__ import annotations

import time
from typing import Any

import numpy as np
from std_msgs.msg import Int32

from landmark_localizer import conversions
from landmark_localizer.camera_check import frame_camera
from landmark_localizer.errors import LocalizerError
from landmark_localizer.localizer import Frame
from landmark_localizer.node_support import reason_kind
from landmark_localizer.odometry import ACCEPTED, JUMP, TIME_BACK
from vbn_common import names
from vbn_common.geometry.mount import static_mount_tilt, tilt_angles
from vbn_common.geometry.transforms import StampedTransform, correction
from vbn_common.images import ImageDecodeError, decode_image

__all__ = ['CAMERA_INFO_GRACE_S', 'ODOM_MAX_EXTRAPOLATION_S', 'ODOM_WAIT_S', 'RESET_BACK_NS',
           'FrameHandling']

#: A stamp this far back or further is a new run of time (a looping bag): reset.
RESET_BACK_NS = 1_000_000_000
#: An image newer than the newest odometry waits at most this long for the odometry of
#: its stamp (which arrives on another topic, often a moment later), as tf2's message
#: filter waits for a transform.
ODOM_WAIT_S = 0.1
#: Odometry is extrapolated at most this far past its newest message.
ODOM_MAX_EXTRAPOLATION_S = 0.1
#: Seconds of images without any CameraInfo before the node says it uses the database's
#: camera (CameraInfo and the first image arrive in either order).
CAMERA_INFO_GRACE_S = 2.0


class FrameHandling:
    """Odometry, CameraInfo and frames of :class:`~landmark_localizer.node.LocalizerNode`."""

    def _on_odom(self, msg: Any) -> None:
        odom = self.topic(names.ODOM)
        frames = (msg.header.frame_id, msg.child_frame_id)
        wanted = (self.settings.odom_frame_id, self.settings.base_frame_id)
        if any(got and got != want for got, want in zip(frames, wanted, strict=True)):
            self.warnings.warn('odom_frames', f'{odom} is {frames[0]} -> {frames[1]}, '
                               f'expected {wanted[0]} -> {wanted[1]}: ignored')
            return
        try:
            stamp, pose = conversions.odometry_pose(msg)
        except LocalizerError as error:
            stamp, pose = conversions.stamp_to_ns(msg.header.stamp), np.full(3, np.nan)
            self.warnings.warn('odom_bad', f'{odom}: {error}: ignored, odometry history '
                               'restarted')
        with self.lock:
            result = self.odometry.add(stamp, pose)
            if result != ACCEPTED:
                self.odom_restarted = True
            self.odom_arrived.notify_all()
        if result == JUMP:
            self.warnings.warn('odom_jump', f'{odom} jumped by more than '
                               f'{self.settings.odom_max_jump_m:g} m: odometry history '
                               'restarted')
        elif result == TIME_BACK:
            self.warnings.warn('odom_back', f'{odom} stamps went back: odometry history '
                               'restarted')

    def _on_tf_static(self, msg: Any) -> None:
        """Take the camera's mount from ``base_link -> camera`` (its pitch and roll)."""
        loaded = self.loaded
        if loaded is None:
            return
        frames = loaded.index.database.info.frames
        tilt = static_mount_tilt(msg.transforms, frames.get('base', names.BASE_FRAME),
                                 frames.get('camera', names.CAMERA_FRAME))
        if tilt is None:
            return
        with self.lock:
            before = self.mount_tilt
            if before is not None and np.allclose(tilt, before, atol=1e-9):
                return
            self.mount_tilt = tilt
            self.camera_key = None      # the next CameraInfo makes the frames' camera
        pitch, roll = tilt_angles(tilt)
        if before is None:
            self.log.info(f'camera mount from {self.topic(names.TF_STATIC)}: pitch '
                          f'{pitch:.2f} deg, roll {roll:.2f} deg')
            return
        # A static transform that changes mid-run: a remounted camera or a wrong
        # publisher; the frames from now on are levelled with the new one.
        was = [round(v, 2) + 0.0 for v in tilt_angles(before)]  # no "-0.00"
        now = [round(v, 2) + 0.0 for v in (pitch, roll)]
        self.log.warning(f'the camera mount in {self.topic(names.TF_STATIC)} changed while '
                         f'running: pitch {was[0]:.2f} -> {now[0]:.2f} deg, roll {was[1]:.2f} '
                         f'-> {now[1]:.2f} deg; the next frames are levelled with the new one')

    def _on_camera_info(self, msg: Any) -> None:
        loaded = self.loaded
        if loaded is None:
            return
        # Bytes, so that a NaN equals itself and an unchanged CameraInfo is one check.
        key = (int(msg.width), int(msg.height), str(msg.distortion_model),
               np.asarray(msg.k, float).tobytes(), np.asarray(msg.d, float).tobytes())
        with self.lock:
            self.camera_info_seen = True
            if key == self.camera_key:
                return
            changed = self.camera_key is not None
            self.camera_key = key
            camera, problem = frame_camera(msg, loaded.index.camera, self.mount_tilt)
            was = self.camera_problem
            self.camera_problem = problem
            if camera is not None:   # the frames' own camera (another resolution, say)
                loaded.index.frame_camera = camera
        if camera is not None and camera is not loaded.index.camera:
            base = loaded.index.camera
            self.log.info(f'CameraInfo {camera.width}x{camera.height} {camera.kind} differs '
                          f'from the database camera {base.width}x{base.height}: frames are '
                          'read with their own calibration')
        if problem:
            prefix = 'CameraInfo changed: ' if changed else ''
            self.warnings.warn('camera:' + reason_kind(problem),
                               f'{prefix}{problem}: frames are dropped until it matches')
        elif was:
            self.log.info('CameraInfo fits the database camera again: frames resume')

    def _process_frame(self, msg: Any, start: float) -> None:
        loaded = self.loaded
        if loaded is None:
            return
        camera = loaded.index.frame_camera
        stamp = conversions.stamp_to_ns(msg.header.stamp)
        if self.last_stamp is not None and stamp <= self.last_stamp:
            back = self.last_stamp - stamp
            if back == 0:
                self.stats.drop('repeated_stamp')  # the same frame on both topics
                return
            if back < RESET_BACK_NS:
                self._drop('stamp_went_back', f'stamp {stamp * 1e-9:.3f} s is '
                           f"{back * 1e-9:.3f} s older than the last frame's")
                return
            self.log.warning(f'time went back by {back * 1e-9:.1f} s (a bag that '
                             'loops?): state reset, voting again')
            with self.lock:
                self.transform = None
        with self.lock:
            problem, seen = self.camera_problem, self.camera_info_seen
            restarted, self.odom_restarted = self.odom_restarted, False
        if problem:
            self.stats.drop('camera_info')  # said once when the CameraInfo came
            return
        if self.first_image is None:
            self.first_image = start
        if not seen and start - self.first_image >= CAMERA_INFO_GRACE_S:
            self.warnings.warn('no_camera_info',
                               f'no CameraInfo on {self.topic(names.CAMERA_INFO)}: '
                               f'assuming the database camera {camera.width}x'
                               f'{camera.height} {camera.kind}')
        try:
            image = decode_image(msg)
        except ImageDecodeError as error:
            self._drop('decode', str(error))
            return
        shape = (camera.height, camera.width)
        if image.shape != shape:
            whose = 'the database camera' if camera is loaded.index.camera else \
                'its CameraInfo'
            self._drop('size', f'image is {image.shape[1]}x{image.shape[0]}, {whose} '
                       f'{shape[1]}x{shape[0]}')
            return
        odom = self._odometry_at(stamp)
        self.last_stamp = stamp
        with self.localizer_lock:
            if loaded is not self.loaded:
                return          # the database was reloaded meanwhile: the next frame
            if restarted:
                loaded.localizer.reset_motion()
            estimate = loaded.localizer.step(Frame(stamp, image, odom))
        self.estimate = estimate
        self.stats.processed += 1
        self._publish_estimate(estimate, odom)
        self.stats.add_latency(time.perf_counter() - start)

    def _odometry_at(self, stamp: int) -> np.ndarray | None:
        def arrived() -> bool:
            latest = self.odometry.latest_stamp
            return latest is None or latest >= stamp

        with self.odom_arrived:
            latest = self.odometry.latest_stamp
            if latest is not None and 0 < stamp - latest <= ODOM_MAX_EXTRAPOLATION_S * 1e9:
                self.odom_arrived.wait_for(arrived, timeout=ODOM_WAIT_S)
            return self.odometry.at(stamp)

    def _publish_estimate(self, estimate: Any, odom: np.ndarray | None) -> None:
        if not self.active:
            return
        s = self.settings
        self.region_pub.publish(Int32(data=int(estimate.region)))
        messages = conversions.pose_messages(estimate, s.global_frame_id)
        if messages is None:
            return
        self.pose_pub.publish(messages[0])
        self.pose_cov_pub.publish(messages[1])
        self.stats.poses += 1
        tf = self.tf
        if odom is None or tf is None or not s.tf_broadcast:
            return
        stamp = estimate.stamp_ns
        x, y, yaw = (float(v) for v in estimate.pose)
        map_to_base = StampedTransform.planar(stamp, s.global_frame_id, s.base_frame_id,
                                              x, y, yaw)
        odom_to_base = StampedTransform.planar(stamp, s.odom_frame_id, s.base_frame_id,
                                               *(float(v) for v in odom))
        transform = correction(map_to_base, odom_to_base,
                               stamp + int(s.transform_tolerance * 1e9))
        with self.lock:
            self.transform = transform
        tf.send(transform)

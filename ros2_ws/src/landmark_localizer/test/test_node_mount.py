"""The localizer node takes its camera's mount from /tf_static (node_frames.py)."""
from __future__ import annotations

import threading
import types

import numpy as np
import pytest

from landmark_localizer.node_frames import FrameHandling
from vbn_common.bags import messages
from vbn_common.geometry.mount import tilt_matrix


def _node(lines: list[str], warnings: list[str] | None = None) -> types.SimpleNamespace:
    info = types.SimpleNamespace(frames={'base': 'base_link', 'camera': 'camera'})
    return types.SimpleNamespace(
        loaded=types.SimpleNamespace(index=types.SimpleNamespace(
            database=types.SimpleNamespace(info=info))),
        lock=threading.Lock(), mount_tilt=None, camera_key=('seen',),
        log=types.SimpleNamespace(info=lines.append,
                                  warning=(warnings if warnings is not None else lines).append),
        topic=lambda name: name)


def test_a_pitched_mount_in_tf_static_becomes_the_frames_tilt() -> None:
    lines: list[str] = []
    node = _node(lines)
    pitched = messages.tf_message([messages.camera_static_transform(0, 1.2,
                                                                    tilt_matrix(2.0, -1.0))])
    FrameHandling._on_tf_static(node, pitched)
    assert node.mount_tilt == pytest.approx(tilt_matrix(2.0, -1.0), abs=1e-9)
    assert node.camera_key is None        # the next CameraInfo makes the frames' camera
    assert lines == ['camera mount from /tf_static: pitch 2.00 deg, roll -1.00 deg']
    # The same again: nothing to do; another robot's transform: ignored.
    node.camera_key = ('seen',)
    FrameHandling._on_tf_static(node, pitched)
    other = messages.tf_message([messages.transform(0, 'base_link', 'lidar', (0, 0, 1),
                                                    (0.0, 0.0, 0.0, 1.0))])
    FrameHandling._on_tf_static(node, other)
    assert node.camera_key == ('seen',) and len(lines) == 1
    level = messages.tf_message([messages.camera_static_transform(0, 1.2)])
    FrameHandling._on_tf_static(node, level)
    assert node.mount_tilt == pytest.approx(np.eye(3), abs=1e-9) and len(lines) == 2


def test_a_mount_that_changes_mid_run_is_one_warning_and_taken() -> None:
    lines: list[str] = []
    warnings: list[str] = []
    node = _node(lines, warnings)
    first = messages.tf_message([messages.camera_static_transform(0, 1.2,
                                                                  tilt_matrix(1.0, 0.0))])
    FrameHandling._on_tf_static(node, first)
    assert len(lines) == 1 and warnings == []
    node.camera_key = ('seen',)
    second = messages.tf_message([messages.camera_static_transform(0, 1.2,
                                                                   tilt_matrix(3.0, 0.5))])
    FrameHandling._on_tf_static(node, second)
    assert warnings == ['the camera mount in /tf_static changed while running: pitch 1.00 '
                        '-> 3.00 deg, roll 0.00 -> 0.50 deg; the next frames are levelled '
                        'with the new one']
    assert node.mount_tilt == pytest.approx(tilt_matrix(3.0, 0.5), abs=1e-9)
    assert node.camera_key is None and len(lines) == 1
    FrameHandling._on_tf_static(node, second)            # repeated (transient local): quiet
    assert len(warnings) == 1

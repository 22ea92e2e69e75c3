"""Renderer of a scene's extruded walls through a panoramic or pinhole camera (issue 4).

Core modules (no rclpy, no message types): :mod:`.camera` (the two camera models
and their ``CameraInfo`` convention), :mod:`.frames` (``map``, ``base_link``,
``camera``), :mod:`.textures` (wall textures), :mod:`.renderer` (ray casting,
texture sampling, ground truth) and :mod:`.effects` (per-frame noise, blur,
exposure).
"""
from __future__ import annotations

from visibility_builder.render.camera import (
    CameraInfoFields,
    CameraModel,
    PanoramicCamera,
    PinholeCamera,
    make_camera,
)
from visibility_builder.render.effects import ImageEffects, apply_effects
from visibility_builder.render.renderer import Renderer, Rendering, cast_rays
from visibility_builder.render.textures import WallAtlas, build_wall_atlas

__all__ = [
    'CameraInfoFields',
    'CameraModel',
    'ImageEffects',
    'PanoramicCamera',
    'PinholeCamera',
    'Renderer',
    'Rendering',
    'WallAtlas',
    'apply_effects',
    'build_wall_atlas',
    'cast_rays',
    'make_camera',
]

"""Renderer of a scene's extruded walls through a panoramic or pinhole camera.

Core modules (no rclpy, no message types): :mod:`.textures` (wall textures),
:mod:`.renderer` (ray casting, texture sampling, ground truth) and :mod:`.effects`
(per-frame noise, blur, exposure). The camera models and frames it renders through
are shared with the builder and the localizer: :mod:`vbn_common.geometry`.
"""
from __future__ import annotations

from vbn_worlds.render.effects import ImageEffects, apply_effects
from vbn_worlds.render.renderer import Occluders, Renderer, Rendering, cast_rays
from vbn_worlds.render.textures import Appearance, WallAtlas, build_wall_atlas

__all__ = [
    'Appearance',
    'ImageEffects',
    'Occluders',
    'Renderer',
    'Rendering',
    'WallAtlas',
    'apply_effects',
    'build_wall_atlas',
    'cast_rays',
]

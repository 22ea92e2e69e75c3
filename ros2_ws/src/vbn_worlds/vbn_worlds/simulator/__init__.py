"""The synthetic world simulator of Chapter 8 (Sections 8.1 and 8.2).

Random polygon worlds per experiment setting (:mod:`.settings`, :mod:`.scene_sampler`),
their pose grid (:mod:`.grid`), the vectorised feature visibility
(:mod:`.visibility`) and the composition into a world instance (:mod:`.simulate`).
"""
from __future__ import annotations

from vbn_worlds.simulator.grid import pose_grid
from vbn_worlds.simulator.scene_sampler import random_scene
from vbn_worlds.simulator.settings import SETTINGS, WorldSetting, get_setting, small_setting
from vbn_worlds.simulator.visibility import compute_visibility

__all__ = ['SETTINGS', 'WorldSetting', 'compute_visibility', 'get_setting', 'pose_grid',
           'random_scene', 'small_setting']

"""Render speed benchmark (``pytest -m bench -s``): prints the time per image."""
from __future__ import annotations

import time

import numpy as np
import pytest

from landmark_db.scenes import resolve_scene
from vbn_common.geometry.camera import make_camera
from vbn_worlds.render.renderer import Renderer


@pytest.mark.bench
@pytest.mark.parametrize('scene_name', ['room', 'floor'])
@pytest.mark.parametrize('camera, size', [('panoramic', (1024, 256)), ('pinhole', (640, 480))])
def test_bench_render(scene_name, camera, size):
    scene = resolve_scene(scene_name)
    renderer = Renderer(scene, make_camera(camera, *size))
    xmin, ymin, xmax, ymax = scene.bounds()
    rng = np.random.default_rng(0)
    poses = []
    while len(poses) < 50:
        p = np.array([rng.uniform(xmin, xmax), rng.uniform(ymin, ymax), rng.uniform(-3, 3)])
        if scene.free_space(p[None, :2])[0]:
            poses.append(p)
    for encoding in ('bgr8', 'mono8'):
        renderer.render(poses[0], encoding=encoding)
        times = []
        for pose in poses:
            start = time.perf_counter()
            renderer.render(pose, encoding=encoding)
            times.append(time.perf_counter() - start)
        ms = 1000 * np.array(times)
        print(f'\n{scene_name} {camera} {size[0]}x{size[1]} {encoding}: '
              f'median {np.median(ms):.1f} ms, p95 {np.percentile(ms, 95):.1f} ms '
              f'over {len(ms)} poses')
        assert np.median(ms) > 0

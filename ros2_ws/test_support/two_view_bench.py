"""Median pose error of each two-view method against pixel noise (docs/localization.md).

Each trial: two model views about 1 m apart with known poses and a current view near
them, 50 scene points on the room's walls seen by all three, Gaussian pixel noise on
every view, inlier threshold ``max(1.5, 3 noise)`` pixels; each method estimates the
motion from both model views and the rays are intersected
(:func:`position_from_two_views`). Reported: the median position error
(mm), the median heading error (degrees), failures (errors raised), and the median
CPU time of one two-view solve (ms, single-threaded). Run::

    python ros2_ws/test_support/two_view_bench.py            # 200 trials (a few minutes)
    pytest -m bench -s ros2_ws/src/vbn_common/test/test_two_view_bench.py
"""
from __future__ import annotations

import os

# Before numpy loads: OpenBLAS threads only contend on these small matrices (a
# two-view solve runs 5 to 100 times slower with them on a loaded 2-core machine).
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
os.environ.setdefault('OMP_NUM_THREADS', '1')

import dataclasses  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from two_view_samples import random_pose_near, render_views  # noqa: E402

from vbn_common.errors import VbnCommonError  # noqa: E402
from vbn_common.geometry import (  # noqa: E402
    compose_poses,
    invert_pose,
    make_camera,
    wrap_angle,
)
from vbn_common.geometry.linear_combination import linear_combination_of_views  # noqa: E402
from vbn_common.geometry.localize import position_from_two_views  # noqa: E402
from vbn_common.geometry.motion import TwoViewConfig  # noqa: E402
from vbn_common.geometry.two_view import relative_motion  # noqa: E402

NOISES = (0.0, 0.5, 1.0, 2.0)
# ':raw' is the method as the thesis gives it, without the Gauss-Newton polish.
PANORAMIC_METHODS = ('panoramic_planar', 'panoramic_planar:raw', 'pinhole_planar',
                     'pinhole_planar:raw', 'general_essential')
PINHOLE_METHODS = ('pinhole_planar', 'pinhole_planar:raw', 'general_essential',
                   'linear_combination')


def _panoramic_trial(rng: np.random.Generator) -> np.ndarray:
    a = np.array([rng.uniform(1.0, 5.0), rng.uniform(0.7, 2.3), 0.0])
    angle = rng.uniform(-math.pi, math.pi)
    b = a + np.array([math.cos(angle), math.sin(angle), 0.0])
    b[:2] = np.clip(b[:2], [0.4, 0.4], [5.6, 2.6])
    mid = np.array([(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, 0.0])
    current = random_pose_near(rng, mid, 0.5, math.pi)
    return np.stack([a, b, current])


def _pinhole_trial(rng: np.random.Generator) -> np.ndarray:
    # Look along the room from near one end (the far wall and both side walls in view:
    # a scene on one plane is degenerate for the essential matrix), views turned 20 deg.
    facing = float(rng.choice([0.0, math.pi]))
    x = rng.uniform(0.8, 1.6) if facing == 0.0 else rng.uniform(4.4, 5.2)
    y = rng.uniform(1.0, 2.0)
    forward = math.cos(facing)
    a = np.array([x, y - 0.4, facing + math.radians(10)])
    b = np.array([x + 0.2 * forward, y + 0.4, facing - math.radians(10)])
    current = random_pose_near(rng, np.array([x + 0.3 * forward, y, facing]), 0.4,
                               math.radians(15))
    return np.stack([a, b, current])


def _solve(method: str, camera, views, config: TwoViewConfig) -> tuple[object, object, float]:
    start = time.process_time()
    if method == 'linear_combination':
        rays = [camera.unproject(views.uv[k]) for k in range(3)]
        pose_b_in_a = compose_poses(invert_pose(views.poses[0]), views.poses[1])
        motion_a, motion_b = linear_combination_of_views(rays[0], rays[1], rays[2],
                                                         pose_b_in_a, rng=0,
                                                         threshold=3 * config.threshold_px
                                                         / camera.fx)
        elapsed = time.process_time() - start
        return motion_a, motion_b, elapsed
    if method.endswith(':raw'):
        method, config = method[:-4], dataclasses.replace(config, refine=False)
    motion_a = relative_motion(views.uv[0], views.uv[2], camera, method=method,
                               config=config, rng=0)
    elapsed = time.process_time() - start
    motion_b = relative_motion(views.uv[1], views.uv[2], camera, method=method,
                               config=config, rng=0)
    return motion_a, motion_b, elapsed


def run(trials: int = 200, seed: int = 7, n_points: int = 50) -> list[dict]:
    """Return one row per (camera, method, noise) with median errors and times."""
    rows = []
    for kind, methods, make_poses in (('panoramic', PANORAMIC_METHODS, _panoramic_trial),
                                      ('pinhole', PINHOLE_METHODS, _pinhole_trial)):
        camera = make_camera(kind)
        for noise in NOISES:
            rng = np.random.default_rng(seed)
            scenes = []
            for _ in range(trials):
                poses = make_poses(rng)
                scenes.append(render_views(camera, poses, rng, n=n_points, noise_px=noise))
            # The inlier threshold follows the noise, as a user would set it.
            config = TwoViewConfig(threshold_px=max(1.5, 3.0 * noise))
            for method in methods:
                pos_err, yaw_err, times, failures = [], [], [], 0
                for views in scenes:
                    try:
                        motion_a, motion_b, elapsed = _solve(method, camera, views, config)
                        est = position_from_two_views(views.poses[0], motion_a,
                                                      views.poses[1], motion_b)
                    except VbnCommonError:
                        failures += 1
                        continue
                    truth = views.poses[2]
                    pos_err.append(math.hypot(est.x - truth[0], est.y - truth[1]))
                    yaw_err.append(abs(float(wrap_angle(est.yaw - truth[2]))))
                    times.append(elapsed)
                rows.append({
                    'camera': kind, 'method': method, 'noise_px': noise,
                    'position_mm': 1e3 * float(np.median(pos_err)) if pos_err else math.nan,
                    'heading_deg': math.degrees(float(np.median(yaw_err))) if yaw_err
                    else math.nan,
                    'failures': failures, 'trials': trials,
                    'ms': 1e3 * float(np.median(times)) if times else math.nan,
                    'ms95': 1e3 * float(np.percentile(times, 95)) if times else math.nan,
                })
    return rows


def table(rows: list[dict]) -> str:
    """Return the rows as a Markdown table (one line per camera and method)."""
    lines = ['| camera | method | ' + ' | '.join(f'{n:g} px' for n in NOISES)
             + ' | failures | CPU ms per solve (median / p95) |',
             '|---|---|' + '---|' * len(NOISES) + '---|---|']
    keys = sorted({(r['camera'], r['method']) for r in rows},
                  key=lambda k: (k[0] != 'panoramic', k[1]))
    for camera, method in keys:
        mine = [r for r in rows if r['camera'] == camera and r['method'] == method]
        cells = [f"{r['position_mm']:.1f} mm / {r['heading_deg']:.3f} deg" for r in mine]
        failures = '/'.join(str(r['failures']) for r in mine)
        ms = max(r['ms'] for r in mine)
        ms95 = max(r['ms95'] for r in mine)
        lines.append(f'| {camera} | {method} | ' + ' | '.join(cells)
                     + f' | {failures} | {ms:.1f} / {ms95:.1f} |')
    return '\n'.join(lines)


def full_pose_times(trials: int = 100, seed: int = 1) -> str:
    """Return a Markdown table of the CPU time of a full pose (two solves, intersection).

    50 points, 20 % outliers, 0.5 px noise: the localizer's tracking case.
    """
    lines = ['| camera | method | median ms | p95 ms |', '|---|---|---|---|']
    config = TwoViewConfig()
    for kind, methods, make_poses in (('panoramic', PANORAMIC_METHODS, _panoramic_trial),
                                      ('pinhole', PINHOLE_METHODS, _pinhole_trial)):
        camera = make_camera(kind)
        rng = np.random.default_rng(seed)
        scenes = [render_views(camera, make_poses(rng), rng, n=50, noise_px=0.5, outliers=0.2)
                  for _ in range(trials)]
        for method in (m for m in methods if not m.endswith(':raw')):
            times = []
            for views in scenes:
                start = time.process_time()
                try:
                    motion_a, motion_b, _ = _solve(method, camera, views, config)
                    position_from_two_views(views.poses[0], motion_a, views.poses[1], motion_b)
                except VbnCommonError:
                    pass
                times.append(time.process_time() - start)
            lines.append(f'| {kind} | {method} | {1e3 * np.median(times):.1f} | '
                         f'{1e3 * np.percentile(times, 95):.1f} |')
    return '\n'.join(lines)


if __name__ == '__main__':
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 200
    print(table(run(trials=count)))
    print()
    print(full_pose_times(trials=max(count // 2, 1)))

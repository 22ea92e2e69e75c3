"""The two-view pose solvers on the sample bags' real images (docs/localization.md).

Exploration panoramas (``bags/room_exploration``, 25 cm grid) serve as model views
of known pose; the current view is another exploration panorama, or a frame of
``bags/room_run`` (another trajectory, exposure changes, JPEG 80). SIFT features
(the builder's :class:`~vbn_common.features.SiftConfig`) are matched with
Lowe's ratio test (0.8) and a mutual check; every match of a model view with the
current view is used. Each method estimates the motion from both model views and
the rays are intersected; the errors are against ``/ground_truth/pose``. Run::

    python ros2_ws/test_support/two_view_real_bags.py
"""
from __future__ import annotations

import os

# Before numpy loads: OpenBLAS threads only contend on these small matrices (a
# two-view solve runs 5 to 100 times slower with them on a loaded 2-core machine).
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
os.environ.setdefault('OMP_NUM_THREADS', '1')

import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from vbn_common.errors import VbnCommonError  # noqa: E402
from vbn_common.exploration import read_exploration  # noqa: E402
from vbn_common.features import extract_features  # noqa: E402
from vbn_common.geometry import camera_from_info, wrap_angle  # noqa: E402
from vbn_common.geometry.localize import position_from_two_views  # noqa: E402
from vbn_common.geometry.motion import TwoViewConfig  # noqa: E402
from vbn_common.geometry.two_view import relative_motion  # noqa: E402
from vbn_common.images import decode_image  # noqa: E402

# ':raw' is the method as the thesis gives it, without the Gauss-Newton polish.
METHODS = ('panoramic_planar', 'panoramic_planar:raw', 'pinhole_planar', 'general_essential')


class _Features:
    """SIFT features per frame, computed once."""

    def __init__(self, exploration) -> None:
        self.exploration = exploration
        self.cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def __call__(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        if index not in self.cache:
            image = decode_image(self.exploration.frames[index].image)
            feats = extract_features(image)
            self.cache[index] = (feats.keypoints.astype(float),
                                 feats.descriptors.astype(np.float32))
        return self.cache[index]


def match(desc_a: np.ndarray, desc_b: np.ndarray, ratio: float = 0.8) -> np.ndarray:
    """Return ``(m, 2)`` index pairs: ratio test both ways and mutual nearest neighbours."""
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    forward = matcher.knnMatch(desc_a, desc_b, k=2)
    backward = matcher.knnMatch(desc_b, desc_a, k=1)
    best_back = {m[0].queryIdx: m[0].trainIdx for m in backward if m}
    pairs = [(m[0].queryIdx, m[0].trainIdx) for m in forward
             if len(m) == 2 and m[0].distance < ratio * m[1].distance
             and best_back.get(m[0].trainIdx) == m[0].queryIdx]
    return np.array(pairs, dtype=int).reshape(-1, 2)


def solve(camera, feats_model, feats_current, method: str):
    """Return the motion to the current view, the match count and the solve's CPU time."""
    pairs = match(feats_model[1], feats_current[1])
    uv_model, uv_current = feats_model[0][pairs[:, 0]], feats_current[0][pairs[:, 1]]
    config = TwoViewConfig(refine=not method.endswith(':raw'))
    start = time.process_time()
    motion = relative_motion(uv_model, uv_current, camera, method=method.split(':')[0],
                             config=config, rng=0)
    return motion, len(pairs), time.process_time() - start


def _triplets(model_poses: np.ndarray, rng: np.random.Generator, count: int,
              current_poses: np.ndarray | None = None) -> list[tuple[int, int, int]]:
    """Model views ~1 m apart and a current view near them (between, off their line)."""
    xy = model_poses[:, :2]
    out: list[tuple[int, int, int]] = []
    tries = 0
    while len(out) < count and tries < 100 * count:
        tries += 1
        if current_poses is None:
            c = int(rng.integers(len(xy)))
            here = xy[c]
        else:
            c = int(rng.integers(len(current_poses)))
            here = current_poses[c, :2]
        d = np.linalg.norm(xy - here, axis=1)
        near = np.flatnonzero((d > 0.2) & (d < 0.8))
        if len(near) < 2:
            continue
        a = int(rng.choice(near))
        partners = near[(np.abs(np.linalg.norm(xy[near] - xy[a], axis=1) - 1.0) < 0.15)]
        if not len(partners):
            continue
        # the partner whose ray to the current view makes the largest angle with a's
        ray_a = (here - xy[a]) / np.linalg.norm(here - xy[a])
        rays = (here - xy[partners]) / np.linalg.norm(here - xy[partners], axis=1)[:, None]
        sines = np.abs(ray_a[0] * rays[:, 1] - ray_a[1] * rays[:, 0])
        b = int(partners[int(np.argmax(sines))])
        if sines.max() < math.sin(math.radians(20)):
            continue
        out.append((a, b, c))
    return out


def evaluate(model_bag: str, current_bag: str | None, count: int, seed: int = 3) -> dict:
    """Return per-method position errors (m), heading errors (rad), times (s), failures."""
    models = read_exploration(model_bag)
    camera = camera_from_info(models.camera_info)
    model_poses = models.camera_poses()
    model_feats = _Features(models)
    if current_bag is None:
        currents, current_poses, current_feats = models, model_poses, model_feats
        triplets = _triplets(model_poses, np.random.default_rng(seed), count)
    else:
        currents = read_exploration(current_bag)
        current_poses = currents.camera_poses()
        current_feats = _Features(currents)
        triplets = _triplets(model_poses, np.random.default_rng(seed), count, current_poses)
    results = {m: {'position': [], 'heading': [], 'seconds': [], 'failures': 0,
                   'matches': [], 'inliers': []} for m in METHODS}
    for a, b, c in triplets:
        truth = current_poses[c]
        for method in METHODS:
            row = results[method]
            try:
                motion_a, n_a, seconds = solve(camera, model_feats(a), current_feats(c),
                                               method)
                row['seconds'].append(seconds)
                motion_b, n_b, _ = solve(camera, model_feats(b), current_feats(c), method)
                est = position_from_two_views(model_poses[a], motion_a, model_poses[b],
                                              motion_b)
            except VbnCommonError as exc:
                row['failures'] += 1
                print(f'  {method} {a} {b} {c}: {exc}', file=sys.stderr)
                continue
            row['position'].append(math.hypot(est.x - truth[0], est.y - truth[1]))
            row['heading'].append(abs(float(wrap_angle(est.yaw - truth[2]))))
            row['matches'] += [n_a, n_b]
            row['inliers'] += [int(motion_a.inliers.sum()), int(motion_b.inliers.sum())]
    return {'triplets': len(triplets), 'results': results}


def report(title: str, out: dict) -> str:
    """Return a Markdown table of one evaluation."""
    lines = [f'{title} ({out["triplets"]} triplets)', '',
             '| method | median position error | 90th pct | median heading error | '
             'failures | matches / inliers (median) | CPU ms per solve (median) |',
             '|---|---|---|---|---|---|---|']
    for method, row in out['results'].items():
        if not row['position']:
            lines.append(f'| {method} | - | - | - | {row["failures"]} | - | - |')
            continue
        pos = np.array(row['position']) * 1e3
        lines.append(
            f'| {method} | {np.median(pos):.1f} mm | {np.percentile(pos, 90):.1f} mm | '
            f'{math.degrees(float(np.median(row["heading"]))):.3f} deg | {row["failures"]} | '
            f'{int(np.median(row["matches"]))} / {int(np.median(row["inliers"]))} | '
            f'{1e3 * float(np.median(row["seconds"])):.1f} |')
    return '\n'.join(lines)


if __name__ == '__main__':
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 40
    print(report('room_exploration: current = another exploration panorama',
                 evaluate('bags/room_exploration', None, count)))
    print()
    print(report('room_run: current = a run frame, models = exploration panoramas',
                 evaluate('bags/room_exploration', 'bags/room_run', count)))

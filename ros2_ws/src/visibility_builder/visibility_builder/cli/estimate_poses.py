"""``vbn estimate-poses BAGDIR --out OUTBAG``: image poses from the images and the odometry.

Example::

    vbn render --scene room --kind exploration --odometry --out out/room_driven
    vbn estimate-poses out/room_driven --out out/room_estimated
    vbn build out/room_estimated --db out/room_estimated.db --set read.pose_source=estimated

Reads the exploration's images, camera info and odometry (``odom -> base_link`` on
``/tf``), estimates every image's pose by thesis Section 6.1
(:mod:`visibility_builder.estimation.pipeline`) and writes a copy of the bag with
``/estimated/pose`` added. Prints the pairs tried, kept and refused (with why), the
time of each step and, when the bag has ``/ground_truth/pose``, the accuracy of the
odometry, of the thesis's own result (directions alone, scaled by the odometry's path),
of the joint solve with the odometry, of the unrefined result and of the result after the
bundle adjustment (:mod:`visibility_builder.estimation.refinement`), each after an SE(2)
alignment. The scale is the odometry's, its wheels calibrated by the images' turns
(:mod:`visibility_builder.estimation.scale`; ``--no-wheel-calibration`` keeps it as it
is). ``--known-distance I J METRES`` takes the scale from a distance measured between
two images' places instead. ``--report DIR`` draws the view graph and the odometry's
trajectory against the estimate (:mod:`visibility_builder.estimation.report`).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
import sys
from typing import Any

__all__ = ['register', 'run']


def register(subparsers: Any) -> None:
    """Add the ``estimate-poses`` subcommand."""
    parser = subparsers.add_parser(
        'estimate-poses', help="estimate the exploration images' poses (thesis 6.1)",
        description="Estimate every exploration image's pose from the images and the "
                    'odometry (thesis Section 6.1: pairwise motion, rotations by quaternion '
                    'least squares, positions from the null space of the direction '
                    'system), and write a copy of the bag with /estimated/pose added.')
    parser.add_argument('bag', metavar='BAGDIR', help='exploration bag with odometry')
    parser.add_argument('--out', required=True, metavar='OUTBAG', help='bag to write')
    parser.add_argument('--frame', choices=('odometry', 'truth'), default='odometry',
                        help="odometry: map is the odometry's frame at the first image "
                             '(default); truth: aligned to /ground_truth/pose (benchmarks)')
    parser.add_argument('--window', type=int, default=None,
                        help='first pass: pair each place with the next N places (4)')
    parser.add_argument('--radius', type=float, default=None,
                        help='second pass: pair places this close, metres (0.75)')
    parser.add_argument('--workers', type=int, default=None,
                        help='processes for SIFT (default: every core)')
    parser.add_argument('--known-distance', nargs=3, metavar=('I', 'J', 'METRES'),
                        default=None,
                        help='scale from a measured distance between images I and J (0-based, '
                             "bag order) instead of the odometry's path length")
    parser.add_argument('--no-wheel-calibration', action='store_true',
                        help="keep the odometry's distances as they are (default: its "
                             "wheels calibrated by the images' turns; turn off for an "
                             "odometry whose heading comes from a gyro)")
    parser.add_argument('--report', metavar='DIR', default=None,
                        help='write view_graph.png, trajectories.png and summary.json here')
    parser.add_argument('--json', metavar='FILE', default=None,
                        help='write the counts, times and figures as JSON into FILE')
    parser.add_argument('--quiet', action='store_true', help='no progress line')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Estimate, write the bag, print the figures."""
    from dataclasses import replace

    import numpy as np

    from vbn_common.errors import VbnCommonError
    from vbn_common.exploration import ReadConfig, read_exploration
    from visibility_builder.errors import VisibilityBuilderError
    from visibility_builder.estimation.accuracy import align_se2, pose_errors, similarity_scale
    from visibility_builder.estimation.odometry_path import read_track, track_steps
    from visibility_builder.estimation.pipeline import EstimationSettings, estimate_poses
    from visibility_builder.estimation.pose_bag import write_estimated_bag
    from visibility_builder.estimation.scale import check_known_distance, scaled_to_distance

    out = Path(args.out)
    if out.exists():
        raise VisibilityBuilderError(f'{out} exists already, not overwriting')
    try:
        exploration = read_exploration(args.bag, ReadConfig(pose_source='tf',
                                                            map_frame='odom'))
    except VbnCommonError as error:
        raise VisibilityBuilderError(f'{args.bag}: no usable odometry to estimate from '
                                     f'(odom -> base_link on /tf): {error}') from error
    truth = None
    try:
        truth_exploration = read_exploration(args.bag, ReadConfig(pose_source='ground_truth'))
        by_stamp = {f.stamp_ns: f.base_pose for f in truth_exploration.frames}
        truth = np.array([by_stamp.get(f.stamp_ns, (np.nan,) * 3)
                          for f in exploration.frames], float)
    except VbnCommonError:
        truth = None
    if args.frame == 'truth' and truth is None:
        raise VisibilityBuilderError(f'--frame truth: {args.bag} has no /ground_truth/pose')
    known = None
    if args.known_distance is not None:
        try:
            known = (int(args.known_distance[0]), int(args.known_distance[1]),
                     float(args.known_distance[2]))
        except ValueError as error:
            raise VisibilityBuilderError('--known-distance takes two image indices and a '
                                         f'distance in metres, got {args.known_distance}'
                                         ) from error
        check_known_distance(len(exploration.frames), *known)     # before the estimation
    settings = EstimationSettings(workers=args.workers,
                                  wheel_calibration=not args.no_wheel_calibration)
    if args.window is not None:
        settings = replace(settings, window=args.window)
    if args.radius is not None:
        settings = replace(settings, radius_m=args.radius)
    progress = None if args.quiet or not sys.stderr.isatty() else _progress
    track = read_track(args.bag)          # the odometry stream, read once
    steps = track_steps(track, exploration.stamps_ns(), exploration.base_poses())
    result = estimate_poses(exploration, settings, progress, steps=steps, track=track)
    if progress is not None:
        print(file=sys.stderr)
    if known is not None:
        result = scaled_to_distance(result, *known)
    poses = result.base_poses
    if args.frame == 'truth':
        poses = align_se2(poses, truth)
    n = len(exploration.frames)
    estimated = int(np.isfinite(poses).all(axis=1).sum())
    written = write_estimated_bag(args.bag, out, exploration.stamps_ns(), poses)
    kept_dir = int(result.kept_direction.sum())
    kept_rot = int(result.kept_rotation.sum())
    passes = ', '.join(f'{k} {v}' for k, v in result.tried.items())
    print(f'{args.bag}: {n} images at {int(result.stations.max()) + 1} places; pairs tried '
          f'{sum(result.tried.values())} ({passes}), measured {len(result.pairs)}, kept '
          f'{kept_rot} for rotations and {kept_dir} '
          'for directions')
    if result.refused:
        print('  refused: ' + ', '.join(f'{v} {k}' for k, v in sorted(result.refused.items())))
    for line in result.warnings:
        print(f'warning: {line}')
    if len(result.components) > 1:
        print(f'warning: the pairs join the places into {len(result.components)} pieces '
              f'({result.components[:5]}...): the largest is estimated, the others rest on '
              'the odometry')
    if result.wheels is not None:
        print(f'  {result.wheels.line()}')
    print('  times: ' + ', '.join(f'{k} {v:.1f} s' for k, v in result.times.items()))
    if result.refinement is not None:
        r = result.refinement
        print(f'  bundle adjustment: {r.tracks} tracks, {r.observations} observations '
              f'({r.removed} removed as outliers), RMS {r.rms_px:.2f} px')
    figures: dict[str, Any] = {'images': n, 'estimated': estimated, 'written': written,
                               'pairs': len(result.pairs), 'tried': result.tried,
                               'refused': result.refused, 'times': result.times,
                               'pieces': len(result.components),
                               'components': result.components[:10],
                               'warnings': result.warnings,
                               'wheels': None if result.wheels is None else
                               result.wheels.__dict__}
    if truth is not None:
        for name, p in (('odometry', result.odometry_poses), ('thesis', result.thesis_poses),
                        ('joint', result.joint_poses), ('unrefined', result.unrefined_poses),
                        ('result', result.base_poses)):
            errors = pose_errors(p, truth)
            print(f'  {name:<10} against /ground_truth/pose (SE(2) aligned): {errors.line()}')
            figures[name] = errors.__dict__
        largest = result.pieces == 0
        if len(result.components) > 1 and largest.sum() >= 3:
            # The largest piece on its own (its own alignment): the others rest on the
            # odometry, and their error would hide how well the pairs posed the piece.
            errors = pose_errors(result.base_poses[largest], truth[largest])
            print(f'  largest piece ({int(largest.sum())} images, aligned alone): '
                  f'{errors.line()}')
            figures['largest_piece'] = errors.__dict__
        figures['result_scale'] = similarity_scale(result.base_poses, truth)
        print(f"  scale: the truth is {figures['result_scale']:.5f} times the result's size "
              '(a similarity alignment)')
    print(f'wrote {out}: {written} /estimated/pose of {n} images (frame map = '
          f'{"the truth, aligned" if args.frame == "truth" else "odometry at the first image"})')
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=2, default=float))
    if args.report:
        from visibility_builder.estimation.report import write_estimation_report

        aligned = None
        if truth is not None:
            # The truth moved onto the estimate (the inverse of aligning the estimate).
            aligned = align_se2(truth, result.base_poses)
        write_estimation_report(Path(args.report), result, figures, aligned)
        print(f'report: {args.report}/view_graph.png, trajectories.png, summary.json')
    return 0


def _progress(step: str, done: int, total: int) -> None:
    print(f'\r[estimate-poses] {step}: {done}/{total}   ', end='', file=sys.stderr, flush=True)

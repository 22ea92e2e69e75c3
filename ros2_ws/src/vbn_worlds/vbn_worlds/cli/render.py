"""``vbn render``: render a scene into an exploration or run bag.

Example::

    vbn render --scene room --kind exploration --camera panoramic --out bags/room_exploration

``--snapshot X Y YAW`` writes one image (PNG) instead of a bag, for documentation.
"""
from __future__ import annotations

import argparse
import sys
from typing import Any

__all__ = ['register', 'run']


def register(subparsers: Any) -> None:
    """Add the ``render`` subcommand."""
    parser = subparsers.add_parser(
        'render', help='render a scene into an exploration or run bag (MCAP)',
        description='Render a 2.5-D scene (walls extruded from a floor plan) through a '
                    'panoramic, pinhole or fisheye camera (with lens distortion) and write '
                    'a rosbag2 MCAP bag: an '
                    'exploration of every grid pose, a smooth run with odometry, or a run '
                    'with a kidnapping halfway.')
    parser.add_argument('--scene', required=True,
                        help='scene JSON file, or a shipped scene name (room, floor)')
    parser.add_argument('--kind', choices=('exploration', 'run', 'run-kidnapped'),
                        default='exploration', help='what the robot does (default exploration)')
    parser.add_argument('--camera', choices=('panoramic', 'pinhole', 'fisheye'),
                        default='panoramic',
                        help='camera model (default panoramic; fisheye: equidistant)')
    parser.add_argument('--distortion', type=_distortion, default=None,
                        metavar='MODEL:c1,c2,...',
                        help='lens distortion: plumb_bob:k1,k2,p1,p2,k3 or '
                             'rational_polynomial:k1,k2,p1,p2,k3,k4,k5,k6 (pinhole), '
                             'equidistant:k1,k2,k3,k4 (fisheye); images are rendered '
                             'through it and CameraInfo carries it')
    parser.add_argument('--spacing', type=float, default=0.25,
                        help='exploration grid spacing in metres (default 0.25)')
    parser.add_argument('--seed', type=int, default=0,
                        help='seed of odometry noise and image effects (default 0)')
    parser.add_argument('--camera-pitch', type=float, default=0.0, metavar='DEG',
                        help='the mount: camera pitch in degrees, positive looking up '
                             '(written to /tf_static; default 0)')
    parser.add_argument('--camera-roll', type=float, default=0.0, metavar='DEG',
                        help='the mount: camera roll about its optical axis, degrees '
                             '(default 0)')
    parser.add_argument('--camera-height', type=float, default=None, metavar='M',
                        help="the camera's height above the floor in metres (default: "
                             "the scene's)")
    parser.add_argument('--vibration', type=float, default=0.0, metavar='DEG',
                        help='per-frame random pitch and roll of that standard deviation, '
                             'degrees (the ground truth pose carries them; default 0)')
    parser.add_argument('--width', type=int, default=None,
                        help='image width (default 1024 panoramic, 640 pinhole and fisheye)')
    parser.add_argument('--height', type=int, default=None,
                        help='image height (default 256 panoramic, 480 pinhole and fisheye)')
    parser.add_argument('--hfov', type=float, default=None,
                        help='field of view across the image width, degrees (default 90 '
                             'pinhole, 180 fisheye; a fisheye up to 220)')
    parser.add_argument('--headings', type=int, default=None,
                        help='exploration: headings per position, evenly spaced (default 1 '
                             'for panoramic, 4 for pinhole; the builder makes a pose per '
                             'heading, and neighbouring headings share more features the '
                             'closer they are: 8 at 90 degrees)')
    parser.add_argument('--encoding', choices=('bgr8', 'mono8'), default='bgr8',
                        help='image encoding (default bgr8)')
    parser.add_argument('--compressed', nargs='?', const='jpeg', choices=('jpeg', 'png'),
                        default=None,
                        help='write sensor_msgs/CompressedImage on '
                             '/camera/image_raw/compressed (jpeg unless png is given)')
    parser.add_argument('--jpeg-quality', type=int, default=90,
                        help='JPEG quality 1..100 (default 90)')
    parser.add_argument('--exposure', type=float, default=0.0,
                        help='per-frame relative exposure change (e.g. 0.1)')
    parser.add_argument('--blur', type=float, default=0.0,
                        help='per-frame blur, maximum Gaussian sigma in pixels')
    parser.add_argument('--noise', type=float, default=0.0,
                        help='per-frame Gaussian noise, grey levels')
    parser.add_argument('--duration', type=float, default=None,
                        help='cut a run after this many seconds (default: whole path)')
    parser.add_argument('--speed', type=float, default=0.4,
                        help='run top speed in m/s (default 0.4)')
    parser.add_argument('--odometry', action='store_true',
                        help='exploration: drive between the positions as a robot does, '
                             'stopping for the images, and record /odom and odom -> '
                             'base_link on /tf (the ground truth stays for judging)')
    parser.add_argument('--drift', type=float, default=1.0, metavar='SCALE',
                        help="multiplies the wheel odometry's errors (default 1; 0: none)")
    parser.add_argument('--changes', default=None, metavar='FILE|random[:SEED]',
                        help='the world changed since the exploration: a change set (JSON: '
                             'furniture, posters rehung or taken down, light, people; see '
                             'vbn_worlds.synthesis.world_changes), or one drawn '
                             'for the scene from SEED (default --seed)')
    parser.add_argument('--light', default=None, metavar='GAIN[,SIDE_DEG,STRENGTH]',
                        help="the light's gain (0.5 to 1.5 in the benchmark) and a light "
                             'from direction SIDE_DEG of that strength (0 to 1)')
    parser.add_argument('--people', type=int, default=None, metavar='N',
                        help='people walking through the view (occluders that move)')
    parser.add_argument('--save-changes', default=None, metavar='FILE',
                        help='write the change set used to FILE (JSON)')
    parser.add_argument('--path-seed', type=int, default=None, metavar='N',
                        help="varies a run's path (default: --seed; 0: the scene's own "
                             'path)')
    parser.add_argument('--rate', type=float, default=10.0, metavar='HZ',
                        help="a run's camera rate (default 10; 50 divided by a whole "
                             'number: 5, 2, 1)')
    parser.add_argument('--slip', type=int, default=0, metavar='N',
                        help="a run's wheels slip N times for a second (odometry +20 %%)")
    parser.add_argument('--odom-dropouts', type=int, default=0, metavar='N',
                        help="a run's odometry is missing N times for a second")
    parser.add_argument('--snapshot', type=float, nargs=3, metavar=('X', 'Y', 'YAW'),
                        default=None,
                        help='write one image from pose (X, Y, YAW in degrees) as PNG to '
                             '--out instead of a bag')
    parser.add_argument('--out', required=True, help='bag directory to create (or PNG file)')
    parser.set_defaults(func=run)


def _distortion(text: str) -> tuple[str, tuple[float, ...]]:
    """Parse ``MODEL:c1,c2,...`` (argparse type)."""
    model, _, values = text.partition(':')
    try:
        coefficients = tuple(float(v) for v in values.split(',')) if values else ()
    except ValueError as error:
        raise argparse.ArgumentTypeError(
            f'expected MODEL:c1,c2,... with numbers, got {text!r}') from error
    if not model:
        raise argparse.ArgumentTypeError(f'expected MODEL:c1,c2,..., got {text!r}')
    return model, coefficients


def _changes(args: argparse.Namespace, scene: Any) -> Any:
    """Return the ``WorldChanges`` that ``--changes``, ``--light`` and ``--people`` give."""
    import dataclasses

    from vbn_worlds.errors import WorldsError
    from vbn_worlds.synthesis.world_changes import (
        WorldChanges,
        load_changes,
        random_changes,
    )

    changes = None
    if args.changes is not None:
        kind, _, seed = args.changes.partition(':')
        if kind == 'random':
            try:
                changes = random_changes(scene, int(seed) if seed else args.seed)
            except ValueError as error:
                raise WorldsError(f'--changes random:SEED needs an integer seed, '
                                             f'got {seed!r}') from error
        else:
            changes = load_changes(args.changes)
    if args.light is None and args.people is None:
        return changes
    changes = changes or WorldChanges(seed=args.seed)
    if args.light is not None:
        try:
            values = [float(v) for v in args.light.split(',')]
        except ValueError:
            values = []
        if len(values) not in (1, 3):
            raise WorldsError(f'--light is GAIN or GAIN,SIDE_DEG,STRENGTH, got '
                                         f'{args.light!r}')
        side = values[1:] or [changes.appearance.side_deg, changes.appearance.side_strength]
        changes = dataclasses.replace(changes, appearance=dataclasses.replace(
            changes.appearance, gain=values[0], side_deg=side[0], side_strength=side[1]))
    if args.people is not None:
        changes = dataclasses.replace(changes, people=args.people)
    return changes


def run(args: argparse.Namespace) -> int:
    """Render the bag (or snapshot) that ``args`` describe."""
    import dataclasses
    import math
    from pathlib import Path

    import numpy as np

    from landmark_db.scenes import resolve_scene
    from vbn_worlds.errors import WorldsError
    from vbn_worlds.render.effects import ImageEffects
    from vbn_worlds.synthesis.bags import BagSpec, write_bag
    from vbn_worlds.synthesis.trajectory import RunParameters

    scene = resolve_scene(args.scene)
    effects = ImageEffects(exposure=args.exposure, blur_sigma=args.blur,
                           noise_sigma=args.noise)
    if not (math.isfinite(args.speed) and args.speed > 0):
        raise WorldsError(f'--speed must be positive, got {args.speed}')
    spec = BagSpec(kind=args.kind, camera=args.camera, width=args.width, height=args.height,
                   hfov_deg=args.hfov, headings=args.headings, distortion=args.distortion,
                   camera_pitch_deg=args.camera_pitch, camera_roll_deg=args.camera_roll,
                   camera_height=args.camera_height, vibration_deg=args.vibration,
                   spacing=args.spacing,
                   seed=args.seed, encoding=args.encoding, compression=args.compressed,
                   jpeg_quality=args.jpeg_quality, effects=effects,
                   run=RunParameters(max_speed=args.speed), duration=args.duration,
                   odometry=args.odometry, drift=args.drift,
                   changes=_changes(args, scene), path_seed=args.path_seed,
                   rate_hz=args.rate, slip_bursts=args.slip,
                   odom_dropouts=args.odom_dropouts)
    if args.save_changes is not None and spec.changes is not None:
        from vbn_common.jsonio import write_json_atomic

        write_json_atomic(spec.changes.to_dict(), args.save_changes, indent=1)
    if args.snapshot is not None:
        import cv2

        from vbn_common.geometry.mount import tilted
        from vbn_worlds.render.lens_view import make_renderer
        from vbn_worlds.render.textures import build_wall_atlas
        from vbn_worlds.synthesis.people import walkers

        spec.check()
        x, y, yaw_deg = args.snapshot
        pose = np.array([x, y, math.radians(yaw_deg)])
        if not scene.free_space(pose[None, :2])[0]:
            raise WorldsError(f'snapshot pose ({x}, {y}) is not in free space')
        if spec.camera_height is not None:
            scene = dataclasses.replace(scene, camera_height=spec.camera_height)
        camera = tilted(spec.camera_model(), spec.mount_tilt())
        changes = spec.changes
        renderer = make_renderer(scene, camera) if changes is None else make_renderer(
            changes.render_scene(scene), camera,
            build_wall_atlas(changes.render_scene(scene), appearance=changes.appearance))
        occluders = None if changes is None else changes.occluders(scene)
        if changes is not None and changes.people:
            occluders = occluders + walkers(changes.planning_scene(scene), changes.people,
                                            changes.seed, 1.0).occluders(0.0)
        image = renderer.render(pose, encoding=args.encoding, effects=effects,
                                rng=np.random.default_rng(args.seed),
                                occluders=occluders or None).image
        out = Path(args.out)
        if out.suffix.lower() != '.png':
            raise WorldsError(f'snapshot output must be a .png file, got {out}')
        if not cv2.imwrite(str(out), image):
            raise WorldsError(f'cannot write {out}')
        print(f'wrote {out}: {image.shape[1]} x {image.shape[0]} {args.camera} image')
        return 0

    last = [-1]

    def progress(done: int, total: int) -> None:
        percent = 100 * done // max(total, 1)
        if percent // 10 != last[0]:
            last[0] = percent // 10
            print(f'  {done}/{total} images', file=sys.stderr, flush=True)

    summary = write_bag(scene, spec, args.out, progress)
    total = sum(summary.counts.values())
    print(f'wrote {summary.path}: {summary.images} images, {total} messages, '
          f'{summary.duration_s:.1f} s')
    for topic, count in summary.counts.items():
        print(f'  {topic}: {count}')
    return 0

"""``vbn bench-strecha``: the general path of 6.1 on real photographs against pycolmap's mappers.

Example::

    # the Strecha scenes (benchmark data, never committed):
    #   fetch openMVG/SfM_quality_evaluation, then
    git --git-dir=MIRROR archive HEAD Benchmarking_Camera_Calibration_2008 | tar -x -C S
    vbn bench-strecha --data S/Benchmarking_Camera_Calibration_2008 --out out/strecha

(``MIRROR``: the repository's git directory; ``S``: any folder.)

For each scene (``fountain-P11``, ``Herz-Jesus-P25``: a hand-held camera, general 3-D
motion, ground-truth cameras): the photographs scaled to ``--width`` columns (the
intrinsics with them), then side by side on the same images and the same known
intrinsics

- this project (:mod:`visibility_builder.estimation.unordered`): SIFT, every pair by the
  essential matrix, rotations by 6.1.3, positions by 6.1.4, then bundle adjustment;
- pycolmap's incremental mapper and its global mapper (SIFT extraction and exhaustive
  matching by COLMAP, shared by both mappers and counted in both times).

Each is judged by its camera centres against the ground truth after a similarity
alignment (no method knows the scale): images posed, median and largest error (mm), and
the wall time. Targets: median within 2 x of the better pycolmap
mapper's, time within 2 x. Everything goes into ``OUT/summary.json``.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
import time
from typing import Any

__all__ = ['register', 'run']

SCENES = 'fountain-P11,Herz-Jesus-P25'


def register(subparsers: Any) -> None:
    """Add the ``bench-strecha`` subcommand."""
    parser = subparsers.add_parser(
        'bench-strecha', help='image poses of the Strecha photographs against pycolmap',
        description='Estimate the camera poses of the Strecha scenes by thesis 6.1 (general '
                    'motion) and by pycolmap incremental and global mappers, judged against '
                    'the ground-truth cameras.')
    parser.add_argument('--data', required=True, metavar='DIR',
                        help='folder with SCENE/images/*.jpg and SCENE/gt_dense_cameras')
    parser.add_argument('--out', required=True, metavar='DIR', help='output folder')
    parser.add_argument('--scenes', default=SCENES, help=f'scenes, comma separated ({SCENES})')
    parser.add_argument('--width', type=int, default=1536,
                        help='images scaled to this many columns (1536)')
    parser.add_argument('--max-features', type=int, default=8000,
                        help='SIFT keypoints per image for this project (8000)')
    parser.add_argument('--no-colmap', action='store_true', help='skip the pycolmap mappers')
    parser.set_defaults(func=run)


def _read_scene(folder: Path, width: int, out: Path) -> tuple[list[str], Any, Any]:
    """Scale the images into ``out`` and return names, the camera and the true centres."""
    import cv2
    import numpy as np

    from vbn_common.geometry.camera import PinholeCamera
    from visibility_builder.errors import VisibilityBuilderError

    images = sorted((folder / 'images').glob('*.jpg'))
    if len(images) < 2:
        raise VisibilityBuilderError(f'{folder}/images: fewer than two .jpg photographs')
    out.mkdir(parents=True, exist_ok=True)
    names, centres, intrinsics = [], [], None
    for path in images:
        camera_file = folder / 'gt_dense_cameras' / f'{path.name}.camera'
        try:
            rows = [list(map(float, line.split())) for line in
                    camera_file.read_text().splitlines() if line.strip()]
            k, centre, size = np.array(rows[0:3]), np.array(rows[7]), rows[8]
        except (OSError, ValueError, IndexError) as error:
            raise VisibilityBuilderError(f'{camera_file}: not a Strecha camera file '
                                         f'({error})') from error
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise VisibilityBuilderError(f'{path}: cannot be decoded')
        scale = width / image.shape[1]
        small = cv2.resize(image, (width, int(round(image.shape[0] * scale))),
                           interpolation=cv2.INTER_AREA)
        cv2.imwrite(str(out / f'{path.stem}.png'), small)
        if intrinsics is None:
            intrinsics = (k[0, 0] * scale, k[1, 1] * scale, (k[0, 2] + 0.5) * scale - 0.5,
                          (k[1, 2] + 0.5) * scale - 0.5, small.shape[1], small.shape[0])
        if abs(size[0] - image.shape[1]) > 0.5:
            raise VisibilityBuilderError(f'{camera_file}: camera for {size[0]:g} columns, '
                                         f'the image has {image.shape[1]}')
        names.append(f'{path.stem}.png')
        centres.append(centre)
    fx, fy, cx, cy, w, h = intrinsics
    camera = PinholeCamera(width=int(w), height=int(h), fx=fx, fy=fy, cx=cx, cy=cy)
    return names, camera, np.array(centres)


def _ours(image_dir: Path, names: list[str], camera: Any, max_features: int
          ) -> dict[str, Any]:
    import numpy as np

    from vbn_common.features import SiftConfig, extract_many
    from vbn_common.images import EncodedImage
    from visibility_builder.estimation.unordered import estimate_unordered

    t = time.perf_counter()
    encoded = [EncodedImage(compressed=True, data=(image_dir / name).read_bytes(),
                            format='png') for name in names]
    features = extract_many(encoded, SiftConfig(n_features=max_features,
                                                precise_upscale=True))
    seconds_features = time.perf_counter() - t
    estimate = estimate_unordered(features, camera)
    total = time.perf_counter() - t
    return {'thesis': estimate.thesis_centres, 'refined': estimate.centres,
            'time': total, 'times': {'features': seconds_features, **estimate.times},
            'pairs': len(estimate.pairs), 'refused': estimate.refused,
            'observations': estimate.observations, 'rms_px': estimate.rms_px,
            'centres': np.asarray(estimate.centres)}


def _colmap(image_dir: Path, names: list[str], camera: Any, work: Path) -> dict[str, Any]:
    import shutil

    import numpy as np
    import pycolmap

    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    database = work / 'database.db'
    t = time.perf_counter()
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = 'PINHOLE'
    # COLMAP puts the first pixel's centre at (0.5, 0.5), OpenCV (and this project) at 0.
    reader.camera_params = f'{camera.fx},{camera.fy},{camera.cx + 0.5},{camera.cy + 0.5}'
    pycolmap.extract_features(database, image_dir, image_names=names,
                              camera_mode=pycolmap.CameraMode.SINGLE, reader_options=reader,
                              device=pycolmap.Device.cpu)
    pycolmap.match_exhaustive(database, device=pycolmap.Device.cpu)
    shared = time.perf_counter() - t
    out: dict[str, Any] = {}
    for key, mapper in (('colmap incremental', pycolmap.incremental_mapping),
                        ('colmap global', pycolmap.global_mapping)):
        t = time.perf_counter()
        try:
            maps = mapper(database, image_dir, work / key.replace(' ', '_'))
        except Exception as error:      # noqa: BLE001 - a peer's failure is a result
            out[key] = {'error': str(error), 'time': shared + time.perf_counter() - t}
            continue
        seconds = shared + time.perf_counter() - t
        centres = np.full((len(names), 3), np.nan)
        if maps:
            best = max(maps.values(), key=lambda r: r.num_reg_images())
            for image in best.images.values():
                if image.has_pose and image.name in names:
                    centres[names.index(image.name)] = image.projection_center()
        out[key] = {'centres': centres, 'time': seconds}
    return out


def run(args: argparse.Namespace) -> int:
    """Run the benchmark, print the table, write ``summary.json``; 0 when the targets hold."""
    import numpy as np

    from vbn_common.atomic import write_text_atomic
    from visibility_builder.errors import VisibilityBuilderError
    from visibility_builder.estimation.accuracy import centre_errors_sim3

    data, out = Path(args.data), Path(args.out)
    if not data.is_dir():
        raise VisibilityBuilderError(f'{data}: no such folder (see vbn bench-strecha --help '
                                     'for how to get the Strecha scenes)')
    out.mkdir(parents=True, exist_ok=True)
    lines = ['| scene | method | posed | centre error median / max | time |',
             '|---|---|---|---|---|']
    summary: list[dict[str, Any]] = []
    passed = True
    for scene in [s for s in args.scenes.split(',') if s]:
        names, camera, truth = _read_scene(data / scene, args.width, out / scene / 'images')
        results = {}
        mine = _ours(out / scene / 'images', names, camera, args.max_features)
        results['this project, thesis 6.1'] = {'centres': mine['thesis'], 'time': None}
        results['this project, refined'] = {'centres': mine['refined'], 'time': mine['time']}
        if not args.no_colmap:
            results.update(_colmap(out / scene / 'images', names, camera, out / scene / 'colmap'))
        row: dict[str, Any] = {'scene': scene, 'images': len(names), 'width': args.width,
                               'ours_times': mine['times'], 'ours_pairs': mine['pairs'],
                               'ours_refused': mine['refused'], 'ours_rms_px': mine['rms_px']}
        for method, result in results.items():
            if 'error' in result:
                lines.append(f"| {scene} | {method} | failed: {result['error'][:60]} | - | "
                             f"{result['time']:.1f} s |")
                row[method] = {'error': result['error']}
                continue
            errors = centre_errors_sim3(result['centres'], truth)
            ok = np.isfinite(errors)
            median = float(np.median(errors[ok])) if ok.any() else float('nan')
            largest = float(errors[ok].max()) if ok.any() else float('nan')
            seconds = result['time']
            lines.append(f'| {scene} | {method} | {int(ok.sum())} of {len(names)} | '
                         f'{1000 * median:.1f} / {1000 * largest:.1f} mm | '
                         + (f'{seconds:.1f} s |' if seconds is not None else '- |'))
            row[method] = {'posed': int(ok.sum()), 'median_m': median, 'max_m': largest,
                           'time_s': seconds}
        peers = [row[k] for k in ('colmap incremental', 'colmap global')
                 if k in row and 'median_m' in row[k] and row[k]['posed'] == len(names)]
        ours = row['this project, refined']
        if peers:
            best_median = min(p['median_m'] for p in peers)
            best_time = min(p['time_s'] for p in peers)
            row['median_ratio'] = ours['median_m'] / best_median
            row['time_ratio'] = ours['time_s'] / best_time
            row['pass'] = bool(ours['posed'] == len(names) and row['median_ratio'] <= 2.0
                               and row['time_ratio'] <= 2.0)
            lines.append(f"| {scene} | ratio to the better pycolmap mapper | | "
                         f"{row['median_ratio']:.2f} x | {row['time_ratio']:.2f} x |")
            passed &= row['pass']
        else:
            passed = False          # nothing to judge against
        summary.append(row)
    print('\n'.join(lines))
    print('targets: every image posed, median centre error within 2 x and time within 2 x of '
          "the better pycolmap mapper's: " + ('PASS' if passed else 'FAIL')
          + ('' if not args.no_colmap else ' (--no-colmap: not judged)'))
    write_text_atomic(out / 'summary.json', json.dumps(summary, indent=2, default=float))
    return 0 if passed else 1

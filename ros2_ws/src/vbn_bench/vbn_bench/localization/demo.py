"""The evaluation of ``vbn demo``: a recording of the localizer node, judged as a run.

:func:`evaluate_demo` reads what ``vbn record`` captured of the node while the run
bag played (poses, regions, ``/diagnostics``) and judges it with the code of
``vbn localize`` (:mod:`vbn_bench.localization.evaluation`): accuracy by evo and
ours, availability over the images played, region changes, the node's latency; it
draws the trajectories over the regions and checks the targets of ``room_run``.
"""
from __future__ import annotations

import json
from pathlib import Path

__all__ = ['LENS_MAX_ERROR_M', 'LENS_TARGETS', 'evaluate_demo']

#: The targets for a pinhole or fisheye room (``vbn demo --camera``).
LENS_TARGETS = {'translation_median_m': 0.02, 'translation_p95_m': 0.08,
                'heading_median_deg': 0.5, 'availability': 0.95}
#: No pose further off than this, metres.
LENS_MAX_ERROR_M = 0.5


def evaluate_demo(out: Path, recorded: Path, db: Path, run_bag: Path, scene: str,
                  lens: bool = False) -> bool:
    """Evaluate a recording of the node; print the table; write the PNG and JSON.

    Args:
        out: Output folder (``trajectory.png``, ``results.json``).
        recorded: The recorded bag.
        db: The database localized against.
        run_bag: The bag played (its images are the frames).
        scene: Scene name or file drawn under the trajectories ('' for none).
        lens: The targets (pinhole or fisheye: 95 % posed, median
            2 cm, p95 8 cm, heading median 0.5 deg, no pose 50 cm off) instead of
            room_run's.

    Returns:
        Whether every target is met.
    """
    from dataclasses import replace
    import math

    import numpy as np

    from landmark_db.database import open_database
    from vbn_bench.localization.evaluation import (
        Check,
        Latency,
        RegionChanges,
        Thresholds,
        associate,
        check_run,
        count_region_changes,
        evaluate_run,
        evo_ape,
        format_checks,
        format_evaluation,
    )
    from vbn_bench.localization.plots import save_trajectory_figure
    from vbn_bench.localization.pose_bags import read_pose_bag, read_run_bag

    bag = read_pose_bag(recorded)
    played = read_run_bag(run_bag)
    frames = np.sort(played.stamps_ns)
    frame_poses = np.full((len(frames), 3), np.nan)
    rows, pose_rows = associate(frames, bag.pose_stamps_ns, 0.001)
    frame_poses[rows] = bag.poses[pose_rows]
    truth_stamps = bag.truth_stamps_ns if len(bag.truth_stamps_ns) else played.truth_stamps_ns
    truth_poses = bag.truth_poses if len(bag.truth_stamps_ns) else played.truth_poses
    regions = np.where(np.isfinite(frame_poses).all(axis=1), 0, -1)
    evaluation = evaluate_run(frames, regions, frame_poses, truth_stamps, truth_poses)
    from_topic = count_region_changes(bag.regions)
    diag = bag.diagnostics[-1] if bag.diagnostics else {}

    def number(key: str) -> float:
        try:
            return float(diag[key])
        except (KeyError, ValueError):
            return math.nan

    changes = from_topic
    if diag:
        changes = RegionChanges(int(number('predicted_switches')),
                                int(number('switches_after_loss')))
        ms = 1e-3
        latency = Latency(number('latency_p50_ms') * ms, number('latency_p95_ms') * ms,
                          math.nan, math.nan, math.nan, math.nan, 0, 0)
        evaluation = replace(evaluation, latency=latency,
                             falls_to_lost=int(number('falls_to_lost')))
    evaluation = replace(evaluation, changes=changes, evo=evo_ape(recorded)
                         if len(bag.poses) and len(bag.truth_stamps_ns) else None)
    print(format_evaluation(evaluation, f'{run_bag} through the localizer node over DDS '
                                        f'({len(frames)} images played):'))
    print(f'  /localizer/region {len(bag.regions)} messages; changes seen there: '
          f'{from_topic.predicted} direct, {from_topic.after_loss} after LOST')
    if diag:
        print(f'  node diagnostics  frames received {diag.get("frames_received")}, processed '
              f'{diag.get("frames_processed")}, dropped {diag.get("frames_dropped")}; '
              f'latency over the last {min(200, int(number("frames_processed") or 0))} '
              f'frames p50 {number("latency_p50_ms"):.1f} ms, p95 '
              f'{number("latency_p95_ms"):.1f} ms, max {number("latency_max_ms"):.1f} ms')
    scene_obj = None
    if scene:
        from landmark_db.scenes import resolve_scene
        scene_obj = resolve_scene(scene)
    png = save_trajectory_figure(out / 'trajectory.png', open_database(db), truth_stamps,
                                 truth_poses, bag.pose_stamps_ns, bag.poses, frames, scene_obj,
                                 title=f'{run_bag.name}: localizer node (dots) and ground truth '
                                       f'(line) over the regions of {db.name}')
    print(f'  figure            {png}')
    if lens:
        checks = check_run(evaluation, Thresholds(**LENS_TARGETS), switching=False)
        acc = evaluation.evo or evaluation.accuracy
        largest = acc.translation_max_m if acc else math.nan
        checks.append(Check('largest translation error', largest, LENS_MAX_ERROR_M, True,
                            f'{largest * 100:.1f} cm'))
        print(format_checks(checks, "against the lens cameras' targets:"))
    else:
        checks = check_run(evaluation)
        print(format_checks(checks, 'against the targets for room_run:'))
    results = evaluation.as_dict()
    results['diagnostics'] = diag
    results['checks'] = [{'name': c.name, 'value': c.value, 'limit': c.limit,
                          'passed': c.passed} for c in checks]
    (out / 'results.json').write_text(json.dumps(results, indent=1, default=str))
    return all(c.passed for c in checks)

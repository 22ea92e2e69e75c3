"""``vbn demo``: the whole system on the sample bags, over DDS, ending in PASS or FAIL.

Example (what ``make demo`` runs)::

    vbn demo --out out/demo

Steps, as a user would run them (the build in this process; the node, the recorder and
the player each a process of its own, as a launch file would start them):

1. ``vbn build bags/room_exploration --db OUT/room.db`` (the landmark database);
2. the localizer node (``localizer --ros-args -p db:=OUT/room.db``, the executable
   ``ros2 run landmark_localizer localizer`` starts);
3. ``vbn record`` of ``/localizer/pose``, ``/localizer/pose_with_covariance``,
   ``/localizer/region``, ``/ground_truth/pose`` and ``/diagnostics`` into
   ``OUT/recorded``;
4. ``vbn play bags/room_run --wait-for-subscribers`` (the camera, its calibration,
   odometry and ground truth) to the node in real time.

Then the recording is evaluated by the same code as ``vbn localize``
(:mod:`vbn_bench.localization.evaluation`): accuracy by ``evo_ape`` (and ours beside it),
availability (poses over the images played), region changes by prediction and after a
loss and the per-frame latency (the node's ``/diagnostics``); ``OUT/trajectory.png``
shows the estimated and true trajectories over the regions. The last line is
``PASS`` or ``FAIL`` against the targets for ``room_run`` (accuracy, availability,
switching; latency on one core is ``vbn bench-localize``'s); the exit code is 0 only on
PASS.

``--load N`` runs N busy processes beside the node while the bag plays (a machine busy
with other work: frames the node cannot take in time are dropped, and the odometry
bridges them).

``--camera pinhole`` (or ``fisheye``) renders a pinhole room (90 degrees, plumb_bob
distortion) or a fisheye room (180 degrees, equidistant) into ``OUT`` first, an
exploration with 8 headings per position and a run (``vbn render``, :data:`LENS_BAGS`;
kept for the next demo), and checks the lens cameras' targets for them.

DDS: the demo runs in its own random ``ROS_DOMAIN_ID`` (unless one is set) with
localhost discovery, so it neither hears nor disturbs other ROS programs.
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path
import random
import shutil
import signal
import subprocess
import sys
import time
from typing import Any

from vbn_bench.commands import run_command
from vbn_bench.localization.conditions import LENS_BAGS, LENS_HEADINGS, lens_render_argv
from vbn_common import names
from vbn_common.graph_processes import graph_process_argv

__all__ = ['LENS_BAGS', 'LENS_HEADINGS', 'lens_render_argv', 'register', 'run']

#: Builder settings of the demo's database beyond the builder's defaults (none: the
#: defaults cover the room; ``--build-set`` adds some).
DEMO_BUILD_SETTINGS: tuple[str, ...] = ()
#: What the demo records of the node (and the ground truth that the player publishes).
RECORDED_TOPICS = (names.LOCALIZER_POSE, names.LOCALIZER_POSE_WITH_COVARIANCE,
                   names.LOCALIZER_REGION, names.GROUND_TRUTH_POSE, names.DIAGNOSTICS)
#: What the demo plays of the run bag (those the bag has).
PLAYED_TOPICS = (*names.IMAGE_TOPICS, names.CAMERA_INFO, names.ODOM, names.GROUND_TRUTH_POSE)


def register(subparsers: Any) -> None:
    """Add the ``demo`` subcommand."""
    parser = subparsers.add_parser(
        'demo', help='build, localize the sample run over DDS, evaluate: PASS or FAIL',
        description='Build the database of bags/room_exploration, start the localizer node, '
                    'play bags/room_run to it over DDS, record what it publishes and print '
                    'accuracy (evo_ape), availability, switching and latency, with a PNG of '
                    'the trajectories over the regions; ends with PASS or FAIL.')
    parser.add_argument('--out', default='out/demo', help='output folder (out/demo)')
    parser.add_argument('--camera', choices=('panoramic', *LENS_BAGS), default='panoramic',
                        help='panoramic: the sample bags; pinhole or fisheye: render a room '
                             'with that lens into OUT first (default panoramic)')
    parser.add_argument('--exploration', default=None,
                        help='exploration bag (bags/room_exploration; with --camera pinhole '
                             'or fisheye OUT/room_exploration_CAMERA, rendered if absent)')
    parser.add_argument('--run', default=None,
                        help='run bag (bags/room_run; with --camera pinhole or fisheye '
                             'OUT/room_run_CAMERA, rendered if absent)')
    parser.add_argument('--db', default=None,
                        help='use this database instead of building OUT/room.db')
    parser.add_argument('--build-set', action='append', default=None, metavar='NAME=VALUE',
                        help="vbn build --set (repeatable; default: the builder's defaults)")
    parser.add_argument('--param', action='append', default=[], metavar='NAME:=VALUE',
                        help="a parameter of the localizer node, as ros2 run's -p takes it "
                             '(repeatable; e.g. --param scene_tracks:=40)')
    parser.add_argument('--scene', default='room', help='scene drawn under the trajectories')
    parser.add_argument('--rate', type=float, default=1.0, help='playback rate (1.0)')
    parser.add_argument('--timeout', type=float, default=180.0,
                        help='seconds to wait for the node and the recorder to start')
    parser.add_argument('--load', type=int, default=0, metavar='N',
                        help='N busy processes beside the node while the bag plays')
    parser.set_defaults(func=run)


def _busy(n: int) -> list[subprocess.Popen]:
    """Start ``n`` processes that keep a CPU busy until killed."""
    return [subprocess.Popen([sys.executable, '-c', 'while True: pass'],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            for _ in range(max(n, 0))]


class _Process:
    """A child process with its output in a log file, stopped by SIGINT then SIGKILL."""

    def __init__(self, name: str, argv: list[str], env: dict[str, str], log: Path) -> None:
        self.name = name
        self.log = log
        self._stream = log.open('w')
        self.popen = subprocess.Popen(argv, env=env, stdout=self._stream,
                                      stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                      start_new_session=True)

    def output(self) -> str:
        return self.log.read_text(errors='replace')

    def wait_for(self, text: str, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if text in self.output():
                return True
            if self.popen.poll() is not None:
                return text in self.output()
            time.sleep(0.2)
        return False

    def stop(self, timeout: float = 20.0) -> int | None:
        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGINT)
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait(5)
        self._stream.close()
        return self.popen.returncode


def _env() -> dict[str, str]:
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    env.setdefault('ROS_DOMAIN_ID', str(random.SystemRandom().randint(1, 101)))
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    return env


def _step(text: str) -> float:
    print(f'== {text}', flush=True)
    return time.perf_counter()


def run(args: argparse.Namespace) -> int:
    """Run the demo; 0 on PASS, 1 on FAIL."""
    from landmark_localizer.errors import LocalizerError

    start = time.perf_counter()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    env = _env()
    print(f'vbn demo: output in {out}, ROS_DOMAIN_ID={env["ROS_DOMAIN_ID"]}, localhost '
          'discovery', flush=True)
    _bags(args, out)
    if args.db:
        db = Path(args.db)
        if not db.is_file():
            raise LocalizerError(f'database {db} does not exist')
    else:
        db = out / ('room.db' if args.camera == 'panoramic' else f'room_{args.camera}.db')
        t = _step(f'1/5 build the database of {args.exploration}')
        argv = ['build', args.exploration, '--db', str(db), '--quiet']
        for item in (args.build_set if args.build_set is not None else DEMO_BUILD_SETTINGS):
            argv += ['--set', item]
        run_command(argv, out / 'build.log', append=False)
        print(f'   {db} ({db.stat().st_size / 1e6:.2f} MB) in {time.perf_counter() - t:.0f} s')
    recorded = out / 'recorded'
    if recorded.exists():
        shutil.rmtree(recorded)  # this demo's own previous recording
    executable = graph_process_argv('localizer', path=env.get('PATH'))
    processes: list[_Process] = []
    busy: list[subprocess.Popen] = []
    try:
        t = _step('2/5 start the localizer node')
        ros_args = ['--ros-args', '-p', f'db:={db}']
        for item in args.param:
            if ':=' not in item:
                raise LocalizerError(f'--param {item!r}: expected NAME:=VALUE')
            ros_args += ['-p', item]
        node = _Process('localizer', [*executable, *ros_args], env, out / 'localizer.log')
        processes.append(node)
        if not node.wait_for('localizer ready', args.timeout):
            raise LocalizerError(f'the localizer did not start; see {node.log}')
        print(f'   ready in {time.perf_counter() - t:.0f} s')
        _step('3/5 record ' + ' '.join(RECORDED_TOPICS))
        recorder = _Process('record', graph_process_argv(
            'record', '--topics', *RECORDED_TOPICS, '--out', str(recorded)), env,
            out / 'record.log')
        processes.append(recorder)
        if not recorder.wait_for('recording /localizer/region', args.timeout):
            raise LocalizerError(f'the recorder did not subscribe; see {recorder.log}')
        t = _step(f'4/5 play {args.run} to the node over DDS'
                  + (f' beside {args.load} busy processes' if args.load > 0 else ''))
        busy = _busy(args.load)
        topics = _played_topics(Path(args.run))
        with (out / 'play.log').open('w') as log:
            played = subprocess.run(
                graph_process_argv('play', args.run, '--wait-for-subscribers',
                                   '--wait-timeout', str(args.timeout), '--rate',
                                   str(args.rate), '--topics', *topics),
                stdout=log, stderr=subprocess.STDOUT, env=env, check=False)
        if played.returncode != 0:
            raise LocalizerError(f'vbn play failed (exit {played.returncode}); see '
                                 f'{out / "play.log"}')
        time.sleep(2.5)  # the last frame's pose and one more /diagnostics (1 Hz)
        print(f'   played in {time.perf_counter() - t:.0f} s')
        recorder.stop()
        node.stop()
    finally:
        for hog in busy:
            hog.kill()
            hog.wait()
        for process in reversed(processes):
            process.stop()
    _step('5/5 evaluate the recording')
    from vbn_bench.localization.demo import evaluate_demo

    passed = evaluate_demo(out, recorded, db, Path(args.run), args.scene,
                           lens=args.camera != 'panoramic')
    print(f'(demo took {time.perf_counter() - start:.0f} s)')
    print('PASS' if passed else 'FAIL', flush=True)
    return 0 if passed else 1


def _bags(args: argparse.Namespace, out: Path) -> None:
    """Fill in the exploration and run bags, rendering a lens camera's into OUT."""
    if args.camera == 'panoramic':
        args.exploration = args.exploration or 'bags/room_exploration'
        args.run = args.run or 'bags/room_run'
        return
    for kind in ('exploration', 'run'):
        if getattr(args, kind):
            continue
        bag = out / f'room_{kind}_{args.camera}'
        setattr(args, kind, str(bag))
        if (bag / 'metadata.yaml').is_file():
            continue
        if bag.exists():
            shutil.rmtree(bag)  # a render that did not finish
        t = _step(f'0/5 render {bag} ({args.camera})')
        run_command([*lens_render_argv(args.camera, kind), '--out', str(bag)],
                    out / f'render_{kind}.log', append=False)
        print(f'   rendered in {time.perf_counter() - t:.0f} s')


def _played_topics(run_bag: Path) -> list[str]:
    from vbn_common.bags import open_bag

    with open_bag(run_bag) as bag:
        return [t for t in PLAYED_TOPICS if t in bag.topics]

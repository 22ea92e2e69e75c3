"""``vbn simulate``: generate a random synthetic world of Section 8.2 (setting 1-4)."""
from __future__ import annotations

import argparse
import logging

from landmark_db.defaults import POSE_SPACING

__all__ = ['register', 'run']

_LOG = logging.getLogger(__name__)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``simulate`` subcommand."""
    parser = subparsers.add_parser(
        'simulate',
        help='generate a random synthetic world (thesis Section 8.2) as a world JSON',
        description='Draw a random polygon world of one of the four settings of thesis '
                    'Section 8.2 (1: rectangular + Type 1 features, 2: rectangular + Type 2, '
                    '3: irregular + Type 1, 4: irregular + Type 2), sample poses on a grid '
                    'and compute which features each pose sees. The same setting, seed and '
                    'spacing always give the same world.',
    )
    parser.add_argument('--setting', type=int, required=True, choices=(1, 2, 3, 4),
                        help='world setting of thesis Section 8.2')
    parser.add_argument('--seed', type=int, required=True, help='random seed (>= 0)')
    parser.add_argument('--out', required=True, metavar='WORLD.json',
                        help='world instance JSON to write')
    parser.add_argument('--scene-out', metavar='SCENE.json',
                        help='also write the polygon scene (perimeter, obstacles, features)')
    parser.add_argument('--spacing', type=float, default=POSE_SPACING,
                        help=f'pose grid spacing in metres (default: {POSE_SPACING}, as in the '
                             'thesis)')
    parser.add_argument('--small', action='store_true',
                        help='a reduced-size world (about 10 m across) of the same setting, '
                             'small enough for the exact solver')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Generate the world and write the requested files."""
    import math

    from landmark_db.scene import save_scene
    from landmark_db.world import save_world
    from vbn_common.atomic import check_output_folder
    from vbn_worlds.errors import WorldsError
    from vbn_worlds.simulator.settings import get_setting, small_setting
    from vbn_worlds.simulator.simulate import simulate_world

    if args.seed < 0:
        raise WorldsError(f'--seed must be >= 0, got {args.seed}')
    if not (math.isfinite(args.spacing) and 0.05 <= args.spacing <= 10):
        raise WorldsError(f'--spacing must be between 0.05 and 10 metres, got {args.spacing}')
    # Before the simulation, so that a mistyped folder costs nothing and writes nothing.
    check_output_folder(args.out)
    if args.scene_out:
        check_output_folder(args.scene_out)
    setting = get_setting(args.setting)
    if args.small:
        setting = small_setting(setting)
    simulated = simulate_world(setting, args.seed, spacing=args.spacing)
    save_world(simulated.world, args.out)
    if args.scene_out:
        save_scene(simulated.scene, args.scene_out)
    world = simulated.world
    print(f'{world.name}: {world.n_poses} poses, {len(world.edges)} edges, '
          f'{world.n_features} features, {simulated.mean_visible:.1f} visible per pose '
          f'-> {args.out}')
    return 0

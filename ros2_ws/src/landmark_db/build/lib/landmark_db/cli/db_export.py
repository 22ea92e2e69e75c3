"""``vbn db-export``: write a landmark database's world and decomposition as JSON."""
from __future__ import annotations

import argparse

__all__ = ['register', 'run']


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``db-export`` subcommand."""
    parser = subparsers.add_parser(
        'db-export',
        help='export a landmark database as world and decomposition JSON (for vbn validate)',
        description='Write the world instance a landmark database was built from (poses, '
                    'pose graph, the feature classes each pose sees; feature id = class id) '
                    'and its decomposition (regions with their landmark class ids), in the '
                    'interchange formats of vbn decompose, so that `vbn validate WORLD.json '
                    'DECOMP.json` checks a built database.',
    )
    parser.add_argument('database', metavar='DB', help='landmark database (SQLite file)')
    parser.add_argument('--world', metavar='WORLD.json', help='world instance JSON to write')
    parser.add_argument('--decomposition', metavar='DECOMP.json',
                        help='decomposition JSON to write')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Open the database and write the requested files."""
    from landmark_db.database import open_database
    from landmark_db.decomposition import save_decomposition
    from landmark_db.errors import LandmarkDbError
    from landmark_db.world import save_world
    from vbn_common.atomic import check_output_folder

    if not args.world and not args.decomposition:
        raise LandmarkDbError('nothing to export: give --world and/or --decomposition')
    for out in (args.world, args.decomposition):
        if out:
            check_output_folder(out)
    db = open_database(args.database)
    written = []
    if args.world:
        world = db.to_world_instance()
        save_world(world, args.world)
        written.append(f'{args.world} ({world.n_poses} poses, {world.n_features} features)')
    if args.decomposition:
        decomposition = db.to_decomposition()
        save_decomposition(decomposition, args.decomposition)
        written.append(f'{args.decomposition} ({len(decomposition.regions)} regions, '
                       f'k = {decomposition.k})')
    print(f'{args.database} -> ' + ', '.join(written))
    return 0

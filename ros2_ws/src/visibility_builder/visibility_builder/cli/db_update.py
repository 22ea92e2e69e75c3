"""``vbn db-update DB BAGDIR``: rebuild the regions a changed world broke.

Example::

    vbn db-update out/room.db bags/room_reexplored --out out/room_updated.db

Reads a partial re-exploration of the changed area (images with poses in the database's
``map``), gives its features the database's classes where their scene points are,
replaces the visibility of the poses it covers, keeps every region whose landmark is
still seen from all its poses and rebuilds the others
(:mod:`visibility_builder.db_update`). The database (or ``--out``) is replaced
atomically: when the update fails, the file is as it was.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
import sys
from typing import Any

__all__ = ['register', 'run']


def register(subparsers: Any) -> None:
    """Add the ``db-update`` subcommand."""
    parser = subparsers.add_parser(
        'db-update', help='update a database from a re-exploration of a changed area',
        description='Match a partial re-exploration (images with map poses) to the '
                    "database's classes, replace the visibility of the poses it covers, "
                    'rebuild the regions whose landmark the world no longer shows and '
                    'write the database atomically.')
    parser.add_argument('db', metavar='DB', help='the landmark database to update')
    parser.add_argument('bag', metavar='BAGDIR', help='re-exploration bag (or .mcap)')
    parser.add_argument('--out', default=None,
                        help='write the updated database here (default: replace DB)')
    parser.add_argument('--workers', type=int, default=None,
                        help='processes for SIFT (default: every core)')
    parser.add_argument('--json', default=None, metavar='FILE', help='write the counts')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Update; print what changed; return 0 on success."""
    from landmark_db.database import open_database, write_database
    from vbn_common.atomic import check_output_folder
    from visibility_builder.db_update import UpdateConfig, update_database

    out = Path(args.out or args.db)
    check_output_folder(out)
    database = open_database(args.db)
    result = update_database(database, args.bag, UpdateConfig(workers=args.workers),
                             on_stage=lambda s: print(f'[{s}]', file=sys.stderr, flush=True))
    write_database(out, result.database)
    for name, value in result.counts.items():
        print(f'  {name:32s} {value}')
    print(f'wrote {out}: {result.database.n_regions} regions '
          f'({result.counts["regions_affected"]} rebuilt as {result.counts["regions_added"]}'
          f'), {out.stat().st_size / 1e6:.2f} MB')
    if args.json:
        Path(args.json).write_text(json.dumps(
            {**result.counts, 'affected': result.affected.tolist(), 'out': str(out)},
            indent=1))
    return 0

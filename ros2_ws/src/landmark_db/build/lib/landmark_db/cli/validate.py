"""``vbn validate``: check a decomposition against its world."""
from __future__ import annotations

import argparse

__all__ = ['register', 'run']


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``validate`` subcommand."""
    parser = subparsers.add_parser(
        'validate',
        help='check a decomposition JSON against its world JSON (exit 0 only if valid)',
        description='Check that every region is connected and sees its k landmark features '
                    'from all its poses, that every k-coverable pose (after the rho '
                    'reduction) has its rho-neighbourhood inside one region unless listed as '
                    'uncovered, and that nothing is uncovered when sigma = 0. Exits 0 when '
                    'valid, 1 when not (each problem printed), 2 on unreadable input.',
    )
    parser.add_argument('world', metavar='WORLD.json', help='world instance JSON')
    parser.add_argument('decomposition', metavar='DECOMP.json', help='decomposition JSON')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Validate; print the verdict and every problem found."""
    from landmark_db.decomposition import load_decomposition, service, validate
    from landmark_db.world import load_world

    world = load_world(args.world)
    decomposition = load_decomposition(args.decomposition)
    problems = validate(world, decomposition)
    if problems:
        print(f'INVALID: {len(problems)} problem(s) in {args.decomposition}')
        for problem in problems:
            print(f'  - {problem}')
        return 1
    served = service(world, [region.poses for region in decomposition.regions],
                     decomposition.k, decomposition.rho)
    print(f'valid: {len(decomposition.regions)} regions, k = {decomposition.k}, '
          f'rho = {decomposition.rho}, sigma = {decomposition.sigma}, {served.describe()}')
    return 0

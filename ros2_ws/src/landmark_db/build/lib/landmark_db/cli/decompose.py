"""``vbn decompose``: decompose a world into regions with k-feature landmarks."""
from __future__ import annotations

import argparse

from landmark_db.defaults import DECOMPOSITION

__all__ = ['bound_line', 'register', 'run']


def bound_line(regions: int, bound: int, unserved: int) -> str:
    """One line: the certified bound and the decomposition's ratio to it."""
    ratio = regions / bound if bound else float('inf') if regions else 1.0
    line = (f'lower bound: no complete decomposition has fewer than {bound} regions; '
            f'{regions} / {bound} = {ratio:.3f}')
    if unserved:
        line += f' (this one leaves {unserved} k-coverable poses unserved)'
    return line

_ALGORITHMS = ('A1', 'A2', 'A3', 'B1', 'B2', 'C', 'exact', 'best')


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``decompose`` subcommand."""
    parser = subparsers.add_parser(
        'decompose',
        help='decompose a world JSON into regions (rho-MORDP, thesis Chapters 3-5)',
        description='Solve rho-MORDP for a world instance: find few connected regions of '
                    'poses, each with k landmark features seen from all its poses, such that '
                    'every k-coverable pose has its rho-neighbourhood inside one region. '
                    'Algorithms: A1, A2, A3 (grow from seeds, Figure 5.1), B1, B2 (shrink, '
                    'Figure 5.2), C (neighbourhood seeds, Figure 5.3), exact (optimum by '
                    'set cover with HiGHS, small worlds only), best (candidate pool + set '
                    'cover).',
    )
    parser.add_argument('world', metavar='WORLD.json', help='world instance JSON')
    parser.add_argument('--algorithm', required=True, choices=_ALGORITHMS,
                        help='decomposition algorithm')
    parser.add_argument('--k', type=int, required=True, help='features per landmark (>= 1)')
    parser.add_argument('--rho', type=int, default=DECOMPOSITION.rho,
                        help='overlap: graph radius every pose needs inside one region '
                             f'(default: {DECOMPOSITION.rho})')
    parser.add_argument('--sigma', type=int, default=DECOMPOSITION.sigma,
                        help='add a region only if it covers more than SIGMA otherwise '
                             f'uncovered poses (default: {DECOMPOSITION.sigma}, a complete '
                             'decomposition)')
    parser.add_argument('--alpha', type=float, default=DECOMPOSITION.alpha,
                        help="algorithm C's least unassigned fraction of a neighbourhood "
                             f'(default: {DECOMPOSITION.alpha})')
    parser.add_argument('--seed', type=int, default=DECOMPOSITION.seed,
                        help='seed of the tie-breaking random generator '
                             f'(default: {DECOMPOSITION.seed})')
    parser.add_argument('--time-limit', type=float, default=None, metavar='SECONDS',
                        help='set-cover solver time limit for exact (default '
                             f'{DECOMPOSITION.exact_time_limit:g}) and best (default '
                             f'{DECOMPOSITION.best_time_limit:g})')
    parser.add_argument('--bound', action='store_true',
                        help='also certify a lower bound on the fewest regions (column '
                             'generation; best at sigma 0 always does) and print the ratio')
    parser.add_argument('--out', required=True, metavar='DECOMP.json',
                        help='decomposition JSON to write')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Load the world, decompose it and write the decomposition."""
    import math

    from landmark_db.decomposition import certify, decompose, save_decomposition, service
    from landmark_db.errors import LandmarkDbError
    from landmark_db.world import load_world
    from vbn_common.atomic import check_output_folder

    if args.k < 1:
        raise LandmarkDbError(f'--k must be at least 1, got {args.k}')
    if args.rho < 0:
        raise LandmarkDbError(f'--rho must be at least 0, got {args.rho}')
    if args.sigma < 0:
        raise LandmarkDbError(f'--sigma must be at least 0, got {args.sigma}')
    if not (math.isfinite(args.alpha) and 0 < args.alpha <= 1):
        raise LandmarkDbError(f'--alpha must be in (0, 1], got {args.alpha}')
    if args.seed < 0:
        raise LandmarkDbError(f'--seed must be >= 0, got {args.seed}')
    options = {}
    if args.time_limit is not None:
        if not (math.isfinite(args.time_limit) and args.time_limit > 0):
            raise LandmarkDbError(f'--time-limit must be positive, got {args.time_limit}')
        if args.algorithm in ('exact', 'best'):
            options['time_limit'] = args.time_limit
    check_output_folder(args.out)  # before a decomposition that may take minutes
    world = load_world(args.world)
    if service(world, [], args.k, args.rho).k_coverable == 0:
        most = int(world.visible_counts.max(initial=0))
        raise LandmarkDbError(
            f'no pose of {args.world} is k-coverable: none sees k = {args.k} features '
            f'throughout its rho = {args.rho} neighbourhood (the most any pose sees is '
            f'{most}); lower --k or --rho')
    decomposition = decompose(world, args.algorithm, args.k, args.rho, args.sigma,
                              alpha=args.alpha, rng=args.seed, **options)
    if args.bound and decomposition.lower_bound is None:
        decomposition.lower_bound = certify(world, decomposition).regions
    save_decomposition(decomposition, args.out)
    sizes = [len(region) for region in decomposition.regions]
    mean = sum(sizes) / len(sizes) if sizes else 0.0
    served = service(world, [region.poses for region in decomposition.regions],
                     decomposition.k, decomposition.rho)
    print(f'{args.algorithm}: {len(sizes)} regions (mean {mean:.1f} poses), '
          f'{served.describe()}, {decomposition.seconds:.3f} s -> {args.out}')
    if decomposition.lower_bound is not None:
        print(bound_line(len(sizes), decomposition.lower_bound, served.unserved.size))
    return 0

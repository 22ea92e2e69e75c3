"""``vbn db-info``: summarise a landmark database (regions, features, poses, sizes)."""
from __future__ import annotations

import argparse
from typing import Any

__all__ = ['format_summary', 'register', 'run']


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``db-info`` subcommand."""
    parser = subparsers.add_parser(
        'db-info',
        help='summarise a landmark database: regions, features, poses, sizes, parameters',
        description='Check a landmark database (application id, schema version, SQLite '
                    'integrity) and print how many regions, feature classes, poses and '
                    'model views it holds, its service (the k-coverable poses whose '
                    'rho-neighbourhood lies inside one region, measured on the stored '
                    'world), the bytes each table takes and the parameters it was built '
                    'with. Exits 2 with one line for a missing, foreign, newer or '
                    'damaged file.',
    )
    parser.add_argument('database', metavar='DB', help='landmark database (SQLite file)')
    parser.add_argument('--json', action='store_true',
                        help='print the summary as one JSON object')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print the summary of the database."""
    import json

    from landmark_db.database import database_summary, open_database

    summary = database_summary(args.database)
    data = summary.to_dict()
    # Service is measured on the stored world, not read from a stored count.
    data['service'] = open_database(args.database).service().to_dict()
    if args.json:
        print(json.dumps(data, indent=2, sort_keys=True))
    else:
        print(format_summary(data))
    return 0


def _size(n: int) -> str:
    for unit, scale in (('GB', 1e9), ('MB', 1e6), ('kB', 1e3)):
        if n >= scale:
            return f'{n / scale:.1f} {unit}'
    return f'{n} B'


def format_summary(summary: dict[str, Any]) -> str:
    """Return the human-readable summary of :meth:`DatabaseSummary.to_dict`'s output."""
    counts, build, sizes = summary['counts'], summary['build'], summary['table_bytes']
    camera = build['camera']
    regions = counts['regions']
    mean = counts['region_poses'] / regions if regions else 0.0
    spacing = build['pose_spacing']
    lines = [
        f"{summary['path']}: landmark database, schema version {summary['schema_version']}, "
        f"{_size(summary['file_bytes'])}",
        f"  built:       {build['created_utc']} from {build['source_bag'] or '(no bag)'}, "
        f"poses from {build['pose_source']}",
        f"  regions:     {regions} (mean {mean:.1f} poses), "
        f"{counts['region_adjacency']} neighbouring pairs",
        f"  landmarks:   k = {build['k']}, rho = {build['rho']}, sigma = {build['sigma']}, "
        f"algorithm {build['algorithm']} ({build['decomposition_seconds']:.2f} s); "
        f"{counts['landmark_features']} landmark + {counts['extra_features']} extra "
        f'region features',
        f"  features:    {counts['classes']} classes, {counts['class_descriptors']} "
        f"descriptors, {counts['visibility']} pose-class sightings",
        '  descriptors: ' + ('whole (128 bytes each)' if counts['descriptor_bytes'] == 128
                             else f"{counts['descriptor_bytes']}-byte codes of a product "
                             f'quantizer (the 32 kB codebook in the file)'),
        f"  poses:       {counts['poses']}, {counts['edges']} edges"
        + (f', spacing {spacing:g} m' if spacing is not None else '')
        + f", {counts['uncovered']} listed as uncovered",
        f"  service:     {_service(summary.get('service'))}",
        f"  model views: {counts['model_views']} with {counts['model_view_features']} "
        f'features',
        '  scene points: ' + (f"{counts['scene_points']} (3-D points with a descriptor, for "
                              'poses outside the regions)' if 'scene_points' in counts
                              else 'none (schema 1)'),
        f"  camera:      {camera['kind']} {camera['width']} x {camera['height']}, "
        f"{camera['distortion_model'] or 'no'} distortion, frame {camera['frame_id']}",
        '  frames:      ' + ', '.join(f'{key} = {value}'
                                      for key, value in sorted(build['frames'].items())),
        '  sift:        ' + _pairs(build['sift']),
        '  parameters:  ' + _pairs(build['parameters']),
    ]
    if sizes:
        biggest = sorted(sizes.items(), key=lambda item: (-item[1], item[0]))
        shown = ', '.join(f'{name} {_size(n)}' for name, n in biggest[:5])
        rest = biggest[5:]
        if rest:
            shown += f', {len(rest)} more tables {_size(sum(n for _, n in rest))}'
        lines.append('  sizes:       ' + shown)
    return '\n'.join(lines)


def _service(figures: dict[str, Any] | None) -> str:
    if not figures:
        return '(not measured)'
    return (f"served {figures['served']} of {figures['k_coverable']} k-coverable poses "
            f"({100.0 * figures['served_share']:.1f} %; N_rho(v) inside one region), "
            f"{figures['in_region']} lie in a region")


def _pairs(values: dict[str, Any]) -> str:
    import json

    if not values:
        return '(none)'
    return ', '.join(f'{key} = {json.dumps(value)}' for key, value in sorted(values.items()))

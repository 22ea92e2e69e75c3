"""The report of a build: ``regions.png``, ``visibility_sizes.png`` and ``summary.json``.

Written by ``vbn build --report DIR`` and by the builder node's ``report`` parameter:
the regions over the floor plan (one colour per region, crosses on the k-coverable poses
the database does not serve), poses per feature class before and after the filters (the thesis's
Figure 8.7) and every count and time of the build.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = ['write_report']


def write_report(folder: Path, result: Any, scene_name: str | None) -> None:
    """Write the figures and ``summary.json`` of a build into ``folder``."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import numpy as np

    from vbn_common.atomic import write_text_atomic
    from visibility_builder.plotting import save_decomposition_figure

    folder.mkdir(exist_ok=True)
    scene = None
    if scene_name:
        from landmark_db.scenes import resolve_scene
        scene = resolve_scene(scene_name)
    db = result.database
    save_decomposition_figure(
        folder / 'regions.png', result.world, [r.poses for r in db.regions], db.info.k,
        db.uncovered, scene=scene,
        title=f'{len(db.regions)} regions, {db.info.algorithm}, k={db.info.k}, '
              f'rho={db.info.rho}, sigma={db.info.sigma}')
    report = result.report
    fig, ax = plt.subplots(figsize=(7, 4))
    before, after = report.visibility_sizes_before, report.visibility_sizes_after
    top = int(max(before.max(initial=1), after.max(initial=1)))
    bins = np.arange(1, top + 2) - 0.5 if top <= 60 else 40
    # The first bar counts the classes seen from one pose: the legend counts them too.
    ax.hist(before[before > 0], bins=bins, alpha=0.5, label=f'after Algorithm 6.3 '
            f'({int((before > 0).sum())} classes, {int((before > 1).sum())} of them seen '
            f'from 2+ poses)')
    ax.hist(after, bins=bins, alpha=0.6, label=f'after the filters ({after.size} classes, '
            f'median {np.median(after) if after.size else 0:.0f} poses)')
    ax.set_xlabel('poses a feature class is seen from')
    ax.set_ylabel('classes')
    ax.set_yscale('log')
    ax.legend()
    ax.set_title('Feature visibility regions by size (thesis Figure 8.7)')
    fig.tight_layout()
    fig.savefig(folder / 'visibility_sizes.png', dpi=110)
    plt.close(fig)
    summary = report.summary()
    summary['database'] = {'regions': len(db.regions), 'classes': db.classes.n_classes,
                           'poses': db.poses.n_poses, 'k': db.info.k, 'rho': db.info.rho,
                           'sigma': db.info.sigma, 'algorithm': db.info.algorithm,
                           'pose_source': db.info.pose_source,
                           'service': db.service(result.world).to_dict()}
    write_text_atomic(folder / 'summary.json', json.dumps(summary, indent=2, default=str))

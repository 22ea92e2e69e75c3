"""The lens cameras and conditions, as bags the benchmark renders.

The lens rooms of ``vbn demo --camera`` (:data:`LENS_BAGS`, :func:`lens_render_argv`) and
the conditions of ``vbn bench-localize --conditions`` (:data:`CONDITIONS`): each names the
database it localizes against (the room's, a lens room's, or one built from its own
exploration) and the ``vbn render`` arguments of its run, and :func:`condition_targets`
gives the targets for it:

- ``level``: a level panorama run (seed 0, no image effects) on the room database, the
  reference of ``pitch2``;
- ``pitch2``: exploration and run pitched 2 degrees: median and p95 within 1.2 times
  ``level``'s;
- ``vibration``: a run shaking by 0.5 degrees (per-frame pitch and roll) on the level
  room database: p95 at most 5 cm;
- ``height``: a run camera 5 cm higher than the exploration's: 90 % posed, p95 10 cm;
- ``hires``: a 1280 x 960 pinhole run on the 640 x 480 pinhole room database;
- ``floor_pinhole``, ``floor_fisheye``: the 25 cm floor explored with 8 headings and its
  run, through the lens cameras;

and no pose more than 50 cm off in any of them. The lens rows (``hires`` and the floor)
have the lens room's targets (:data:`~vbn_bench.localization.demo.LENS_TARGETS`).
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any

__all__ = ['CONDITIONS', 'LENS_BAGS', 'LENS_HEADINGS', 'LENS_TRACKING_P95_S', 'Condition',
           'condition_targets', 'lens_render_argv', 'lens_targets']

#: The TRACKING latency target for a pinhole camera, one core.
LENS_TRACKING_P95_S = 0.012

#: ``vbn render`` settings of the lens cameras (the lens cameras' rows).
LENS_BAGS: dict[str, tuple[str, ...]] = {
    'pinhole': ('--camera', 'pinhole', '--distortion', 'plumb_bob:-0.3,0.08,0.0005,-0.0005,0'),
    'fisheye': ('--camera', 'fisheye', '--hfov', '180',
                '--distortion', 'equidistant:0.02,-0.005,0.001,0'),
}
#: Headings per position of the lens cameras' explorations.
LENS_HEADINGS = 8


def lens_render_argv(camera: str, kind: str, scene: str = 'room') -> list[str]:
    """Return ``vbn render``'s arguments (without ``--out``) of a lens camera's bag.

    Args:
        camera: ``pinhole`` or ``fisheye`` (:data:`LENS_BAGS`).
        kind: ``exploration`` (:data:`LENS_HEADINGS` headings per position) or ``run``.
        scene: the shipped scene (``room`` or ``floor``; explorations on a 25 cm grid).
    """
    extra = ['--kind', 'exploration', '--headings', str(LENS_HEADINGS)] \
        if kind == 'exploration' else ['--kind', kind]
    return ['render', '--scene', scene, *extra, *LENS_BAGS[camera], '--compressed']


#: The panoramic run of the conditions: the room's run path, seed 0, no image effects.
_PANORAMIC_RUN = ('render', '--scene', 'room', '--kind', 'run', '--camera', 'panoramic',
                  '--compressed')
#: ``bags/room_exploration``'s settings (the Makefile's sample bags), pitched 2 degrees.
_PITCHED_EXPLORATION = ('render', '--scene', 'room', '--kind', 'exploration', '--camera',
                        'panoramic', '--spacing', '0.25', '--compressed', '--jpeg-quality',
                        '85', '--camera-pitch', '2')


@dataclass(frozen=True)
class Condition:
    """One row of ``vbn bench-localize --conditions``.

    Attributes:
        name: The row's name.
        about: What it measures, one line.
        database: ``room`` (the benchmark's room database), ``pinhole`` or ``fisheye``
            (the lens room's), or the name of this condition's own exploration bag in
            the cache, rendered with ``exploration`` and built into the output folder.
        run: ``vbn render`` arguments of the run (without ``--out``).
        run_bag: the run bag's name in the cache.
        exploration: ``vbn render`` arguments of its own exploration, if any.
    """

    name: str
    about: str
    database: str
    run: tuple[str, ...]
    run_bag: str
    exploration: tuple[str, ...] = ()


CONDITIONS: dict[str, Condition] = {c.name: c for c in (
    Condition('level', 'level panorama (the reference of pitch2)', 'room', _PANORAMIC_RUN,
              'room_run_level'),
    Condition('pitch2', 'panorama pitched 2 deg, exploration and run',
              'room_exploration_pitch2', (*_PANORAMIC_RUN, '--camera-pitch', '2'),
              'room_run_pitch2', _PITCHED_EXPLORATION),
    Condition('vibration', 'run shaking 0.5 deg (per-frame pitch and roll)', 'room',
              (*_PANORAMIC_RUN, '--vibration', '0.5'), 'room_run_vibration'),
    Condition('height', 'run camera 5 cm higher than the exploration', 'room',
              (*_PANORAMIC_RUN, '--camera-height', '1.25'), 'room_run_height'),
    Condition('hires', 'pinhole run at 1280 x 960 on the 640 x 480 database', 'pinhole',
              (*lens_render_argv('pinhole', 'run'), '--width', '1280', '--height', '960'),
              'room_run_pinhole_hires'),
    *(Condition(f'floor_{camera}', f'25 cm floor, {about}, {LENS_HEADINGS} headings',
                f'floor_exploration_{camera}_lens',
                tuple(lens_render_argv(camera, 'run', 'floor')), f'floor_run_{camera}_lens',
                tuple(lens_render_argv(camera, 'exploration', 'floor')))
      for camera, about in (('pinhole', 'pinhole 90 deg plumb_bob'),
                            ('fisheye', 'fisheye 180 deg equidistant'))),
)}

#: Targets of the shaking and higher-camera rows, and pitch2's ratio to level.
VIBRATION_P95_M = 0.05
HEIGHT_P95_M = 0.10
HEIGHT_AVAILABILITY = 0.90
PITCH_RATIO = 1.2


def _accuracy(fig: dict[str, Any]) -> dict[str, Any]:
    return fig.get('evo') or fig.get('accuracy') or {}


def condition_targets(name: str, fig: dict[str, Any], runs: dict[str, dict[str, Any]]
                      ) -> list[tuple[str, float, float, bool]]:
    """Return the targets of one condition's run.

    Args:
        name: The condition (a key of :data:`CONDITIONS`).
        fig: Its ``vbn localize --json`` figures.
        runs: Every run's figures by row name (``cond_level`` for pitch2's reference).

    Returns:
        ``(label, measured, limit, at_most)`` rows.
    """
    from vbn_bench.localization.demo import LENS_MAX_ERROR_M

    row = f'cond_{name}'
    if name == 'hires' or name.startswith('floor_'):
        return lens_targets(row, fig, latency=name == 'floor_pinhole')
    acc = _accuracy(fig)
    checks = [(f'{row} largest translation error, m', acc.get('translation_max_m', math.nan),
               LENS_MAX_ERROR_M, True)]
    if name == 'pitch2':
        level = _accuracy(runs.get('cond_level') or {})
        for key, label in (('translation_median_m', 'median'), ('translation_p95_m', 'p95')):
            reference = level.get(key) or math.nan   # no level run (or 0): NaN, FAIL
            checks.append((f'{row} translation {label} / level',
                           acc.get(key, math.nan) / reference, PITCH_RATIO, True))
    elif name == 'vibration':
        checks.append((f'{row} translation p95 (evo), m', acc.get('translation_p95_m',
                                                                  math.nan),
                       VIBRATION_P95_M, True))
    elif name == 'height':
        checks.append((f'{row} translation p95 (evo), m', acc.get('translation_p95_m',
                                                                  math.nan),
                       HEIGHT_P95_M, True))
        checks.append((f'{row} availability', fig['availability'], HEIGHT_AVAILABILITY,
                       False))
    return checks


def lens_targets(row: str, fig: dict[str, Any], latency: bool
                 ) -> list[tuple[str, float, float, bool]]:
    """Return the lens room's targets of a run (and the pinhole's latency, if asked).

    Args:
        row: The run's name in the table.
        fig: Its ``vbn localize --json`` figures.
        latency: Also TRACKING p95 on one core (wall clock and CPU time), the
            640 x 480 pinhole's target.

    Returns:
        ``(label, measured, limit, at_most)`` rows.
    """
    from vbn_bench.localization.demo import LENS_MAX_ERROR_M, LENS_TARGETS

    acc = _accuracy(fig)
    checks = [(f'{row} {label}', acc.get(key, math.nan), LENS_TARGETS[key], True)
              for key, label in (('translation_median_m', 'translation median (evo), m'),
                                 ('translation_p95_m', 'translation p95 (evo), m'),
                                 ('heading_median_deg', 'heading median, deg'))]
    checks.append((f'{row} largest translation error, m', acc.get('translation_max_m',
                                                                  math.nan),
                   LENS_MAX_ERROR_M, True))
    checks.append((f'{row} availability', fig['availability'], LENS_TARGETS['availability'],
                   False))
    if latency:
        for key, label in (('latency', 'latency'), ('cpu_latency', 'CPU time')):
            value = (fig.get(key) or {}).get('tracking_p95')
            checks.append((f'{row} {label} TRACKING p95, s',
                           math.nan if value is None else float(value), LENS_TRACKING_P95_S,
                           True))
    return checks

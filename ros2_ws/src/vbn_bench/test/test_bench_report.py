"""vbn bench-localize's table: the room runs carry the targets, floor_run is reported."""
from __future__ import annotations

from vbn_bench.localization.report import report


def figures(availability: float, median: float, p95: float, tracking_p95: float,
            lost_p95: float, size: int = 10**6, **extra) -> dict:
    return {'frames': 100, 'poses': int(100 * availability), 'availability': availability,
            'changes': {'predicted': 9, 'after_loss': 1, 'predicted_fraction': 0.9},
            'evo': {'translation_median_m': median, 'translation_p95_m': p95,
                    'heading_median_deg': 0.1},
            'latency': {'p50': 0.005, 'p95': tracking_p95, 'tracking_p95': tracking_p95,
                        'lost_p95': lost_p95},
            'cpu_latency': {'tracking_p95': tracking_p95, 'lost_p95': lost_p95},
            'size_bytes': size, 'recovery': [1], 'db': 'x.db', **extra}


def test_room_targets_pass_and_floor_accuracy_is_reported_not_judged() -> None:
    coverage = {'inside': {'frames': 60, 'poses': 59, 'availability': 59 / 60,
                           'translation_median_m': 0.006, 'translation_p95_m': 0.034},
                'outside': {'frames': 40, 'poses': 30, 'availability': 0.75,
                            'translation_median_m': 0.016, 'translation_p95_m': 0.33}}
    runs = {'room_run': figures(1.0, 0.008, 0.046, 0.0086, 0.072),
            'room_run_kidnapped': figures(0.99, 0.006, 0.023, 0.009, 0.105),
            # Far from the room's accuracy targets, but they are not the floor's.
            'floor_run': figures(0.90, 0.008, 0.178, 0.0085, 0.064, 8 * 10**6,
                                 coverage=coverage)}
    text, passed = report(runs)
    assert passed, text
    assert 'floor_run translation p95' not in text  # no target row for the floor's accuracy
    assert "| inside the database's regions | 60 | 98.3 % | 0.60 cm | 3.40 cm | - |" in text
    assert "| outside the database's regions | 40 | 75.0 % | 1.60 cm | 33.00 cm | - |" in text
    runs['floor_run']['latency']['tracking_p95'] = 0.012  # the floor's latency is judged
    text, passed = report(runs)
    assert not passed and '| floor_run latency TRACKING p95, s | 0.012 | <= 0.01 | FAIL |' in text


def test_lens_rooms_carry_the_real_cameras_targets() -> None:
    pinhole = figures(0.96, 0.012, 0.07, 0.0115, 0.09)
    pinhole['evo'].update(translation_max_m=0.3, heading_median_deg=0.3)
    runs = {'room_run_pinhole': pinhole}
    text, passed = report(runs)
    assert passed, text
    assert '| room_run_pinhole availability | 0.96 | >= 0.95 | PASS |' in text
    assert '| room_run_pinhole largest translation error, m | 0.3 | <= 0.5 | PASS |' in text
    assert '| room_run_pinhole latency TRACKING p95, s | 0.0115 | <= 0.012 | PASS |' in text
    fisheye = figures(0.87, 0.006, 0.038, 0.02, 0.09)     # fisheye: no latency target
    fisheye['evo'].update(translation_max_m=0.6)
    text, passed = report({'room_run_fisheye': fisheye})
    assert not passed
    assert '| room_run_fisheye availability | 0.87 | >= 0.95 | FAIL |' in text
    assert '| room_run_fisheye largest translation error, m | 0.6 | <= 0.5 | FAIL |' in text
    assert 'room_run_fisheye latency' not in text


def test_conditions_carry_the_real_cameras_targets() -> None:
    """pitch2 against level (1.2x), vibration p95 5 cm, height 90 % / 10 cm, floor lens."""
    level = figures(1.0, 0.004, 0.015, 0.008, 0.05)
    pitched = figures(1.0, 0.0046, 0.019, 0.008, 0.05)   # median 1.15x, p95 1.27x level's
    shaking = figures(0.98, 0.011, 0.041, 0.008, 0.05)
    higher = figures(0.89, 0.003, 0.016, 0.008, 0.05)
    floor = figures(0.97, 0.01, 0.06, 0.013, 0.2)
    for fig in (level, pitched, shaking, higher, floor):
        fig['evo']['translation_max_m'] = 0.2
    text, passed = report({'cond_level': level, 'cond_pitch2': pitched,
                           'cond_vibration': shaking, 'cond_height': higher,
                           'cond_floor_pinhole': floor})
    assert not passed
    assert '| cond_pitch2 translation median / level | 1.15 | <= 1.2 | PASS |' in text
    assert '| cond_pitch2 translation p95 / level | 1.267 | <= 1.2 | FAIL |' in text
    assert '| cond_vibration translation p95 (evo), m | 0.041 | <= 0.05 | PASS |' in text
    assert '| cond_height availability | 0.89 | >= 0.9 | FAIL |' in text
    assert '| cond_floor_pinhole translation p95 (evo), m | 0.06 | <= 0.08 | PASS |' in text
    assert '| cond_floor_pinhole CPU time TRACKING p95, s | 0.013 | <= 0.012 | FAIL |' in text
    assert '| cond_level largest translation error, m | 0.2 | <= 0.5 | PASS |' in text


def test_condition_names_parse_and_pitch2_brings_its_reference() -> None:
    import pytest

    from landmark_localizer.errors import LocalizerError
    from vbn_bench.cli.bench_localize import _conditions
    from vbn_bench.localization.conditions import CONDITIONS, lens_render_argv

    assert _conditions('') == []
    assert _conditions('all') == list(CONDITIONS)
    assert _conditions('vibration, pitch2') == ['vibration', 'level', 'pitch2']
    with pytest.raises(LocalizerError, match="unknown condition 'tilt'"):
        _conditions('tilt')
    floor = CONDITIONS['floor_pinhole']
    assert floor.exploration == tuple(lens_render_argv('pinhole', 'exploration', 'floor'))
    assert floor.exploration[:3] == ('render', '--scene', 'floor')
    assert CONDITIONS['hires'].run[-4:] == ('--width', '1280', '--height', '960')


def test_runs_at_more_seeds_are_summed_up_per_run_and_each_carries_the_targets() -> None:
    """--seeds: the median of the runs' medians, the worst p95 and error, the peer beside."""
    def with_max(fig: dict, largest: float, heading: float) -> dict:
        fig['evo'].update(translation_max_m=largest, heading_median_deg=heading)
        return fig

    runs = {'room_run': with_max(figures(1.0, 0.0006, 0.0025, 0.011, 0.1), 0.008, 0.012),
            'room_run@s11': with_max(figures(0.99, 0.0008, 0.0041, 0.011, 0.1), 0.012, 0.014),
            'room_run@s12': with_max(figures(1.0, 0.0007, 0.0029, 0.011, 0.1), 0.02, 0.013),
            'room_run_effects': figures(1.0, 0.0007, 0.003, 0.011, 0.1)}
    for name in ('room_run', 'room_run@s11', 'room_run@s12'):
        runs[f'peer_tracking_{name}'] = with_max(
            figures(1.0, 0.0004, 0.001, 0.1, 0.1, peer={'mode': 'tracking',
                                                          'compact_bytes': 4 * 10**6}),
            0.002, 0.005)
    text, passed = report(runs)
    assert not passed
    assert ('| room_run, ours | base, 11, 12 | 0.070 cm | 0.410 cm | 2.00 cm | 0.0130 deg '
            '| 99.0 % |') in text
    assert ('| room_run, peer tracking | base, 11, 12 | 0.040 cm | 0.100 cm | 0.20 cm | '
            '0.0050 deg | 100.0 % |') in text
    assert 'room_run_effects, ours' not in text     # one run: nothing to sum up
    # Every seed has its own rows against the accuracy targets.
    assert '| room_run@s11 translation p95 (evo), m | 0.0041 | <= 0.003 | FAIL |' \
        in text
    assert '| room_run@s12 translation p95 (evo), m | 0.0029 | <= 0.003 | PASS |' \
        in text


def test_seed_runs_render_the_run_they_repeat_with_the_seed() -> None:
    import pytest

    from landmark_localizer.errors import LocalizerError
    from vbn_bench.localization.conditions import lens_render_argv
    from vbn_bench.localization.seeds import (
        family_of,
        parse_seeds,
        seed_bag_name,
        seed_render_argv,
        seed_run_name,
    )

    assert parse_seeds('') == [] and parse_seeds('3,11') == [3, 11]
    for bad in ('3,x', '-1', '4,4', '0', '1\u00b2', '\u0661'):
        with pytest.raises(LocalizerError, match='--seeds'):
            parse_seeds(bad)
    argv = seed_render_argv('room_run_effects', 7)
    assert argv[:2] == ['render', '--scene'] and argv[-4:] == ['--seed', '7', '--path-seed', '7']
    assert {'--blur', '--noise', '--exposure'} <= set(argv)
    assert seed_render_argv('room_run_pinhole', 7)[:-4] == lens_render_argv('pinhole', 'run')
    assert 'run-kidnapped' in seed_render_argv('room_run_kidnapped', 7)
    assert seed_bag_name('room_run_fisheye', 7) == 'room_run_fisheye_lens_s7'
    assert family_of(seed_run_name('room_run_kidnapped', 7)) == ('room_run_kidnapped', 7)
    with pytest.raises(LocalizerError, match='no run family'):
        seed_render_argv('floor_run', 7)


def test_seed_runs_carry_their_runs_targets_without_the_peer_and_a_missing_figure_is_worst(
        ) -> None:
    """A seed run is judged as the run it repeats; a run with no figure is not left out."""
    kidnapped = figures(1.0, 0.0006, 0.002, 0.011, 0.1)
    lost = figures(0.5, 0.0006, 0.002, 0.011, 0.1, recovery=[None])
    lens = figures(0.96, 0.0012, 0.007, 0.0115, 0.09)
    lens['evo'].update(translation_max_m=0.3)
    runs = {'room_run_kidnapped': kidnapped, 'room_run_kidnapped@s11': lost,
            'room_run_pinhole': lens, 'room_run_pinhole@s11': dict(lens, evo=None,
                                                                   accuracy=None)}
    text, passed = report(runs)
    assert not passed
    assert '| room_run_kidnapped frames to a correct pose | 1 | <= 3 | PASS |' in text
    assert '| room_run_kidnapped@s11 frames to a correct pose | nan | <= 3 | FAIL |' in text
    assert '| room_run_pinhole@s11 availability | 0.96 | >= 0.95 | PASS |' in text
    # The seed run without accuracy figures: the family's worst p95 is unknown, not 0.7 cm.
    assert '| room_run_pinhole, ours | base, 11 | - | - | - | - | 96.0 % |' in text

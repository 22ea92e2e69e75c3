"""End-to-end tests of the decomposition benchmark (vbn bench-decomposition)."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from landmark_db.errors import LandmarkDbError
from vbn_bench.cli import bench_decomposition
from vbn_bench.decomposition.reference import THESIS_TABLE_8_2, THESIS_TABLE_8_3, THESIS_TABLE_8_4
from vbn_bench.decomposition.report import (
    approximation_ratios,
    format_report,
    improvement_over_b2,
    summarize,
)
from vbn_bench.decomposition.runner import (
    REDUCED,
    SMALL,
    BenchConfig,
    RunRecord,
    planned_worlds,
    run_benchmark,
)


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog='vbn')
    subparsers = parser.add_subparsers(dest='command')
    bench_decomposition.register(subparsers)
    return parser.parse_args(['bench-decomposition', *argv])


def test_bench_end_to_end_writes_tables_results_and_figures(tmp_path: Path,
                                                            capsys: pytest.CaptureFixture
                                                            ) -> None:
    args = _parse(['--worlds', '1', '--settings', '2', '--reduced', '--small-worlds', '1',
                   '--algorithms', 'A1,B2,C', '--processes', '1', '--out', str(tmp_path)])
    assert args.func(args) == 0
    captured = capsys.readouterr()
    out = captured.out
    # Progress: one world of the main tables and one small world, counted apart.
    assert 'worlds (reduced size): 100%' in captured.err and '1/1' in captured.err
    assert 'small worlds (with exact): 100%' in captured.err
    assert 'Table 8.2' in out and 'Table 8.3' in out and 'Table 8.4' in out
    # The thesis's numbers are printed beside ours.
    assert f"[{THESIS_TABLE_8_2[2]['B2']:.2f}]" in out
    assert f"[{THESIS_TABLE_8_3[2]['A1']:.2f}]" in out
    assert 'passed the validator' in out
    for name in ('results.json', 'results.csv', 'tables.txt', 'fig_8_3_bars.png',
                 'decomposition_setting2.png', 'decomposition_setting2_B2.png',
                 'decomposition_k_rho_sweep.png'):
        path = tmp_path / name
        assert path.exists() and path.stat().st_size > 0, name
    assert (tmp_path / 'fig_8_3_bars.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    results = json.loads((tmp_path / 'results.json').read_text())
    records = results['records']
    # One reduced main world x 3 algorithms + one small world x (3 + exact).
    assert len(records) == 3 + 4
    assert all(r['valid'] for r in records)
    assert {r['algorithm'] for r in records} == {'A1', 'B2', 'C', 'exact'}
    exact = next(r for r in records if r['algorithm'] == 'exact')
    ratios = results['approximation_ratios']
    for alg in ('A1', 'B2', 'C'):
        heuristic = next(r for r in records if r['algorithm'] == alg and
                         r['world_class'] == SMALL)
        # The exact optimum is never beaten by a heuristic on the same world.
        assert heuristic['regions'] >= exact['regions']
        assert ratios[alg]['mean'] == pytest.approx(heuristic['regions'] / exact['regions'])
    assert results['thesis_reference']['table_8_4']['2'] == THESIS_TABLE_8_4[2]
    csv_lines = (tmp_path / 'results.csv').read_text().splitlines()
    assert len(csv_lines) == 1 + len(records)


def test_bench_rejects_bad_arguments(tmp_path: Path) -> None:
    for argv, message in ((['--settings', '5'], 'settings'), (['--worlds', '0'], 'worlds'),
                          (['--algorithms', 'Z9'], 'algorithm'),
                          (['--settings', 'a,b'], 'settings')):
        args = _parse([*argv, '--out', str(tmp_path)])
        with pytest.raises(LandmarkDbError, match=message):
            args.func(args)


def test_results_do_not_depend_on_process_count() -> None:
    config = BenchConfig(settings=(3,), worlds=2, reduced=True, small_worlds=0,
                         algorithms=('A3', 'B1'), processes=1)
    one, _ = run_benchmark(config)
    two, _ = run_benchmark(BenchConfig(**{**config.__dict__, 'processes': 2}))
    key = [(r.world_seed, r.algorithm, r.regions, r.used_features, r.uncovered) for r in one]
    assert key == [(r.world_seed, r.algorithm, r.regions, r.used_features, r.uncovered)
                   for r in two]
    assert len({r.world_seed for r in one}) == 2


def _record(algorithm: str, regions: int, seed: int = 0, world_class: str = 'full',
            setting: int = 1, valid: bool = True) -> RunRecord:
    return RunRecord(world_class=world_class, setting=setting, world_seed=seed,
                     algorithm=algorithm, k=4, rho=1, sigma=9, n_poses=100, n_edges=180,
                     n_features=50, mean_visible=10.0, n_coverable=90, regions=regions,
                     mean_region_poses=100 / max(regions, 1), used_features=4 * regions,
                     seconds=0.1, valid=valid, problems=[] if valid else ['bad'])


def test_summary_improvement_and_ratios_by_hand() -> None:
    records = [_record('B2', 10, 0), _record('B2', 20, 1), _record('best', 9, 0),
               _record('best', 18, 1), _record('best', 1, 2, valid=False)]
    summary = summarize(records)
    cells = {(c['algorithm']): c for c in summary['cells']}
    assert cells['B2']['regions'] == 15
    assert cells['best']['regions'] == 13.5  # the invalid run is left out of the means
    assert cells['best']['invalid'] == 1
    assert improvement_over_b2(summary)['1'] == pytest.approx(10.0)
    small = [_record('exact', 4, 0, SMALL), _record('B2', 5, 0, SMALL),
             _record('exact', 5, 1, SMALL), _record('B2', 5, 1, SMALL)]
    ratios = approximation_ratios(small)
    assert ratios['B2']['mean'] == pytest.approx((5 / 4 + 1) / 2)
    assert ratios['B2']['max'] == pytest.approx(1.25)
    assert ratios['B2']['optimal_share'] == pytest.approx(0.5)
    assert ratios['exact']['mean_regions'] == pytest.approx(4.5)


def test_report_says_fewer_or_more_regions_not_a_backwards_sign() -> None:
    # Regression: 'best' with fewer regions than B2 was printed as '+10.0%'.
    fewer = summarize([_record('B2', 10, 0), _record('best', 9, 0)])
    line = next(x for x in format_report(fewer, [], ['B2', 'best']).splitlines()
                if "'best' against B2" in x)
    assert line == ("Regions of the new heuristic 'best' against B2: setting 1: 10.0 % fewer; "
                    'mean over settings 10.0 % fewer')
    more = summarize([_record('B2', 10, 0), _record('best', 11, 0)])
    line = next(x for x in format_report(more, [], ['B2', 'best']).splitlines()
                if "'best' against B2" in x)
    assert '+' not in line and line.endswith('setting 1: 10.0 % more; '
                                             'mean over settings 10.0 % more')


def test_progress_counts_worlds_and_small_worlds_separately() -> None:
    # Regression: the '--worlds' counter's total included the small worlds.
    config = BenchConfig(settings=(3, 4), worlds=2, reduced=True, small_worlds=1,
                         algorithms=('B1',), processes=1)
    assert planned_worlds(config) == {REDUCED: 4, SMALL: 2}
    calls: list[tuple[str, int, int]] = []
    run_benchmark(config, progress=lambda *call: calls.append(call))
    assert calls == [(REDUCED, 1, 4), (REDUCED, 2, 4), (REDUCED, 3, 4), (REDUCED, 4, 4),
                     (SMALL, 1, 2), (SMALL, 2, 2)]


def test_reference_tables_are_complete() -> None:
    for table in (THESIS_TABLE_8_2, THESIS_TABLE_8_3):
        assert sorted(table) == [1, 2, 3, 4]
        assert all(sorted(row) == ['A1', 'A2', 'A3', 'B1', 'B2', 'C'] for row in table.values())
    # Spot checks against the thesis text.
    assert THESIS_TABLE_8_2[1]['B2'] == 112.63
    assert THESIS_TABLE_8_3[4]['C'] == 218.56
    assert np.allclose([THESIS_TABLE_8_4[s] for s in (1, 2, 3, 4)], [30, 95, 41, 117])


def test_scaling_world_meets_its_targets() -> None:
    from vbn_bench.decomposition.scaling import format_scaling, run_scaling, scaling_world

    simulated = scaling_world(2_000, 600, seed=1)
    assert simulated.world.n_features == 600
    assert 1_600 < simulated.world.n_poses < 2_400
    rows = run_scaling(((1_000, 300),), algorithms=('B2',))
    assert rows[0]['valid'] and rows[0]['regions'] > 0
    assert 'B2' in format_scaling(rows)


def test_scaling_and_calibration_write_their_files(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    from vbn_bench.decomposition import scaling

    monkeypatch.setattr(scaling, 'DEFAULT_SIZES', ((600, 200),))
    args = _parse(['--scaling', '--scaling-algorithms', 'B1,B2', '--out', str(tmp_path)])
    assert args.func(args) == 0
    err = capsys.readouterr().err
    assert 'scaling runs: 100%' in err and '2/2' in err
    rows = json.loads((tmp_path / 'scaling.json').read_text())
    assert [r['algorithm'] for r in rows] == ['B1', 'B2'] and all(r['valid'] for r in rows)
    assert (tmp_path / 'scaling.txt').read_text().startswith('Scaling run')
    args = _parse(['--calibrate', '--worlds', '1', '--settings', '4', '--processes', '1',
                   '--out', str(tmp_path)])
    assert args.func(args) == 0
    assert [r['setting'] for r in json.loads((tmp_path / 'calibration.json').read_text())] == [4]
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith('.')) == []

"""``vbn demo --camera``: which bags the demo uses, and the lens targets it checks."""
from __future__ import annotations

import argparse
from pathlib import Path

from vbn_bench.cli import demo
from vbn_bench.localization.demo import LENS_MAX_ERROR_M, LENS_TARGETS
from vbn_bench.localization.evaluation import Thresholds


def _args(**values) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    demo.register(parser.add_subparsers())
    return parser.parse_args(['demo', *sum(([f'--{k}', v] for k, v in values.items()), [])])


def test_panoramic_demo_uses_the_sample_bags(tmp_path: Path) -> None:
    args = _args(out=str(tmp_path))
    demo._bags(args, tmp_path)
    assert (args.exploration, args.run) == ('bags/room_exploration', 'bags/room_run')


def test_lens_demo_reuses_its_rendered_bags(tmp_path: Path, monkeypatch) -> None:
    for kind in ('exploration', 'run'):
        bag = tmp_path / f'room_{kind}_pinhole'
        bag.mkdir()
        (bag / 'metadata.yaml').write_text('rosbag2_bagfile_information: {}\n')
    calls = []
    monkeypatch.setattr(demo, 'run_command', lambda *a, **k: calls.append(a))
    args = _args(out=str(tmp_path), camera='pinhole')
    demo._bags(args, tmp_path)
    assert args.exploration == str(tmp_path / 'room_exploration_pinhole')
    assert args.run == str(tmp_path / 'room_run_pinhole')
    assert calls == []                                  # nothing rendered again


def test_lens_demo_renders_what_is_missing(tmp_path: Path, monkeypatch) -> None:
    calls = []

    def fake_run(argv, log, **kwargs):
        calls.append(argv)

    monkeypatch.setattr(demo, 'run_command', fake_run)
    args = _args(out=str(tmp_path), camera='fisheye', run='my_run')
    demo._bags(args, tmp_path)
    assert args.run == 'my_run'                          # given: kept
    assert len(calls) == 1
    argv = calls[0]
    assert argv[0] == 'render'
    assert argv[argv.index('--kind') + 1] == 'exploration'
    assert argv[argv.index('--headings') + 1] == str(demo.LENS_HEADINGS)
    assert argv[argv.index('--camera') + 1] == 'fisheye'
    assert argv[argv.index('--distortion') + 1].startswith('equidistant:')
    assert argv[argv.index('--out') + 1] == str(tmp_path / 'room_exploration_fisheye')


def test_lens_targets_are_the_documented_ones() -> None:
    t = Thresholds(**LENS_TARGETS)
    assert (t.availability, t.translation_median_m, t.translation_p95_m,
            t.heading_median_deg) == (0.95, 0.02, 0.08, 0.5)
    assert LENS_MAX_ERROR_M == 0.5


def test_the_demo_load_is_busy_processes_that_go_away() -> None:
    from vbn_bench.cli.demo import _busy

    hogs = _busy(2)
    try:
        assert len(hogs) == 2 and all(h.poll() is None for h in hogs)
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()
    assert all(h.returncode is not None for h in hogs)
    assert _busy(0) == []

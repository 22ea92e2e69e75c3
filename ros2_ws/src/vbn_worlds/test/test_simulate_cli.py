"""Tests of ``vbn simulate``."""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

from landmark_db.scene import load_scene
from landmark_db.world import load_world
from vbn_worlds.cli import simulate
from vbn_worlds.errors import WorldsError


def _run(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog='vbn')
    simulate.register(parser.add_subparsers(dest='command'))
    args = parser.parse_args(['simulate', *argv])
    return args.func(args)


def test_simulate_writes_world_and_scene_deterministically(tmp_path: Path) -> None:
    a, b = tmp_path / 'a.json', tmp_path / 'b.json'
    scene_path = tmp_path / 'scene.json'
    assert _run(['--setting', '4', '--seed', '3', '--small', '--out', str(a),
                 '--scene-out', str(scene_path)]) == 0
    assert _run(['--setting', '4', '--seed', '3', '--small', '--out', str(b)]) == 0
    assert a.read_bytes() == b.read_bytes()
    world = load_world(a)
    scene = load_scene(scene_path)
    assert world.n_poses > 50
    # The world JSON lists only features seen from some pose; ids are scene rows.
    assert 0 < world.n_features <= len(scene.features)
    assert world.feature_ids.max() < len(scene.features)
    assert world.spacing == 0.5
    assert np.all(scene.free_space(world.poses))
    # Every edge joins grid neighbours 0.5 m apart.
    lengths = np.linalg.norm(world.poses[world.edges[:, 0]] - world.poses[world.edges[:, 1]],
                             axis=1)
    np.testing.assert_allclose(lengths, 0.5)
    c = tmp_path / 'c.json'
    assert _run(['--setting', '4', '--seed', '4', '--small', '--out', str(c)]) == 0
    assert c.read_bytes() != a.read_bytes()


def test_simulate_spacing_option(tmp_path: Path) -> None:
    out = tmp_path / 'w.json'
    assert _run(['--setting', '1', '--seed', '0', '--spacing', '1.0', '--out', str(out)]) == 0
    world = load_world(out)
    assert world.spacing == 1.0
    # A full-size world (about 40 m across) at 1 m spacing has about 1,500 poses.
    assert 800 < world.n_poses < 2500


@pytest.mark.parametrize('argv, message', [
    (['--seed', '-1'], 'seed'),
    (['--seed', '0', '--spacing', '0'], 'spacing'),
    (['--seed', '0', '--spacing', 'nan'], 'spacing'),
])
def test_simulate_rejects_bad_input(tmp_path: Path, argv: list[str], message: str) -> None:
    with pytest.raises(WorldsError, match=message):
        _run(['--setting', '1', *argv, '--out', str(tmp_path / 'w.json')])

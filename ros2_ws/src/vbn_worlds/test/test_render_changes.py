"""A world that changed after its exploration: furniture, posters, light, people, paths.

Hand-checked geometry on a 4 m square room: a table's rows in a panorama, what the
changes keep of the explored walls; and properties of the drawn change sets.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from landmark_db.scene import Scene
from vbn_common.geometry.camera import PanoramicCamera
from vbn_worlds.errors import WorldsError
from vbn_worlds.render.renderer import Occluders, Renderer
from vbn_worlds.render.textures import Appearance, build_wall_atlas
from vbn_worlds.synthesis.bags import BagSpec, write_bag
from vbn_worlds.synthesis.people import walkers
from vbn_worlds.synthesis.trajectory import run_trajectory
from vbn_worlds.synthesis.world_changes import (
    Furniture,
    WorldChanges,
    load_changes,
    random_changes,
)

SQUARE = Scene(np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]]),
               wall_height=2.5, camera_height=1.2, texture_seed=1, name='square')
HALL = Scene(np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 6.0], [0.0, 6.0]]),
             obstacles=(np.array([[4.0, 2.5], [5.0, 2.5], [5.0, 3.5], [4.0, 3.5]]),),
             texture_seed=3, name='hall')
TABLE = np.array([[2.5, 1.5], [3.0, 1.5], [3.0, 2.5], [2.5, 2.5]])


@pytest.fixture(scope='module')
def atlas():
    return build_wall_atlas(SQUARE, texels_per_metre=80)


def test_a_table_hides_the_wall_below_its_top_only(atlas) -> None:
    camera = PanoramicCamera(512, 128)
    renderer = Renderer(SQUARE, camera, atlas)
    pose = np.array([1.0, 2.0, 0.0])       # facing the east wall 3 m away; table at 1.5 m
    bare = renderer.render(pose, with_points=True)
    table = Occluders.boxes([TABLE], [0.75], [(40.0, 80.0, 160.0)])
    out = renderer.render(pose, with_points=True, occluders=table)
    col = int(camera.cx)
    # The table's front face at 1.5 m: from its top (0.75 m) down to the floor.
    top = camera.horizon_row + camera.f_vertical * (1.2 - 0.75) / 1.5
    bottom = camera.horizon_row + camera.f_vertical * 1.2 / 1.5
    changed = np.flatnonzero(np.any(out.image[:, col] != bare.image[:, col], axis=-1))
    assert changed.min() == math.ceil(top)
    assert changed.max() == min(math.floor(bottom), camera.height - 1)
    # Above its top the wall shows as explored, and its points are the wall's.
    np.testing.assert_array_equal(out.image[:changed.min(), col], bare.image[:changed.min(), col])
    assert np.isnan(out.wall_points[changed, col]).all()
    above = np.flatnonzero(~np.isnan(bare.wall_points[:changed.min(), col, 0]))
    np.testing.assert_array_equal(out.wall_points[above, col], bare.wall_points[above, col])
    # Behind the camera nothing changed.
    np.testing.assert_array_equal(out.image[:, 0], bare.image[:, 0])
    # A person (1.75 m, above the camera) hides the wall up to 0.55 m above the camera
    # at 1.5 m: at 3 m, the wall up to 2.3 m.
    person = Occluders.boxes([TABLE], [1.75], [(200.0, 60.0, 60.0)])
    hidden = renderer.render(pose, with_points=True, occluders=person)
    head = math.ceil(camera.horizon_row - camera.f_vertical * (1.75 - 1.2) / 1.5)
    assert np.isnan(hidden.wall_points[head:, col]).all()
    seen = hidden.wall_points[:head, col, 2]
    assert seen[~np.isnan(seen)].min() == pytest.approx(2.3, abs=0.05)


def test_the_default_appearance_is_the_explored_one_and_changes_touch_their_walls(atlas
                                                                                  ) -> None:
    same = build_wall_atlas(SQUARE, texels_per_metre=80, appearance=Appearance())
    np.testing.assert_array_equal(same.mip, atlas.mip)
    rehung = build_wall_atlas(SQUARE, texels_per_metre=80,
                              appearance=Appearance(rehung=(1,), bare=(2,)))

    def wall(a, j):
        x, y = a.origins[j].astype(int)
        w, h = a.extents[j].astype(int)
        return a.levels[0][y:y + h, x:x + w].astype(float)

    for j in (0, 3):
        np.testing.assert_array_equal(wall(rehung, j), wall(atlas, j))
    assert np.abs(wall(rehung, 1) - wall(atlas, 1)).mean() > 1.0
    # Posters down: the bare wall has less texture than before.
    edges = [np.abs(np.diff(wall(a, 2), axis=1)).mean() for a in (atlas, rehung)]
    assert edges[1] < 0.7 * edges[0]
    dark = build_wall_atlas(SQUARE, texels_per_metre=80, appearance=Appearance(gain=0.5))
    ratio = wall(dark, 0).mean() / wall(atlas, 0).mean()
    assert ratio == pytest.approx(0.5, abs=0.02)
    # A light from the east: the wall facing it (the west wall, normal +x) brightens.
    side = Appearance(side_deg=0.0, side_strength=0.5)
    normals = np.array([[1.0, 0.0], [-1.0, 0.0]])
    np.testing.assert_allclose(side.shade(normals) / Appearance().shade(normals), [1.5, 0.5])


def test_change_sets_round_trip_and_bad_ones_are_named(tmp_path: Path) -> None:
    changes = WorldChanges((Furniture(TABLE, 0.75, (1.0, 2.0, 3.0)),),
                           Appearance(0.7, 90.0, 0.4, (1,), (2,), 5), people=2, seed=4)
    path = tmp_path / 'changes.json'
    path.write_text(json.dumps(changes.to_dict()))
    back = load_changes(path)
    assert back.appearance == changes.appearance and back.people == 2 and back.seed == 4
    np.testing.assert_array_equal(back.furniture[0].footprint, TABLE)
    back.check(SQUARE)
    with pytest.raises(WorldsError, match='posters bare wall 9'):
        WorldChanges(appearance=Appearance(bare=(9,))).check(SQUARE)
    outside = Furniture(TABLE + 5.0, 0.75)
    with pytest.raises(WorldsError, match=r'furniture\[0\] does not stand'):
        WorldChanges((outside,)).check(SQUARE)
    path.write_text('{"furniture": [{"footprint": [[0, 0], [1, 1]], "height": 1}]}')
    with pytest.raises(WorldsError, match='footprint must be three or more'):
        load_changes(path)
    path.write_text('{"chairs": 3}')
    with pytest.raises(WorldsError, match="unknown field 'chairs'"):
        load_changes(path)
    with pytest.raises(WorldsError, match='missing.json'):
        load_changes(tmp_path / 'missing.json')


@pytest.mark.parametrize('seed', [1, 2, 3])
def test_random_changes_leave_a_passage_and_keep_the_old_walls(seed: int) -> None:
    changes = random_changes(HALL, seed)
    again = random_changes(HALL, seed)
    assert again.to_dict() == changes.to_dict()
    assert len(changes.furniture) == 3
    starts, _, _ = HALL.wall_segments()
    for piece in changes.furniture:
        assert HALL.wall_distance(piece.footprint).min() >= 0.6 - 1e-9
    # New walls come after the old ones: the old ones keep their indices and textures.
    drawn = changes.render_scene(HALL)
    np.testing.assert_array_equal(drawn.wall_segments()[0][:len(starts)], starts)
    # The run goes round every piece, low or high.
    run = run_trajectory(changes.planning_scene(HALL), path_seed=seed)
    assert changes.planning_scene(HALL).free_space(run.poses[:, :2]).all()
    assert 0.5 <= changes.appearance.gain <= 1.5


def test_run_paths_change_with_the_path_seed() -> None:
    own = run_trajectory(HALL)
    np.testing.assert_array_equal(run_trajectory(HALL, path_seed=0).poses, own.poses)
    paths = [run_trajectory(HALL, path_seed=s) for s in (1, 2)]
    for path in paths:
        assert HALL.free_space(path.poses[:, :2]).all()
        assert HALL.wall_distance(path.poses[:, :2]).min() >= 0.3 * 0.8 - 1e-6
        n = min(len(path.poses), len(own.poses))
        assert np.abs(path.poses[:n, :2] - own.poses[:n, :2]).max() > 0.5
    n = min(len(paths[0].poses), len(paths[1].poses))
    assert np.abs(paths[0].poses[:n, :2] - paths[1].poses[:n, :2]).max() > 0.5


def test_walkers_stay_in_the_free_space_and_move() -> None:
    people = walkers(HALL, 3, seed=7, duration_s=30.0)
    before = None
    for t in np.linspace(0.0, 30.0, 61):
        xy, _ = people.positions(float(t))
        assert HALL.free_space(xy).all() and HALL.wall_distance(xy).min() >= 0.35 - 1e-6
        before = xy if before is None else before
    moved = np.linalg.norm(people.positions(30.0)[0] - people.positions(0.0)[0], axis=1)
    assert (moved > 0.5).any()
    assert len(people.occluders(3.0)) == 3 * 4
    # A walker does not stand in the robot: one within half a metre of it is left out.
    xy, _ = people.positions(3.0)
    assert len(people.occluders(3.0, xy[0])) == 2 * 4
    assert len(people.occluders(3.0, xy[0] + [0.2, 0.3])) == 2 * 4
    assert len(people.occluders(3.0, np.array([-50.0, -50.0]))) == 3 * 4
    np.testing.assert_array_equal(walkers(HALL, 3, seed=7, duration_s=30.0).places[0],
                                  people.places[0])


def test_a_changed_world_run_bag_goes_round_the_furniture(tmp_path: Path) -> None:
    changes = WorldChanges((Furniture(np.array([[6.5, 1.0], [7.5, 1.0], [7.5, 2.0],
                                                [6.5, 2.0]]), 0.8),),
                           Appearance(gain=0.6), people=1, seed=2)
    spec = BagSpec(kind='run', width=128, height=32, duration=4.0, seed=1, changes=changes)
    summary = write_bag(HALL, spec, tmp_path / 'run')
    assert summary.images == 41
    with pytest.raises(WorldsError, match='does not stand'):
        write_bag(HALL, BagSpec(kind='run', width=128, height=32, duration=1.0,
                                changes=WorldChanges((Furniture(TABLE + 20.0, 0.8),))),
                  tmp_path / 'bad')
    assert not (tmp_path / 'bad').exists()

"""Tests of the decomposition pictures."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from landmark_db.scene import Scene
from landmark_db.world import WorldInstance
from vbn_common.palette import PALETTE_HEX, region_colours
from visibility_builder.plotting import (
    _mask_outline,
    grid_cells,
    save_decomposition_figure,
)


def _grid_world(nx: int = 6, ny: int = 4) -> WorldInstance:
    xs, ys = np.meshgrid(np.arange(nx) * 0.5, np.arange(ny) * 0.5)
    poses = np.stack([xs.ravel(), ys.ravel()], axis=1) + 0.25
    index = np.arange(nx * ny).reshape(ny, nx)
    edges = np.concatenate([np.stack([index[:, :-1].ravel(), index[:, 1:].ravel()], axis=1),
                            np.stack([index[:-1].ravel(), index[1:].ravel()], axis=1)])
    visible = np.ones((nx * ny, 5), dtype=bool)
    visible[0, :] = False  # one pose sees nothing
    return WorldInstance.from_visibility(poses, edges, visible, spacing=0.5, name='grid')


def test_save_decomposition_figure_writes_a_png(tmp_path: Path) -> None:
    world = _grid_world()
    scene = Scene(np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 2.0], [0.0, 2.0]]))
    regions = [np.arange(1, 12), np.arange(10, 24)]
    path = save_decomposition_figure(tmp_path / 'd.png', world, regions, k=4,
                                     uncovered=[5], scene=scene, title='two regions')
    data = path.read_bytes()
    assert data[:8] == b'\x89PNG\r\n\x1a\n'
    assert len(data) > 2000


def test_grid_cells_recover_the_grid() -> None:
    world = _grid_world(6, 4)
    ix, iy, spacing, origin = grid_cells(world)
    assert spacing == 0.5
    np.testing.assert_allclose(origin, [0.25, 0.25])
    assert ix.max() == 5 and iy.max() == 3
    np.testing.assert_array_equal(ix[:6], np.arange(6))


def test_outline_of_one_cell_is_its_four_sides() -> None:
    mask = np.zeros((3, 4), dtype=bool)
    mask[1, 1] = True  # padded; unpadded cell (0, 0) spans [0, 1] x [0, 1]
    segments = _mask_outline(mask)
    assert len(segments) == 4
    corners = {tuple(p) for seg in segments for p in seg.tolist()}
    assert corners == {(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)}
    # A 2 x 1 block has a perimeter of 6 unit segments.
    mask[1, 2] = True
    assert len(_mask_outline(mask)) == 6


def test_region_colours_are_distinct_and_reproducible() -> None:
    a = region_colours(30)
    assert a.shape == (30, 4)
    assert len({tuple(c) for c in a}) == 30
    np.testing.assert_array_equal(a, region_colours(30))


def test_the_palette_is_matplotlibs_tab20_tab20b_and_set3() -> None:
    from matplotlib import colormaps

    theirs = np.concatenate([colormaps[name](np.arange(colormaps[name].N))
                             for name in ('tab20', 'tab20b', 'Set3')])
    assert len(PALETTE_HEX) == 52
    np.testing.assert_array_equal(region_colours(52, seed=0)[np.argsort(
        np.random.default_rng(0).permutation(52))], theirs)

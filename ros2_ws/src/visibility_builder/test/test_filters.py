"""Good-feature filters (visibility_builder.filters) on hand-drawn lattices."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.filters import FilterConfig, retain_good_features

ALL = FilterConfig(min_poses=0, largest_component=False, convex_trim=False, min_block=0)


def lattice(width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """All cells of a width x height lattice as poses (row-major), 4-connected edges."""
    grid = np.array([(x, y) for y in range(height) for x in range(width)])
    index = np.arange(width * height).reshape(height, width)
    edges = np.vstack([np.c_[index[:, :-1].ravel(), index[:, 1:].ravel()],
                       np.c_[index[:-1].ravel(), index[1:].ravel()]])
    return grid, edges


def draw(*rows: str) -> np.ndarray:
    """A visibility column from a drawing; the first string is the top row (largest y)."""
    picture = np.array([[c == '#' for c in row] for row in rows[::-1]])
    return picture.ravel()


def run(columns: list[np.ndarray], width: int, height: int, config: FilterConfig):
    grid, edges = lattice(width, height)
    vis = sp.csr_matrix(np.column_stack(columns))
    return retain_good_features(vis, grid, edges, config)


def region(result, column: int, width: int, height: int) -> list[str]:
    pic = result.visibility[:, column].toarray().ravel().reshape(height, width)[::-1]
    return [''.join('#' if c else '.' for c in row) for row in pic]


def test_region_with_a_hole_survives_the_trim():
    ring = draw('........',
                '.######.',
                '.######.',
                '.##.###.',
                '.######.',
                '.######.',
                '........')
    result = run([ring], 8, 7, FilterConfig(min_poses=16))
    assert result.kept_classes.tolist() == [0]
    assert result.visibility.sum() == 29          # every pose keeps a 7-of-8 neighbour
    assert region(result, 0, 8, 7)[3] == '.##.###.'
    assert [s.classes for s in result.steps] == [1, 1, 1, 1, 1]   # a 3 x 3 block avoids it


def test_largest_component_is_kept():
    two = draw('##....',
               '##..##',
               '....##',
               '....##')
    result = run([two], 6, 4, FilterConfig(min_poses=0, largest_component=True,
                                           convex_trim=False, min_block=0))
    assert region(result, 0, 6, 4) == ['......', '....##', '....##', '....##']
    assert [s.name for s in result.steps] == ['input', 'largest_component']


def test_seven_of_eight_rule_removes_a_thin_line():
    blob = draw('###.....',
                '########',
                '###.....')
    result = run([blob], 8, 3, FilterConfig(min_poses=0, largest_component=False,
                                            convex_trim=True, min_block=0))
    assert region(result, 0, 8, 3) == ['###.....', '###.....', '###.....']


def test_two_by_five_strip_has_no_core_and_is_trimmed_away():
    strip = draw('#####',
                 '#####',
                 '.....')
    result = run([strip], 5, 3, FilterConfig(min_poses=0, min_block=0))
    assert result.kept_classes.tolist() == []
    assert result.steps[-1].name == 'convex_trim' and result.steps[-1].entries == 0


def test_three_by_three_block_is_kept_and_two_by_five_strip_removed():
    block = draw('###..',
                 '###..',
                 '###..')
    strip = draw('#####',
                 '#####',
                 '.....')
    config = FilterConfig(min_poses=0, largest_component=False, convex_trim=False, min_block=3)
    result = run([block, strip], 5, 3, config)
    assert result.kept_classes.tolist() == [0]
    assert result.visibility.shape == (15, 1)
    assert result.steps[-1].name == 'min_block' and result.steps[-1].classes == 1
    looser = run([block, strip], 5, 3, FilterConfig(min_poses=0, largest_component=False,
                                                    convex_trim=False, min_block=2))
    assert looser.kept_classes.tolist() == [0, 1]


def test_min_poses_and_counts_after_each_step():
    small = draw('##.', '##.', '...')                     # 4 poses
    big = draw('###', '###', '###')                       # 9 poses
    line = draw('###', '...', '...')                      # 3 poses
    result = run([small, big, line], 3, 3, FilterConfig(min_poses=4))
    steps = {s.name: (s.classes, s.entries) for s in result.steps}
    assert steps['input'] == (3, 16)
    assert steps['min_poses'] == (2, 13)
    assert steps['largest_component'] == (2, 13)
    assert steps['convex_trim'] == (1, 9)     # the 2 x 2 has no core pose of its own
    assert steps['min_block'] == (1, 9)
    assert result.kept_classes.tolist() == [1]
    assert result.sizes_before.tolist() == [4, 9, 3]
    assert result.sizes_after.tolist() == [9]
    assert result.counts_dict()['min_block_classes'] == 1
    edges, before, after = result.size_histogram(bins=3)
    assert before.sum() == 3 and after.sum() == 1 and len(edges) == 4


def test_cells_without_a_pose_count_as_outside():
    # 3 x 3 lattice with its centre cell missing (a pillar): nobody has 7 of 8.
    grid, edges = lattice(3, 3)
    keep = np.arange(9) != 4
    remap = np.cumsum(keep) - 1
    grid = grid[keep]
    edges = remap[edges[keep[edges].all(axis=1)]]
    vis = sp.csr_matrix(np.ones((8, 1), bool))
    result = retain_good_features(vis, grid, edges, FilterConfig(min_poses=0, min_block=0))
    assert result.visibility.shape[1] == 0


def test_off_lattice_poses_use_the_pose_graph():
    # A star: centre 0 with three graph neighbours, all off the lattice.
    grid = np.full((5, 2), -1)
    edges = np.array([(0, 1), (0, 2), (0, 3), (3, 4)])
    vis = sp.csr_matrix(np.array([[1], [1], [1], [1], [1]], bool))
    result = retain_good_features(vis, grid, edges, FilterConfig(min_poses=0))
    # Pose 0 is a core (3 of 3 neighbours); pose 4 is not next to a core.
    assert result.visibility.toarray().ravel().tolist() == [True, True, True, True, False]
    assert result.kept_classes.tolist() == [0]


def test_everything_disabled_keeps_the_input():
    rng = np.random.default_rng(1)
    vis = rng.random((12, 5)) < 0.5
    vis[:, 0] = False
    result = run([vis[:, i] for i in range(5)], 4, 3, ALL)
    assert result.kept_classes.tolist() == [1, 2, 3, 4]
    assert (result.visibility.toarray() == vis[:, 1:]).all()


def test_bad_inputs_are_clear_errors():
    grid, edges = lattice(2, 2)
    vis = sp.csr_matrix(np.ones((4, 1), bool))
    with pytest.raises(VisibilityBuilderError, match='grid'):
        retain_good_features(vis, grid[:3], edges)
    with pytest.raises(VisibilityBuilderError, match='more than one pose'):
        retain_good_features(vis, np.zeros((4, 2), int), edges)
    with pytest.raises(VisibilityBuilderError, match='outside'):
        retain_good_features(vis, grid, np.array([[0, 9]]))
    with pytest.raises(VisibilityBuilderError, match='min_neighbours'):
        FilterConfig(min_neighbours=9)
    with pytest.raises(VisibilityBuilderError, match='min_poses'):
        FilterConfig(min_poses=-1)

"""Algorithm 6.3 (visibility_builder.classes): one hand-built case per rule of Figure 6.3.

Tests of a rule as Figure 6.3 prints it use ``exclusion='class'``; the default,
feature exclusion, has tests of its own.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from visibility_builder import classes as classes_module
from visibility_builder import pair_matching
from visibility_builder.classes import (
    ClassConfig,
    correspondence_classes,
    pose_pairs_within,
)
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.pair_matching import match_pose_pair

DIM = 8


def feats(*values: float, axis: int = 0) -> np.ndarray:
    """Features on one line of descriptor space: value * e_axis, plus an offset."""
    out = np.zeros((len(values), DIM), np.float32)
    out[:, axis] = values
    out[:, DIM - 1] = 1000.0   # far from the origin, like real SIFT vectors
    return out


def path(n: int) -> np.ndarray:
    return np.array([(i, i + 1) for i in range(n - 1)])


def test_mutual_matches_merge_into_classes():
    a = np.vstack([feats(0.0), feats(0.0, axis=1) + 500])
    b = a + 1.0
    result = correspondence_classes([a, b], path(2), ClassConfig(tau=10, gamma=1))
    assert result.n_classes == 2
    assert result.labels[0].tolist() == result.labels[1].tolist()
    assert sorted(result.labels[0].tolist()) == [0, 1]
    assert result.visibility.toarray().tolist() == [[True, True], [True, True]]
    assert result.stats['mutual'] == 2
    assert result.stats['excluded_symmetry'] == 0


def test_non_symmetric_match_within_tau_excludes_both_classes():
    # f0 -> g (8 <= tau) but g's nearest neighbour in pose 0 is f1 (2): broken symmetry.
    pose0 = np.vstack([feats(0.0, 10.0), feats(0.0, axis=2) + 300])
    pose1 = np.vstack([feats(8.0), feats(1.0, axis=2) + 300])
    result = correspondence_classes([pose0, pose1], path(2),
                                    ClassConfig(tau=9, gamma=1, exclusion='class'))
    assert result.labels[0].tolist()[:2] == [-1, -1]   # f0 and f1 (f1 ~ g, excluded)
    assert result.labels[1].tolist()[0] == -1           # g
    assert result.n_classes == 1                        # the unrelated pair survives
    assert result.labels[0][2] == result.labels[1][1] == 0
    assert result.stats['excluded_symmetry'] >= 2


def test_feature_exclusion_drops_only_the_ambiguous_features():
    # The same case with the default: f0 and g are excluded, f1 (whose class g
    # would have joined) stays as a class of one pose, the unrelated pair merges.
    pose0 = np.vstack([feats(0.0, 10.0), feats(0.0, axis=2) + 300])
    pose1 = np.vstack([feats(8.0), feats(1.0, axis=2) + 300])
    result = correspondence_classes([pose0, pose1], path(2),
                                    ClassConfig(tau=9, gamma=1, exclusion='feature'))
    assert result.labels[0][0] == -1 and result.labels[1][0] == -1
    assert result.labels[0][1] >= 0
    assert result.labels[0][2] == result.labels[1][1] >= 0
    assert result.n_classes == 2
    assert result.stats['excluded_symmetry'] == 2        # f0 and g, each alone


def test_feature_exclusion_keeps_a_long_class_with_one_ambiguous_view():
    # One scene feature tracked along 6 poses; pose 3 also sees a near-copy of it
    # (3.9 from its own member, tau 4): a repeated pattern that breaks symmetry there.
    poses = [np.vstack([feats(1.0 * i), feats(0.0, axis=3) + 500]) for i in range(6)]
    poses[3] = np.vstack([feats(3.0), feats(3.0) + 3.9 * np.eye(1, DIM, 1, dtype=np.float32),
                          feats(0.0, axis=3) + 500])
    config = ClassConfig(tau=4, gamma=2, symmetry_factor=1.0)
    whole = correspondence_classes(poses, path(6), replace(config, exclusion='class'))
    kept = correspondence_classes(poses, path(6), replace(config, exclusion='feature'))
    # Figure 6.3 loses the tracked feature at every pose; feature exclusion drops
    # the two look-alikes of pose 3 and keeps the track as one class of 5 poses
    # (poses 2 and 4 are within gamma).
    assert all(lab[0] == -1 for lab in whole.labels)
    assert kept.labels[3][:2].tolist() == [-1, -1]
    tracked = {int(lab[0]) for v, lab in enumerate(kept.labels) if v != 3}
    assert len(tracked) == 1 and min(tracked) >= 0
    assert int(kept.visibility[:, min(tracked)].sum()) == 5


def test_non_symmetric_neighbour_beyond_tau_is_ignored():
    pose0 = feats(0.0, 10.0)
    pose1 = feats(8.0)
    literal = ClassConfig(tau=7, gamma=1, symmetry_factor=1.0,
                          exclusion='class')                  # Figure 6.3 as printed
    result = correspondence_classes([pose0, pose1], path(2), literal)
    # f0 -> g is 8 > tau: no relation; f1 <-> g merge.
    assert result.n_classes == 2
    assert result.labels[0][1] == result.labels[1][0]
    assert result.labels[0][0] != result.labels[0][1]
    assert result.stats['excluded_symmetry'] == 0


def test_symmetry_factor_widens_the_exclusion_radius_only():
    pose0 = feats(0.0, 10.0)
    pose1 = feats(8.0)
    # f0 -> g is 8: beyond tau (7) but within 1.5 tau: symmetry broken, all excluded.
    wide = correspondence_classes([pose0, pose1], path(2),
                                  ClassConfig(tau=7, gamma=1, symmetry_factor=1.5,
                                              exclusion='class'))
    assert wide.n_classes == 0 and wide.stats['excluded_symmetry'] == 2
    # A mutual pair between tau and the wider radius neither merges nor excludes.
    apart = correspondence_classes([feats(0.0), feats(9.0)], path(2),
                                   ClassConfig(tau=7, gamma=1, symmetry_factor=1.5))
    assert apart.n_classes == 2 and apart.stats['excluded_symmetry'] == 0


def test_two_features_of_one_pose_in_one_class_are_excluded():
    # Square A-B-C-D-A, gamma 1: p ~ r ~ s ~ t ~ q chains p and q, both seen from A.
    a = feats(0.0, 16.0)
    b, c, d = feats(4.0), feats(8.0), feats(12.0)
    square = np.array([(0, 1), (1, 2), (2, 3), (3, 0)])
    result = correspondence_classes([a, b, c, d], square, ClassConfig(tau=5, gamma=1))
    assert result.n_classes == 0
    assert all((lab == -1).all() for lab in result.labels)
    assert result.stats['excluded_uniqueness'] == 1
    assert result.stats['excluded_symmetry'] == 0
    assert result.stats['mutual'] == 4


def test_gamma_limits_which_pose_pairs_are_compared():
    poses = [feats(0.0), feats(0.0, axis=3) + 400, feats(1.0)]
    near = correspondence_classes(poses, path(3), ClassConfig(tau=5, gamma=1))
    far = correspondence_classes(poses, path(3), ClassConfig(tau=5, gamma=2))
    assert near.stats['pose_pairs'] == 2 and far.stats['pose_pairs'] == 3
    assert near.n_classes == 3          # poses 0 and 2 never compared
    assert far.n_classes == 2
    assert far.labels[0][0] == far.labels[2][0]
    assert far.visibility[:, far.labels[0][0]].toarray().ravel().tolist() == [True, False, True]


def test_transitivity_over_a_chain_of_adjacent_poses():
    # Appearance drifts along a corridor: only neighbours are within tau.
    poses = [feats(4.0 * i) for i in range(5)]
    result = correspondence_classes(poses, path(5), ClassConfig(tau=5, gamma=1))
    assert result.n_classes == 1
    assert [lab.tolist() for lab in result.labels] == [[0]] * 5
    assert result.visibility.sum() == 5


def test_transitivity_check_rejects_a_chain_whose_ends_are_far_apart():
    poses = [feats(4.0 * i) for i in range(5)]
    loose = correspondence_classes(poses, path(5), ClassConfig(tau=5, gamma=2))
    strict = correspondence_classes(poses, path(5),
                                    ClassConfig(tau=5, gamma=2, transitivity=7))
    assert loose.n_classes == 1           # 0~4~8~12~16; poses 2 apart are 8 > tau
    assert strict.n_classes == 0          # ... and 8 > 7
    assert strict.stats['excluded_transitivity'] == 1
    wide = ClassConfig(tau=5, gamma=2, transitivity=8.5)
    assert correspondence_classes(poses, path(5), wide).n_classes == 1


def test_repeated_pattern_within_one_pose_is_excluded():
    # Pose 0 sees two near-identical features (a tiled wall); pose 1 one of them.
    pose0 = feats(0.0, 3.0)
    pose1 = feats(0.5)
    fig = ClassConfig(tau=5, gamma=1, exclusion='class')
    same = correspondence_classes([pose0, pose1], path(2), fig)
    off = correspondence_classes([pose0, pose1], path(2), replace(fig, same_pose=False))
    assert same.n_classes == 0
    # feature exclusion drops the repeats, and g, which is nearest to one of them
    # without being its mutual neighbour
    single = correspondence_classes([pose0, pose1], path(2), replace(fig, exclusion='feature'))
    assert [lab.tolist() for lab in single.labels] == [[-1, -1], [-1]]
    # without the v = w pair, f1 -> g (2.5) is non-symmetric anyway; a repeat that
    # the other pose does not reach is only caught by the same-pose comparison:
    far = [feats(0.0, 3.0), feats(0.0, axis=4) + 300]
    assert correspondence_classes(far, path(2), fig).n_classes == 1
    assert correspondence_classes(far, path(2), replace(fig, same_pose=False)).n_classes == 3
    assert off.n_classes == 0


def test_ratio_test_rejects_ambiguous_nearest_neighbours():
    # Pose 1 holds a near-copy of f just beyond tau (5.5): Figure 6.3 alone merges f
    # with its nearest neighbour (3), the ratio test (3 >= 0.5 * 5.5) rejects it.
    pose0 = feats(0.0)
    pose1 = np.vstack([feats(3.0), feats(0.0) + np.eye(1, DIM, 1, dtype=np.float32) * 5.5])
    plain = correspondence_classes([pose0, pose1], path(2),
                                   ClassConfig(tau=5, gamma=1, symmetry_factor=1.0))
    ratio = correspondence_classes([pose0, pose1], path(2),
                                   ClassConfig(tau=5, gamma=1, ratio=0.5, symmetry_factor=1.0))
    assert plain.labels[0][0] == plain.labels[1][0] >= 0
    assert ratio.labels[0][0] == -1 and ratio.labels[1][0] == -1


def test_match_pose_pair_reports_both_directions():
    a = feats(0.0, 10.0)
    b = feats(8.0)
    rel = match_pose_pair(a, b, tau=9)
    assert rel.mutual.tolist() == [[1, 0]]
    # f0 -> g is not mutual: f0 and g are broken (f1 is excluded later, with g's class).
    assert rel.broken_a.tolist() == [0] and rel.broken_b.tolist() == [0]
    assert rel.tested == 3 and rel.within_tau == 3


def test_pose_pairs_within_gamma_on_a_grid():
    # 3 x 3 grid, 4-connected: from the centre everything is within 2.
    idx = np.arange(9).reshape(3, 3)
    edges = np.vstack([np.c_[idx[:, :-1].ravel(), idx[:, 1:].ravel()],
                       np.c_[idx[:-1].ravel(), idx[1:].ravel()]])
    assert len(pose_pairs_within(edges, 9, 1)) == 12
    two = pose_pairs_within(edges, 9, 2)
    assert (two[:, 0] < two[:, 1]).all()
    # pairs at distance 2: 6 straight (same row or column) + 8 diagonal neighbours
    assert len(two) == 12 + 6 + 8
    assert len(pose_pairs_within(edges, 9, 4)) == 36


def test_invariants_on_random_worlds_and_workers_agree(monkeypatch):
    monkeypatch.setattr(classes_module, '_MIN_POOL_ENTRIES', 0)   # use the pool here
    rng = np.random.default_rng(3)
    scene = rng.normal(0, 60, (80, 32)).astype(np.float32) + 200
    poses = []
    for _ in range(12):
        seen = rng.choice(80, 30, replace=False)
        poses.append(scene[seen] + rng.normal(0, 8, (30, 32)).astype(np.float32))
    edges = np.array([(i, (i + 1) % 12) for i in range(12)])
    for exclusion in ('class', 'feature'):
        config = ClassConfig(tau=60, gamma=2, exclusion=exclusion)
        one = correspondence_classes(poses, edges, config)
        two = correspondence_classes(poses, edges, replace(config, workers=2))
        assert [a.tolist() for a in one.labels] == [b.tolist() for b in two.labels]
        check_invariants(one)


def test_uint8_descriptors_give_the_float32_classes_in_one_or_two_processes(monkeypatch):
    monkeypatch.setattr(classes_module, '_MIN_POOL_ENTRIES', 0)
    rng = np.random.default_rng(5)
    scene = rng.integers(0, 256, (120, 128))
    poses = [np.clip(scene[rng.choice(120, 50, replace=False)]
                     + rng.integers(-10, 11, (50, 128)), 0, 255).astype(np.uint8)
             for _ in range(16)]
    edges = np.array([(i, i + 1) for i in range(15)] + [(i, i + 4) for i in range(12)])
    config = ClassConfig(tau=200, gamma=2)
    reference = correspondence_classes([p.astype(np.float32) for p in poses], edges, config)
    for workers in (1, 2):
        result = correspondence_classes(poses, edges, replace(config, workers=workers))
        assert [a.tolist() for a in result.labels] == [b.tolist() for b in reference.labels]
        assert {k: v for k, v in result.stats.items() if k != 'seconds'} == \
            {k: v for k, v in reference.stats.items() if k != 'seconds'}
    assert reference.stats['multi_pose_classes'] > 10


def test_column_argmin_takes_the_first_row_on_ties():
    rng = np.random.default_rng(7)
    d2 = rng.integers(0, 4, (40, 30)).astype(np.float32)   # many ties
    assert pair_matching._argmin_columns(d2).tolist() == d2.argmin(axis=0).tolist()
    assert pair_matching._argmin_columns(d2[:, 5:17]).tolist() == \
        d2[:, 5:17].argmin(axis=0).tolist()


def check_invariants(one) -> None:
    assert one.n_classes > 10
    ids = np.concatenate(one.labels)
    assert set(ids[ids >= 0].tolist()) == set(range(one.n_classes))
    for v, lab in enumerate(one.labels):
        kept = lab[lab >= 0]
        assert len(np.unique(kept)) == len(kept)          # local uniqueness
        assert sorted(kept.tolist()) == one.visibility[v].indices.tolist()


def test_empty_poses_and_no_edges():
    empty = np.zeros((0, DIM), np.float32)
    result = correspondence_classes([empty, feats(1.0)], np.zeros((0, 2), int),
                                    ClassConfig(tau=5))
    assert result.n_classes == 1 and result.labels[0].shape == (0,)
    assert result.visibility.shape == (2, 1)


@pytest.mark.parametrize('kwargs, message', [
    ({'tau': 0}, 'tau'), ({'gamma': 0}, 'gamma'), ({'ratio': 1.5}, 'ratio'),
    ({'workers': 0}, 'workers'), ({'transitivity': -1.0}, 'transitivity'),
    ({'symmetry_factor': 0.5}, 'symmetry_factor'),
    ({'exclusion': 'pose'}, "exclusion must be one of feature, class, got 'pose'"),
])
def test_bad_config_is_one_clear_error(kwargs, message):
    with pytest.raises(VisibilityBuilderError, match=message):
        ClassConfig(**kwargs)


def test_bad_inputs_are_clear_errors():
    with pytest.raises(VisibilityBuilderError, match='dimension'):
        correspondence_classes([feats(1.0), np.zeros((2, 4), np.float32)], path(2))
    with pytest.raises(VisibilityBuilderError, match='outside'):
        correspondence_classes([feats(1.0), feats(2.0)], np.array([[0, 5]]))
    with pytest.raises(VisibilityBuilderError, match='NaN'):
        correspondence_classes([np.full((1, DIM), np.nan, np.float32)], np.zeros((0, 2), int))


def test_single_threaded_blas_restores_the_thread_count():
    from vbn_common.blas import _openblas_thread_controls, single_threaded_blas

    controls = _openblas_thread_controls()
    before = [get() for get, _ in controls]
    with single_threaded_blas():
        assert all(get() == 1 for get, _ in controls)
    assert [get() for get, _ in controls] == before

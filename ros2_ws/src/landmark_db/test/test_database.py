"""The landmark database: model invariants, round trip, derived indexes, export."""
from __future__ import annotations

from database_samples import sample_camera, sample_database
import numpy as np
import pytest
import scipy.sparse as sp

from landmark_db.database import (
    BuildInfo,
    FeatureClasses,
    LandmarkDatabase,
    ModelView,
    RegionRecord,
    SampledPoses,
    open_database,
    write_database,
)
from landmark_db.decomposition import validate
from landmark_db.errors import LandmarkDbError
from vbn_common.errors import VbnCommonError


def view(pose, class_ids, seed=0):
    rng = np.random.default_rng(seed)
    m = len(class_ids)
    return ModelView(pose, 10**18 + pose, pose, float(pose), 0.0, 0.1, np.array(class_ids),
                     rng.random((m, 2)).astype(np.float32) * 100,
                     rng.integers(0, 256, (m, 128), dtype=np.uint8))


def info(k=1, **changes):
    values = dict(k=k, rho=0, sigma=0, algorithm='B2', pose_source='tf',
                  source_bag='bags/line', created_utc='2026-12-01T12:00:00Z',
                  camera=sample_camera(), frames={'map': 'map'}, sift={}, parameters={})
    values.update(changes)
    return BuildInfo(**values)


def line_database():
    """Poses 0-1-2 on a line; class 0 seen from 0 and 1, class 1 from 1 and 2, class 2 from 2.

    Regions: R0 = {0, 1} (landmark 0), R1 = {1, 2} (landmark 1, extra 2), R2 = {2}
    (landmark 2, extra 1).
    """
    poses = SampledPoses([[0, 0], [1, 0], [2, 0]], [0, 0, 0], [[0, 0], [1, 0], [2, 0]],
                         [[0, 1], [1, 2]], 1.0)
    visibility = sp.csr_matrix(np.array([[1, 0, 0], [1, 1, 0], [0, 1, 1]], bool))
    classes = FeatureClasses(np.zeros((4, 128), np.uint8), [0, 1, 3, 4], visibility)
    regions = (
        RegionRecord([0, 1], [0], [], (view(0, [0]), view(1, [0, 1]))),
        RegionRecord([2, 1], [1], [2], (view(1, [1, 0]), view(2, [1, 2, -1]))),
        RegionRecord([2], [2], [1], (view(2, [2, 1]),)),
    )
    return LandmarkDatabase(info(), poses, classes, regions, [])


def test_region_graph_and_membership_by_hand():
    db = line_database()
    graph = db.adjacency
    assert graph.pairs.tolist() == [[0, 1], [0, 2], [1, 2]]
    # R0 and R1 share pose 1; R1 and R2 share pose 2; R0 and R2 share none.
    assert graph.shared_poses.tolist() == [1, 0, 1]
    # Ordered pose pairs (u in a, v in b) that are edges: R0->R1 (0,1), (1,2);
    # R0->R2 (1,2); R1->R2 (1,2).
    assert graph.joining_edges.tolist() == [2, 1, 1]
    assert graph.neighbours(0).tolist() == [1, 2]
    # Class 0 votes for R0; class 1 for R1 (landmark) and R2 (extra); class 2 for R1, R2.
    assert db.membership.toarray().tolist() == [[True, False, False], [False, True, True],
                                                [False, True, True]]
    assert db.regions[1].poses.tolist() == [1, 2]  # sorted on input


def test_disjoint_regions_joined_only_by_an_edge():
    db = line_database()
    two = LandmarkDatabase(db.info, db.poses, db.classes, (db.regions[0], db.regions[2]), [])
    assert two.adjacency.pairs.tolist() == [[0, 1]]
    assert two.adjacency.shared_poses.tolist() == [0]
    assert two.adjacency.joining_edges.tolist() == [1]


@pytest.mark.parametrize('seed, rho', [(0, 0), (1, 0), (5, 1)])
def test_round_trip_is_equal(tmp_path, seed, rho):
    db = sample_database(np.random.default_rng(seed), nx=3 + rho, ny=3, rho=rho)
    assert db.n_regions >= 1
    path = tmp_path / 'room.db'
    write_database(path, db)
    back = open_database(path)
    assert back == db
    assert back.classes.descriptors.dtype == np.uint8
    assert back.regions[0].model_views[0].keypoints.dtype == np.float32
    assert back.info.camera.K[0, 2] == 320.5
    assert back.adjacency == db.adjacency
    assert (back.membership != db.membership).nnz == 0
    # A changed database is not equal: equality really compares contents.
    other = sample_database(np.random.default_rng(seed + 100), nx=3 + rho, ny=3, rho=rho)
    assert other != db


def test_rewrite_replaces_previous(tmp_path):
    path = tmp_path / 'room.db'
    first = sample_database(np.random.default_rng(0))
    second = sample_database(np.random.default_rng(1))
    write_database(path, first)
    write_database(path, second)
    assert open_database(path) == second
    assert sorted(p.name for p in tmp_path.iterdir()) == ['room.db']


@pytest.mark.parametrize('seed, rho', [(0, 0), (2, 0), (3, 1)])
def test_exports_validate(seed, rho):
    db = sample_database(np.random.default_rng(seed), nx=4, ny=3, rho=rho)
    world = db.to_world_instance()
    decomposition = db.to_decomposition()
    assert world.feature_ids.tolist() == list(range(db.n_classes))
    assert world.n_poses == db.n_poses and world.spacing == 0.5
    assert decomposition.k == db.info.k and decomposition.rho == rho
    for region, record in zip(decomposition.regions, db.regions):
        assert region.features.tolist() == sorted(record.landmark.tolist())
    assert validate(world, decomposition) == []


def test_export_reports_a_broken_region():
    db = line_database()
    # Region {0, 2} is not connected and pose 0 does not see class 1.
    bad = RegionRecord([0, 2], [1], [], (view(2, [1]),))
    broken = LandmarkDatabase(db.info, db.poses, db.classes, (bad,), [])
    problems = validate(broken.to_world_instance(), broken.to_decomposition())
    assert any('not connected' in p for p in problems)


def test_arrays_are_read_only_and_copied():
    xy = np.array([[0.0, 0.0], [1.0, 0.0]])
    poses = SampledPoses(xy, [0, 0], [[-1, -1], [-1, -1]], [[0, 1]])
    xy[0, 0] = 9.0
    assert poses.xy[0, 0] == 0.0
    with pytest.raises(ValueError):
        poses.xy[0, 0] = 1.0


def test_float_sift_descriptors_become_uint8():
    classes = FeatureClasses(np.full((1, 128), 255.0, np.float32), [0, 1],
                             sp.csr_matrix((1, 1), dtype=bool))
    assert classes.descriptors.dtype == np.uint8 and classes.descriptors[0, 0] == 255


def test_info_json_is_normalised():
    built = info(sift={'sigma': np.float32(1.5), 'octaves': (1, 2)})
    assert built.sift == {'octaves': [1, 2], 'sigma': 1.5}


@pytest.mark.parametrize('make, message', [
    (lambda: info(pose_source='gps'), 'pose_source'),
    (lambda: info(created_utc='yesterday'), 'ISO 8601'),
    (lambda: info(created_utc='2026-12-01T12:00:00+02:00'), 'UTC'),
    (lambda: info(k=0), 'k must be'),
    (lambda: info(parameters={'f': object()}), 'JSON'),
    (lambda: info(frames={'map': 3}), 'frame id'),
    (lambda: SampledPoses([[0, 0]], [0], [[0, -1]], []), 'grid index'),
    (lambda: SampledPoses([[0, np.nan]], [0], [[0, 0]], []), 'non-finite'),
    (lambda: SampledPoses([[0, 0]], [0], [[0, 0]], [[0, 1]]), 'out of range'),
    (lambda: FeatureClasses(np.zeros((2, 128)), [0, 2, 2], sp.csr_matrix((1, 2))),
     'no descriptor'),
    (lambda: FeatureClasses(np.full((1, 128), 300), [0, 1], sp.csr_matrix((1, 1))),
     '0..255'),
    (lambda: FeatureClasses(np.zeros((1, 64)), [0, 1], sp.csr_matrix((1, 1))), '(n, 128)'),
    (lambda: ModelView(0, 0, 0, 0, 0, 0, [1, 1], np.zeros((2, 2)), np.zeros((2, 128))),
     'twice'),
    (lambda: ModelView(0, 0, 0, 0, 0, 0, [1], np.zeros((2, 2)), np.zeros((1, 128))),
     'shape'),
    (lambda: RegionRecord([0, 1], [0], [], (view(0, [1]),)), 'lacks landmark class 0'),
    (lambda: RegionRecord([0, 0], [0], [], (view(0, [0]),)), 'pose twice'),
    (lambda: RegionRecord([0], [0], [0], (view(0, [0]),)), 'both'),
    (lambda: RegionRecord([0], [0], [], ()), 'no model view'),
])
def test_invalid_parts_are_refused(make, message):
    with pytest.raises(LandmarkDbError, match=message):
        make()


def test_database_refuses_out_of_range_indices():
    db = line_database()
    with pytest.raises(LandmarkDbError, match='pose 3 out of range'):
        LandmarkDatabase(db.info, db.poses, db.classes,
                         (RegionRecord([3], [0], [], (view(0, [0]),)),), [])
    with pytest.raises(LandmarkDbError, match='class 7 out of range'):
        LandmarkDatabase(db.info, db.poses, db.classes,
                         (RegionRecord([0], [0], [7], (view(0, [0]),)),), [])
    with pytest.raises(LandmarkDbError, match='model view 0 has pose 5'):
        LandmarkDatabase(db.info, db.poses, db.classes,
                         (RegionRecord([0], [0], [], (view(5, [0]),)),), [])
    with pytest.raises(LandmarkDbError, match='uncovered'):
        LandmarkDatabase(db.info, db.poses, db.classes, db.regions, [4])


def test_write_refuses_a_missing_folder_and_non_database(tmp_path):
    with pytest.raises(VbnCommonError, match='does not exist'):
        write_database(tmp_path / 'nope' / 'x.db', line_database())
    with pytest.raises(LandmarkDbError, match='LandmarkDatabase'):
        write_database(tmp_path / 'x.db', {'regions': []})

"""The landmark database file: refusal of bad files, read-only opening, crash safety."""
from __future__ import annotations

import os
from pathlib import Path
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time

from database_samples import edited_copy, sample_database
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
import numpy as np
from paths import SUPPORT
import pytest

from landmark_db.database import (
    APPLICATION_ID,
    SCHEMA_VERSION,
    database_summary,
    open_database,
    store,
    write_database,
)
from landmark_db.database.compact import compact_database
from landmark_db.errors import LandmarkDbError

TESTS = SUPPORT


@pytest.fixture
def db_file(tmp_path):
    path = tmp_path / 'room.db'
    write_database(path, sample_database(np.random.default_rng(0)))
    return path


@pytest.fixture
def coded_file(tmp_path):
    """The sample with 16-byte descriptor codes and JPEG patches."""
    path = tmp_path / 'coded.db'
    db, _ = compact_database(sample_database(np.random.default_rng(0)), 16, 80,
                             np.random.default_rng(0))
    write_database(path, db)
    return path


def refused(path) -> str:
    with pytest.raises(LandmarkDbError) as error:
        open_database(path)
    message = str(error.value)
    assert '\n' not in message and str(path) in message
    with pytest.raises(LandmarkDbError) as summary_error:
        database_summary(path)
    assert str(summary_error.value) == message
    return message


def test_header_identifies_the_file(db_file):
    connection = sqlite3.connect(f'file:{db_file}?mode=ro', uri=True)
    assert connection.execute('PRAGMA application_id').fetchone()[0] == APPLICATION_ID
    assert connection.execute('PRAGMA user_version').fetchone()[0] == SCHEMA_VERSION
    meta = dict(connection.execute('SELECT key, value FROM meta'))
    assert meta['schema_version'] == str(SCHEMA_VERSION)
    # Schema 5 keeps a region's members in its row: 9 poses and 12 classes fit uint16.
    poses, landmark = connection.execute('SELECT poses, landmark FROM regions WHERE id = 0'
                                         ).fetchone()
    region = sample_database(np.random.default_rng(0)).regions[0]
    assert np.frombuffer(poses, '<u2').tolist() == region.poses.tolist()
    assert np.frombuffer(landmark, '<u2').tolist() == region.landmark.tolist()
    connection.close()


def test_missing_file(tmp_path):
    assert refused(tmp_path / 'none.db').endswith('none.db: no such file')


def test_folder(tmp_path):
    assert 'is a folder' in refused(tmp_path)


def test_empty_file(tmp_path):
    (tmp_path / 'empty.db').write_bytes(b'')
    assert 'empty file' in refused(tmp_path / 'empty.db')


def test_random_bytes(tmp_path):
    path = tmp_path / 'noise.db'
    path.write_bytes(np.random.default_rng(0).bytes(50_000))
    assert refused(path).endswith('not a SQLite database')


@pytest.mark.parametrize('fraction', [0.02, 0.5, 0.9])
def test_truncated_copy(db_file, tmp_path, fraction):
    data = db_file.read_bytes()
    path = tmp_path / 'cut.db'
    path.write_bytes(data[:int(len(data) * fraction)])
    assert 'truncated' in refused(path)


def test_newer_schema(db_file, tmp_path):
    newer = SCHEMA_VERSION + 1
    path = edited_copy(db_file, tmp_path / 'newer.db', f'PRAGMA user_version = {newer}',
                       f"UPDATE meta SET value = '{newer}' WHERE key = 'schema_version'")
    assert refused(path) == (f'database {path} has schema version {newer}, this build reads '
                             f'up to {SCHEMA_VERSION}: upgrade vbn')


def test_sqlite_file_of_another_application(tmp_path):
    path = tmp_path / 'other.db'
    connection = sqlite3.connect(path)
    connection.execute('CREATE TABLE regions (id INTEGER PRIMARY KEY)')
    connection.commit()
    connection.close()
    assert 'not a landmark database (a SQLite file of another application' in refused(path)


def test_missing_table(db_file, tmp_path):
    path = edited_copy(db_file, tmp_path / 'lost.db', 'DROP TABLE region_adjacency')
    assert "table 'region_adjacency' is missing" in refused(path)


@pytest.mark.parametrize('statement, message', [
    ('DELETE FROM region_adjacency', 'region graph does not match'),
    ("UPDATE classes SET descriptors = x'00' WHERE id = 0", 'descriptor counts'),
    ("UPDATE build_parameters SET value = '0' WHERE key = 'k'", 'k must be'),
    ("UPDATE regions SET poses = x'6300', n_poses = 1 WHERE id = 0", 'out of range'),
    ("UPDATE regions SET landmark = x'00' WHERE id = 0", 'members differ'),
    ("UPDATE model_view_features SET keypoints = x'00'", 'do not hold'),
    ("UPDATE visibility SET class_ids = x'000000' WHERE pose = 0", 'uint16 ids'),
    ("UPDATE visibility SET class_ids = x'ff00' WHERE pose = 0", 'class out of range'),
    ('DELETE FROM visibility WHERE pose = 4', 'poses 0..8'),
    # Values SQLite cannot judge: one descriptor byte, one coordinate.
    ('UPDATE classes SET descriptors = zeroblob(length(descriptors)) WHERE id = 1',
     'checksum'),
    ('UPDATE poses SET x = x + 1e-9 WHERE id = 3', 'checksum'),
    # Scene points (schema 5: one row a column).
    ("UPDATE scene_point_columns SET data = zeroblob(length(data)) WHERE name = 'xyz'",
     'checksum'),
    ("UPDATE scene_point_columns SET data = x'00' WHERE name = 'descriptors'",
     'not whole 128-byte descriptors'),
    ("UPDATE scene_point_columns SET dtype = '<f4' WHERE name = 'class_ids'",
     "column 'class_ids' is not"),
    ("UPDATE scene_point_columns SET data = zeroblob(12) WHERE name = 'views'",
     'fewer than 2 views'),
    ("UPDATE scene_point_columns SET shape = '[12, 4]' WHERE name = 'xyz'", 'unknown'),
    ("UPDATE scene_point_columns SET name = 'xyz2' WHERE name = 'xyz'", 'unknown'),
    ("DELETE FROM scene_point_columns WHERE name = 'descriptors'", 'lack'),
    # Their patches.
    ("DELETE FROM scene_point_columns WHERE name = 'patch_axes'", 'axes disagree'),
    ("UPDATE scene_point_columns SET data = x'00' WHERE name = 'patches'",
     "column 'patches' is not"),
    ("UPDATE scene_point_columns SET data = zeroblob(length(data)) WHERE name = 'patches'",
     'checksum'),
])
def test_inconsistent_contents(db_file, tmp_path, statement, message):
    refused_after(db_file, tmp_path, statement, message)


def refused_after(source: Path, tmp_path: Path, statement: str, message: str) -> None:
    """A copy of ``source`` damaged by ``statement`` is refused with ``message``."""
    text = refused_open_only(edited_copy(source, tmp_path / 'edited.db', statement))
    assert 'damaged database' in text and message in text


@pytest.mark.parametrize('statement, message', [
    ('UPDATE descriptor_codebook SET centroids = zeroblob(length(centroids))', 'checksum'),
    ('UPDATE descriptor_codebook SET code_size = 7', 'not one row'),
    ('DELETE FROM descriptor_codebook', 'descriptor counts'),
    ("UPDATE model_view_features SET descriptors = x'00'", 'do not hold'),
    ("UPDATE scene_point_columns SET data = substr(data, 1, 40) WHERE name = 'patches'",
     'patch code'),
    ("UPDATE scene_point_columns SET data = zeroblob(length(data)) WHERE name = 'patches'",
     'the patch code holds 0 patches, not 11'),
    ("UPDATE scene_point_columns SET dtype = '<f2', data = zeroblob(22) "
     "WHERE name = 'patch_points'", 'axes disagree'),
    ("UPDATE scene_point_columns SET shape = '[11, 100000000, 100000000]' "
     "WHERE name = 'patches'", 'are not patches of a database'),
])
def test_inconsistent_compact_contents(coded_file, tmp_path, statement, message):
    refused_after(coded_file, tmp_path, statement, message)


SCHEMA_4 = TESTS / 'data' / 'schema4_sample.db'
"""``sample_database(np.random.default_rng(0))`` written by schema 4's writer (3f0bdbe)."""


@pytest.mark.parametrize('statement, message', [
    ('DELETE FROM class_descriptors WHERE class_id = 0', 'descriptor counts'),
    ('UPDATE region_poses SET pose = 99 WHERE pose = 0', 'out of range'),
    ("UPDATE visibility SET class_ids = x'000000' WHERE pose = 0", 'int32'),
    ('UPDATE class_descriptors SET descriptor = zeroblob(128) WHERE class_id = 1',
     'checksum'),
    ('UPDATE scene_points SET x = x + 1e-9 WHERE id = 2', 'checksum'),
    ("UPDATE scene_points SET descriptor = x'00' WHERE id = 0", 'descriptor is not 128'),
    ('UPDATE scene_points SET class_id = 99 WHERE id = 0', 'out of range'),
    ('UPDATE scene_points SET views = 1 WHERE id = 0', 'fewer than 2 views'),
    ("UPDATE scene_points SET patch = x'00' WHERE id = 0", 'not all one odd square size'),
    ('UPDATE scene_points SET patch_axes = NULL WHERE id = 0', 'a patch needs its axes'),
    ('UPDATE scene_points SET patch = patch_axes, patch_axes = patch WHERE id = 1',
     'not all one odd square size'),
])
def test_inconsistent_schema_4_contents(tmp_path, statement, message):
    refused_after(SCHEMA_4, tmp_path, statement, message)


def schema_4_sample():
    """The fixture's database: the sample, with the build info the file holds.

    (The info holds the decomposition's measured time, which differs run to run.)
    """
    from dataclasses import replace

    return replace(sample_database(np.random.default_rng(0)),
                   info=open_database(SCHEMA_4).info)


def older_file(path: Path, plain, version: int, *statements: str) -> Path:
    """The schema 4 fixture cut down by ``statements`` to an older version holding ``plain``."""
    return edited_copy(SCHEMA_4, path, *statements, f'PRAGMA user_version = {version}',
                       f"UPDATE meta SET value = '{version}' WHERE key = 'schema_version'",
                       f"UPDATE meta SET value = '{plain.content_digest()}' "
                       f"WHERE key = 'content_digest'")


def test_a_schema_4_file_opens_as_written():
    opened = open_database(SCHEMA_4)
    assert opened == schema_4_sample() and opened.codebook is None
    assert database_summary(SCHEMA_4).counts['descriptor_bytes'] == 128


def refused_open_only(path) -> str:
    with pytest.raises(LandmarkDbError) as error:
        open_database(path)
    assert '\n' not in str(error.value)
    return str(error.value)


def test_corrupted_page(db_file, tmp_path):
    data = bytearray(db_file.read_bytes())
    page = 4096
    data[3 * page + 8:4 * page] = np.random.default_rng(1).bytes(page - 8)  # a b-tree page
    path = tmp_path / 'bad.db'
    path.write_bytes(bytes(data))
    message = refused_open_only(path)
    assert 'damaged' in message


def test_opening_does_not_modify_the_file(db_file):
    before = db_file.read_bytes()
    os.utime(db_file, ns=(1_000_000_000, 1_000_000_000))
    open_database(db_file)
    database_summary(db_file)
    assert db_file.read_bytes() == before
    assert db_file.stat().st_mtime_ns == 1_000_000_000
    assert sorted(p.name for p in db_file.parent.iterdir()) == ['room.db']


def test_read_only_file_opens(db_file):
    db_file.chmod(0o444)
    try:
        assert open_database(db_file).n_regions >= 1
    finally:
        db_file.chmod(0o644)


def test_summary_counts(db_file):
    db = open_database(db_file)
    summary = database_summary(db_file)
    assert summary.counts['regions'] == db.n_regions
    assert summary.counts['poses'] == db.n_poses == 9
    assert summary.counts['classes'] == db.n_classes
    assert summary.counts['class_descriptors'] == db.classes.descriptors.shape[0]
    assert summary.counts['visibility'] == db.classes.visibility.nnz
    assert summary.counts['model_views'] == sum(len(r.model_views) for r in db.regions)
    assert summary.counts['landmark_features'] == db.info.k * db.n_regions
    assert summary.counts['region_adjacency'] == db.adjacency.pairs.shape[0]
    assert summary.build['k'] == db.info.k and summary.build['camera']['width'] == 640
    assert sum(summary.table_bytes.values()) == summary.file_bytes == db_file.stat().st_size


def test_failed_write_keeps_previous(db_file, monkeypatch):
    before = db_file.read_bytes()

    def explode(connection, db):
        raise sqlite3.OperationalError('disk I/O error')

    monkeypatch.setattr(store, 'insert_regions', explode)
    with pytest.raises(LandmarkDbError, match='disk I/O error'):
        write_database(db_file, sample_database(np.random.default_rng(1)))
    assert db_file.read_bytes() == before
    assert sorted(p.name for p in db_file.parent.iterdir()) == ['room.db']


_WRITER = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    import numpy as np
    from database_samples import large_database
    from landmark_db.database import store

    target, marker, mode = sys.argv[1], Path(sys.argv[2]), sys.argv[3]
    db = large_database(np.random.default_rng(7))
    if mode == 'pause':
        # Stop inside the transaction, after the poses and classes are written.
        real = store.insert_regions

        def paused(connection, db):
            real(connection, db)
            marker.write_text('in transaction')
            time.sleep(60)

        store.insert_regions = paused
    else:
        marker.write_text('writing')
    store.write_database(target, db)
    marker.write_text('done')
""")


def start_writer(target: Path, marker: Path, mode: str) -> subprocess.Popen:
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join([str(TESTS), env.get('PYTHONPATH', '')])
    return subprocess.Popen([sys.executable, '-c', _WRITER, str(target), str(marker), mode],
                            env=env)


def wait_for(marker: Path, process: subprocess.Popen, text: str) -> None:
    deadline = time.monotonic() + 60
    while not (marker.exists() and marker.read_text() == text):
        assert process.poll() is None, 'the writer ended early'
        assert time.monotonic() < deadline, 'the writer did not start'
        time.sleep(0.02)


def test_kill_9_inside_the_transaction_keeps_previous(tmp_path):
    folder = tmp_path / 'out'
    folder.mkdir()
    target = folder / 'room.db'
    old = sample_database(np.random.default_rng(3))
    write_database(target, old)
    before = target.read_bytes()
    marker = tmp_path / 'marker'
    process = start_writer(target, marker, 'pause')
    try:
        wait_for(marker, process, 'in transaction')
        process.send_signal(signal.SIGKILL)
        assert process.wait(30) == -signal.SIGKILL
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert target.read_bytes() == before
    assert open_database(target) == old
    assert sorted(p.name for p in folder.iterdir()) == ['room.db']  # no stray temporary


def test_kill_9_at_random_moments_keeps_a_whole_database(tmp_path):
    rng = np.random.default_rng(11)
    folder = tmp_path / 'out'
    folder.mkdir()
    target = folder / 'room.db'
    old = sample_database(np.random.default_rng(3))
    write_database(target, old)
    before = target.read_bytes()
    marker = tmp_path / 'marker'
    outcomes = []
    for _ in range(3):
        marker.unlink(missing_ok=True)
        process = start_writer(target, marker, 'random')
        try:
            wait_for(marker, process, 'writing')
            time.sleep(float(rng.uniform(0.0, 0.5)))
            process.send_signal(signal.SIGKILL)
            process.wait(30)
        finally:
            if process.poll() is None:
                process.kill()
                process.wait()
        db = open_database(target)  # never half-written: the old or the new, whole
        if target.read_bytes() == before:
            outcomes.append('old')
        else:
            assert db.n_regions == len(db.regions) and len(db.regions[0].model_views) > 2
            outcomes.append('new')
            write_database(target, old)
        for stray in folder.glob('.room.db.*.tmp'):  # killed during the final copy
            stray.unlink()
            outcomes.append('stray')
    assert 'old' in outcomes or 'new' in outcomes


_PRISTINE: dict = {}


def pristine():
    if not _PRISTINE:
        from landmark_db.database import database_image
        _PRISTINE['db'] = sample_database(np.random.default_rng(4))
        _PRISTINE['image'] = database_image(_PRISTINE['db'])
    return _PRISTINE['db'], _PRISTINE['image']


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(damage=st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 255)),
                       min_size=1, max_size=8))
def test_random_damage_gives_a_database_or_one_line(tmp_path, damage):
    original, image = pristine()
    data = bytearray(image)
    for offset, value in damage:
        data[offset % len(data)] = value
    path = tmp_path / 'damaged.db'
    path.write_bytes(bytes(data))
    try:
        db = open_database(path)
    except LandmarkDbError as error:
        text = str(error)
        assert '\n' not in text and text.isprintable() and str(path) in text
    else:
        # Only damage to unused bytes passes: the content checksum catches the rest.
        assert db == original


def test_everything_is_written_in_one_transaction(tmp_path, monkeypatch):
    statements = []
    real_connect = sqlite3.connect

    def traced(*args, **kwargs):
        connection = real_connect(*args, **kwargs)
        connection.set_trace_callback(statements.append)
        return connection

    monkeypatch.setattr(store.sqlite3, 'connect', traced)
    write_database(tmp_path / 'room.db', sample_database(np.random.default_rng(0)))
    words = [s.split()[0].upper() for s in statements]
    assert words.count('BEGIN') == 1 and words.count('COMMIT') == 1
    begin, commit = words.index('BEGIN'), words.index('COMMIT')
    # Every table and row is written between BEGIN and COMMIT (serialize() then reads
    # the page count).
    writes = [i for i, w in enumerate(words) if w in ('CREATE', 'INSERT', 'UPDATE', 'DELETE')]
    assert all(begin < i < commit for i in writes)
    assert all(s.startswith('PRAGMA "main".page_count') for s in statements[commit + 1:])
    assert words.count('INSERT') > 10
    assert not any(w in ('SAVEPOINT', 'RELEASE', 'ROLLBACK') for w in words)


def test_scene_points_round_trip_and_are_counted(db_file):
    from database_samples import sample_database

    points = sample_database(np.random.default_rng(0)).points
    assert points.n_points == 12
    opened = open_database(db_file)
    assert opened.points == points
    assert database_summary(db_file).counts['scene_points'] == 12
    named = points.class_ids >= 0
    table = opened.points.class_points(opened.n_classes)
    np.testing.assert_array_equal(table[points.class_ids[named]], points.xyz[named])
    assert np.isnan(table[np.setdiff1d(np.arange(opened.n_classes),
                                       points.class_ids[named])]).all()


def test_a_schema_2_file_opens_with_where_points_were_seen_unknown(tmp_path):
    from dataclasses import replace


    sample = schema_4_sample()
    assert sample.points.has_seen_from
    points = replace(sample.points, seen_from=None, patches=None, patch_axes=None)
    plain = replace(sample, points=points)
    assert not points.has_seen_from and np.isnan(points.seen_from).all()
    old = older_file(tmp_path / 'old.db', plain, 2,
                     *(f'ALTER TABLE scene_points DROP COLUMN {c}'
                       for c in ('seen_x', 'seen_y', 'seen_radius', 'patch', 'patch_axes')))
    opened = open_database(old)
    assert opened == plain and not opened.points.has_seen_from
    # Known for some points and not others: refused.
    half = sample.points.seen_from.copy()
    half[0] = np.nan
    with pytest.raises(LandmarkDbError, match='seen_from must be known'):
        replace(sample.points, seen_from=half)


def test_a_schema_1_file_opens_with_no_scene_points(tmp_path):
    from dataclasses import replace

    from landmark_db.database import ScenePoints

    plain = replace(schema_4_sample(), points=ScenePoints.empty())
    old = older_file(tmp_path / 'old.db', plain, 1, 'DROP TABLE scene_points')
    opened = open_database(old)
    assert opened.points.n_points == 0 and opened == plain
    assert 'scene_points' not in database_summary(old).counts
    # A schema 4 file without the table is damaged, and a schema 5 file without its own.
    lost = edited_copy(SCHEMA_4, tmp_path / 'lost.db', 'DROP TABLE scene_points')
    assert "table 'scene_points' is missing" in refused(lost)
    source = tmp_path / 'new.db'
    write_database(source, plain)
    lost = edited_copy(source, tmp_path / 'lost5.db', 'DROP TABLE scene_point_columns')
    assert "table 'scene_point_columns' is missing" in refused(lost)


def test_a_schema_3_file_opens_with_no_patches_and_patches_are_checked(tmp_path):
    from dataclasses import replace


    sample = schema_4_sample()
    assert sample.points.has_patches
    assert sample.points.patch_mask.tolist() == [True] * 11 + [False]
    plain = replace(sample, points=replace(sample.points, patches=None, patch_axes=None))
    assert not plain.points.has_patches
    old = older_file(tmp_path / 'old.db', plain, 3,
                     *(f'ALTER TABLE scene_points DROP COLUMN {c}'
                       for c in ('patch', 'patch_axes')))
    opened = open_database(old)
    assert opened == plain and not opened.points.has_patches
    # A changed patch byte is caught by the checksum.
    changed = edited_copy(SCHEMA_4, tmp_path / 'changed.db',
                          'UPDATE scene_points SET patch = zeroblob(49) WHERE id = 3')
    assert 'checksum' in refused_open_only(changed)
    # Patches without axes, an even side, a partly known axis: refused on construction.
    with pytest.raises(LandmarkDbError, match='come together'):
        replace(sample.points, patch_axes=None)
    with pytest.raises(LandmarkDbError, match='s odd'):
        replace(sample.points, patches=np.zeros((12, 6, 6), np.uint8))
    axes = sample.points.patch_axes.copy()
    axes[0, 0, 0] = np.nan
    with pytest.raises(LandmarkDbError, match='partly unknown'):
        replace(sample.points, patch_axes=axes)

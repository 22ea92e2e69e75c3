"""``vbn db-update``: a partial re-exploration rebuilds only what it touched, atomically.

The update bag is the first part of ``bags/room_exploration`` (the room as explored:
nothing changed, so the regions away from it must come through untouched and the
poses it covers keep almost every class). Bad inputs (a damaged bag, another robot's
camera, another place's images, a region left without a model view) leave the database
byte for byte as it was; a localizer that holds the database keeps working while the
file is replaced.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path
import shutil
import subprocess

from exploration_samples import exploration_messages, write_bag  # noqa: E402
import numpy as np
from paths import REPO
import pytest

from landmark_db.database import open_database
from vbn_common.bags import BagWriter, open_bag
from visibility_builder.errors import VisibilityBuilderError

ROOT = REPO
ROOM = ROOT / 'bags' / 'room_exploration'


def vbn(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(['vbn', *args], capture_output=True, text=True, timeout=900)


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def first_part(source: Path, out: Path, share: float) -> Path:
    """Copy the first ``share`` of ``source``'s time span (every topic)."""
    with open_bag(source) as bag, BagWriter(out) as writer:
        start = min(t for _, _, t, _ in bag.messages())
        stop = start + share * bag.duration_ns
        connections = {name: writer.add_topic(name, info.msgtype, info.qos_profiles or None)
                       for name, info in bag.topics.items()}
        for topic, _, stamp, raw in bag.messages():
            if stamp <= stop:
                writer.write_raw(connections[topic], stamp, raw)
    return out


@pytest.fixture(scope='module')
def part_bag(tmp_path_factory) -> Path:
    return first_part(ROOM, tmp_path_factory.mktemp('update') / 'room_part', 0.3)


def test_partial_update_rebuilds_only_what_it_touched(room_db: Path, part_bag: Path,
                                                      tmp_path: Path) -> None:
    before = digest(room_db)
    out, counts_file = tmp_path / 'updated.db', tmp_path / 'counts.json'
    proc = vbn('db-update', str(room_db), str(part_bag), '--out', str(out),
               '--json', str(counts_file))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert digest(room_db) == before            # --out: the input is not touched
    counts = json.loads(counts_file.read_text())
    old, new = open_database(room_db), open_database(out)
    assert 0 < counts['poses_updated'] < old.n_poses
    assert counts['images_elsewhere'] == 0 and counts['poses_blocked'] == 0
    # The same world re-imaged: the updated poses keep (almost) every class they had.
    kept, lost = counts['classes_kept_at_updated_poses'], counts['classes_lost_at_updated_poses']
    assert lost <= 0.03 * (kept + lost)
    # Poses the update did not reach see what they saw (old class ids keep their meaning).
    assert new.n_classes >= old.n_classes
    rows_old = old.classes.visibility.tocsr()
    rows_new = new.classes.visibility.tocsr()[:, :old.n_classes]
    changed = np.flatnonzero(np.asarray(abs(rows_old.astype(int) - rows_new.astype(int))
                                        .sum(axis=1)).ravel())
    assert changed.size <= counts['poses_updated']
    untouched = np.setdiff1d(np.arange(old.n_poses), changed)
    # Every region whose landmark is still seen from all its poses comes through as it
    # was; the others are the ones rebuilt.
    records = {(r.poses.tobytes(), r.landmark.tobytes()) for r in new.regions}
    kept_regions = [r for r in old.regions
                    if (r.poses.tobytes(), r.landmark.tobytes()) in records]
    assert len(kept_regions) == counts['regions_kept'] >= 0.6 * old.n_regions
    far = [r for r in old.regions if np.isin(r.poses, untouched).all()]
    assert far and all((r.poses.tobytes(), r.landmark.tobytes()) in records for r in far)
    served, coverable = (int(v) for v in counts['served_after'].split(' of '))
    assert served == coverable and new.service().served == served
    assert new.info.parameters['updates'][-1]['bag'] == str(part_bag)


def test_update_with_bad_input_leaves_the_database_as_it_was(room_db: Path, tmp_path: Path
                                                            ) -> None:
    db = shutil.copy(room_db, tmp_path / 'room.db')
    before = digest(Path(db))
    damaged = tmp_path / 'damaged'
    damaged.mkdir()
    (damaged / 'damaged_0.mcap').write_bytes(b'\x89MCAP0\r\n' + b'\x00' * 200)
    foreign = write_bag(tmp_path / 'foreign', exploration_messages(4))   # 8 x 6 camera
    for bag, expected in ((damaged, 'update bag'), (foreign, "is not the database's"),
                          (tmp_path / 'missing', 'update bag')):
        proc = vbn('db-update', str(db), str(bag))
        assert proc.returncode != 0, proc.stdout
        lines = [line for line in proc.stderr.splitlines() if line.startswith('vbn ')]
        assert len(lines) == 1 and expected in lines[0], proc.stderr
        assert 'Traceback' not in proc.stderr
        assert digest(Path(db)) == before


def test_a_region_left_without_model_view_is_refused(room_db: Path, part_bag: Path,
                                                     monkeypatch) -> None:
    from visibility_builder import db_update, update_regions

    def no_view(*args, **kwargs):
        raise VisibilityBuilderError('no image shows it')

    database = open_database(room_db)
    # Drop one region's landmark class everywhere the update looks: that region is
    # rebuilt, and with no model view (however often it is drawn again) the update must
    # refuse.
    monkeypatch.setattr(update_regions, 'select_model_views', no_view)
    monkeypatch.setattr(db_update, 'label_features',
                        lambda features, *a, **k: np.full(len(features), -1, np.int64))
    with pytest.raises(VisibilityBuilderError, match='without a model view'):
        db_update.update_database(database, part_bag, db_update.UpdateConfig(
            workers=1, min_seen_again=0.0))


def test_images_that_show_nothing_the_database_saw_are_another_place(
        room_db: Path, part_bag: Path, monkeypatch) -> None:
    from visibility_builder import db_update

    # None of the update's features is a class the database had at its pose (a hall's
    # exploration against the room's database showed 3 % of them again).
    monkeypatch.setattr(db_update, 'label_features',
                        lambda features, *a, **k: np.full(len(features), -1, np.int64))
    with pytest.raises(VisibilityBuilderError, match=r'show 0 of the \d+ .*another place'):
        db_update.update_database(open_database(room_db), part_bag,
                                  db_update.UpdateConfig(workers=1))


def test_update_in_place_while_a_localizer_holds_the_database(room_db: Path, part_bag: Path,
                                                              tmp_path: Path) -> None:
    from landmark_localizer.frames import Frame
    from landmark_localizer.localizer import Localizer
    from vbn_common.exploration import read_exploration
    from vbn_common.images import decode_image

    db = Path(shutil.copy(room_db, tmp_path / 'room.db'))
    localizer = Localizer(open_database(db))
    frames = read_exploration(part_bag).frames
    first = localizer.step(Frame(frames[0].stamp_ns, decode_image(frames[0].image)))
    proc = vbn('db-update', str(db), str(part_bag))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert not list(tmp_path.glob('*.tmp*'))      # no scratch file left beside it
    later = localizer.step(Frame(frames[1].stamp_ns, decode_image(frames[1].image)))
    assert first.pose is not None and later.pose is not None
    assert open_database(db).info.parameters['updates'][-1]['bag'] == str(part_bag)

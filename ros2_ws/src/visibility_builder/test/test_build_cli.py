"""``vbn build`` on bad input: one line naming the problem, non-zero exit, nothing written.

Every case runs the real command in a subprocess (as a user would) with an existing
database at ``--db``: a failed build must leave it byte for byte as it was.
"""
from __future__ import annotations

import os
from pathlib import Path
import subprocess

from exploration_samples import IMAGE, exploration_messages, image, pose, write_bag
import pytest

from vbn_common.bags import BagWriter

VBN = 'vbn'
SENTINEL = b'the previous database'


def run_build(bag: Path, db: Path, *args: str) -> tuple[int, str]:
    proc = subprocess.run([VBN, 'build', str(bag), '--db', str(db), '--quiet', *args],
                          capture_output=True, text=True, timeout=600)
    return proc.returncode, proc.stdout + proc.stderr


def assert_one_line_error(code: int, output: str, needle: str) -> None:
    assert code != 0, output
    assert 'Traceback' not in output, output
    errors = [line for line in output.splitlines() if line.startswith('vbn build: error:')]
    assert len(errors) == 1, output
    assert needle in errors[0], output


@pytest.fixture
def db(tmp_path: Path) -> Path:
    path = tmp_path / 'previous.db'
    path.write_bytes(SENTINEL)
    return path


def assert_untouched(db: Path) -> None:
    assert db.read_bytes() == SENTINEL
    assert [p.name for p in db.parent.iterdir() if p.name.startswith('.')] == []


@pytest.mark.parametrize(('case', 'needle'), [
    ('empty', 'contains no messages'),
    ('no_images', 'has no images'),
    ('no_camera_info', 'has no camera info'),
    ('no_pose_source', 'has no pose source'),
    ('only_bad_images', 'no usable image'),
    ('nan_poses', 'no usable'),
])
def test_bad_bags(tmp_path: Path, db: Path, case: str, needle: str) -> None:
    bag = tmp_path / case
    if case == 'empty':
        with BagWriter(bag) as writer:
            writer.add_topic('/camera/image_raw', IMAGE)
    elif case == 'no_images':
        write_bag(bag, [m for m in exploration_messages(3) if m[0] != '/camera/image_raw'])
    elif case == 'no_camera_info':
        write_bag(bag, exploration_messages(3, with_info=False))
    elif case == 'no_pose_source':
        write_bag(bag, exploration_messages(3, with_truth=False))
    elif case == 'only_bad_images':
        bad = [image(0, step=3), image(1, encoding='yuv422'), image(2, size=5)]
        write_bag(bag, exploration_messages(3, images=bad))
    else:
        nan = float('nan')
        write_bag(bag, exploration_messages(3, poses=[pose(0, nan, 0, 0)] * 3))
    code, output = run_build(bag, db)
    assert_one_line_error(code, output, needle)
    assert_untouched(db)


def test_bad_output_folder_and_settings(tmp_path: Path, db: Path) -> None:
    bag = write_bag(tmp_path / 'bag', exploration_messages(3))
    code, output = run_build(bag, tmp_path / 'missing' / 'x.db')
    assert_one_line_error(code, output, f'output folder {tmp_path / "missing"} does not exist')
    assert not (tmp_path / 'missing').exists()
    code, output = run_build(bag, tmp_path)
    assert_one_line_error(code, output, 'is a folder, not a file')
    code, output = run_build(bag, db, '--k', '0')
    assert_one_line_error(code, output, 'k must be an integer >= 1')
    code, output = run_build(bag, db, '--algorithm', 'nope')
    assert_one_line_error(code, output, "unknown algorithm 'nope'")
    code, output = run_build(bag, db, '--set', 'classes.nope=3')
    assert_one_line_error(code, output, "unknown build setting 'classes.nope'")
    assert_untouched(db)


@pytest.mark.skipif(os.geteuid() == 0, reason='root writes into read-only folders')
def test_read_only_folder(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / 'bag', exploration_messages(3))
    folder = tmp_path / 'ro'
    folder.mkdir()
    folder.chmod(0o555)
    try:
        code, output = run_build(bag, folder / 'x.db')
    finally:
        folder.chmod(0o755)
    assert_one_line_error(code, output, 'is not writable')

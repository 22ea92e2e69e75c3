"""Tests of vbn_common.atomic: output appears whole on success, never on failure."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from vbn_common import atomic
from vbn_common.atomic import atomic_output, write_bytes_atomic, write_text_atomic
from vbn_common.errors import VbnCommonError


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith('.'))


def test_file_content_appears_only_on_success(tmp_path: Path) -> None:
    target = tmp_path / 'out.json'
    with atomic_output(target) as temporary:
        assert temporary.parent == tmp_path
        assert temporary.name.startswith('.out.json.')
        temporary.write_text('{"a": 1}')
        assert not target.exists()
    assert target.read_text() == '{"a": 1}'
    assert _leftovers(tmp_path) == []


def test_exception_keeps_previous_file_and_removes_temporary(tmp_path: Path) -> None:
    target = tmp_path / 'out.json'
    target.write_text('old')
    with pytest.raises(RuntimeError, match='boom'):
        with atomic_output(target) as temporary:
            temporary.write_text('new, half written')
            raise RuntimeError('boom')
    assert target.read_text() == 'old'
    assert _leftovers(tmp_path) == []


def test_keyboard_interrupt_also_cleans_up(tmp_path: Path) -> None:
    target = tmp_path / 'out.bin'
    with pytest.raises(KeyboardInterrupt):
        with atomic_output(target) as temporary:
            temporary.write_bytes(b'partial')
            raise KeyboardInterrupt
    assert not target.exists()
    assert list(tmp_path.iterdir()) == []


def test_replaces_existing_file(tmp_path: Path) -> None:
    target = tmp_path / 'out.txt'
    target.write_text('old')
    write_text_atomic(target, 'new\n')
    assert target.read_text() == 'new\n'
    write_bytes_atomic(target, b'\x00\x01')
    assert target.read_bytes() == b'\x00\x01'
    assert _leftovers(tmp_path) == []


def test_new_file_permissions_follow_umask(tmp_path: Path) -> None:
    previous = os.umask(0o022)
    try:
        write_text_atomic(tmp_path / 'out.txt', 'x')
    finally:
        os.umask(previous)
    assert (tmp_path / 'out.txt').stat().st_mode & 0o777 == 0o644


def test_bare_file_name_writes_into_current_folder(tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    write_text_atomic('plain.txt', 'x')
    assert (tmp_path / 'plain.txt').read_text() == 'x'


def test_directory_output_appears_only_on_success(tmp_path: Path) -> None:
    target = tmp_path / 'bag'
    with atomic_output(target, directory=True) as temporary:
        assert not temporary.exists()  # the caller creates it (rosbags' Writer insists)
        temporary.mkdir()
        (temporary / 'metadata.yaml').write_text('meta')
        (temporary / 'sub').mkdir()
        (temporary / 'sub' / 'data.mcap').write_bytes(b'mcap')
        assert not target.exists()
    assert (target / 'metadata.yaml').read_text() == 'meta'
    assert (target / 'sub' / 'data.mcap').read_bytes() == b'mcap'
    assert _leftovers(tmp_path) == []


def test_directory_replaces_previous_folder(tmp_path: Path) -> None:
    target = tmp_path / 'bag'
    target.mkdir()
    (target / 'stale.mcap').write_bytes(b'old')
    with atomic_output(target, directory=True) as temporary:
        temporary.mkdir()
        (temporary / 'fresh.mcap').write_bytes(b'new')
    assert sorted(p.name for p in target.iterdir()) == ['fresh.mcap']
    assert _leftovers(tmp_path) == []


def test_directory_exception_keeps_previous_folder(tmp_path: Path) -> None:
    target = tmp_path / 'bag'
    target.mkdir()
    (target / 'old.mcap').write_bytes(b'old')
    with pytest.raises(ValueError, match='bad message'):
        with atomic_output(target, directory=True) as temporary:
            temporary.mkdir()
            (temporary / 'new.mcap').write_bytes(b'partial')
            raise ValueError('bad message')
    assert sorted(p.name for p in target.iterdir()) == ['old.mcap']
    assert (target / 'old.mcap').read_bytes() == b'old'
    assert _leftovers(tmp_path) == []


def test_directory_failed_rename_restores_previous_folder(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    target = tmp_path / 'bag'
    target.mkdir()
    (target / 'old.mcap').write_bytes(b'old')
    real_rename = os.rename

    def rename(source: os.PathLike[str], destination: os.PathLike[str]) -> None:
        if Path(destination) == target and Path(source).name.startswith('.bag.'):
            if any(p.name == 'new.mcap' for p in Path(source).iterdir()):
                raise OSError(28, 'No space left on device')
        real_rename(source, destination)

    monkeypatch.setattr(atomic.os, 'rename', rename)
    with pytest.raises(VbnCommonError, match=r'^cannot write .*bag \(No space left'):
        with atomic_output(target, directory=True) as temporary:
            temporary.mkdir()
            (temporary / 'new.mcap').write_bytes(b'new')
    assert sorted(p.name for p in target.iterdir()) == ['old.mcap']
    assert _leftovers(tmp_path) == []


def test_directory_output_that_writes_nothing_is_an_error(tmp_path: Path) -> None:
    with pytest.raises(VbnCommonError, match='nothing was written'):
        with atomic_output(tmp_path / 'bag', directory=True):
            pass
    assert list(tmp_path.iterdir()) == []


def test_missing_folder_names_the_folder(tmp_path: Path) -> None:
    folder = tmp_path / 'no' / 'such'
    with pytest.raises(VbnCommonError) as caught:
        write_text_atomic(folder / 'x.json', 'x')
    assert str(caught.value) == f'output folder {folder} does not exist'
    assert '.tmp' not in str(caught.value)
    assert not (tmp_path / 'no').exists()


def test_parent_that_is_a_file_is_reported(tmp_path: Path) -> None:
    (tmp_path / 'plain').write_text('x')
    with pytest.raises(VbnCommonError, match='is not a folder'):
        write_text_atomic(tmp_path / 'plain' / 'x.json', 'x')


def test_file_output_onto_a_folder_is_reported(tmp_path: Path) -> None:
    (tmp_path / 'out').mkdir()
    with pytest.raises(VbnCommonError, match='is a folder; expected a file name'):
        write_text_atomic(tmp_path / 'out', 'x')
    assert (tmp_path / 'out').is_dir()


def test_readonly_folder_by_access_check(tmp_path: Path,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    # As root, os.access says every folder is writable (except on read-only file
    # systems), so the test simulates a folder the user may not write.
    real_access = os.access
    monkeypatch.setattr(atomic.os, 'access',
                        lambda p, mode: False if Path(p) == tmp_path else real_access(p, mode))
    with pytest.raises(VbnCommonError) as caught:
        write_text_atomic(tmp_path / 'x.json', 'x')
    assert str(caught.value) == f'output folder {tmp_path} is not writable'
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(os.geteuid() == 0, reason='root may write into a mode 0555 folder')
def test_readonly_folder_for_real(tmp_path: Path) -> None:
    folder = tmp_path / 'locked'
    folder.mkdir()
    folder.chmod(0o555)
    try:
        with pytest.raises(VbnCommonError, match=f'^output folder {folder} is not writable$'):
            write_text_atomic(folder / 'x.json', 'x')
    finally:
        folder.chmod(0o755)


def test_permission_error_creating_the_temporary_names_the_folder(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # What root meets on a folder that access() lets through but open() refuses.
    def refuse(*args: object, **kwargs: object) -> int:
        raise PermissionError(13, 'Permission denied')

    monkeypatch.setattr(atomic.os, 'open', refuse)
    with pytest.raises(VbnCommonError) as caught:
        write_text_atomic(tmp_path / 'x.json', 'x')
    assert str(caught.value) == f'output folder {tmp_path} is not writable'

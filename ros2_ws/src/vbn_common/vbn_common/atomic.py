"""Atomic output: a file or a folder appears complete under its name, or not at all.

Every output of the project (world, decomposition and scene JSON, rosbag2 directories,
the SQLite landmark database) is written through :func:`atomic_output`: the writer fills
a hidden temporary sibling in the same folder, which is flushed to disk and renamed into
place only when the writer finishes without an exception. A crash, an exception or an
interrupt leaves the previous output (if any) untouched and no temporary behind.

The output folder is checked before anything is written, so a user who mistypes it reads
``output folder results/run1 does not exist`` rather than an error about an internal
temporary file name.
"""
from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
import logging
import os
from pathlib import Path
import secrets
import shutil

from vbn_common.errors import VbnCommonError

__all__ = ['atomic_output', 'check_output_folder', 'write_bytes_atomic', 'write_text_atomic']

logger = logging.getLogger(__name__)

_NEW_FILE_MODE = 0o666  # like open(path, 'w'): the umask decides the final permissions


def check_output_folder(path: str | Path) -> Path:
    """Check that the folder an output file or folder goes into exists and is writable.

    Args:
        path: the output file or folder (its parent is checked, not ``path`` itself).

    Returns:
        The parent folder (``.`` for a bare file name).

    Raises:
        VbnCommonError: ``'output folder <folder> does not exist'``, ``'... is not a
            folder'`` or ``'... is not writable'``.
    """
    folder = Path(path).parent
    if not folder.exists():
        raise VbnCommonError(f'output folder {folder} does not exist')
    if not folder.is_dir():
        raise VbnCommonError(f'output folder {folder} is not a folder')
    # os.access answers for the real user: for root it says yes except on read-only
    # file systems; the creation of the temporary below reports what access() misses.
    if not os.access(folder, os.W_OK | os.X_OK):
        raise VbnCommonError(f'output folder {folder} is not writable')
    return folder


def _temporary_name(target: Path) -> Path:
    return target.with_name(f'.{target.name}.{secrets.token_hex(6)}.tmp')


def _create_temporary(target: Path, directory: bool) -> Path:
    """Reserve a hidden sibling of ``target``: an empty file, or a free folder name."""
    folder = target.parent
    for _ in range(100):
        temporary = _temporary_name(target)
        try:
            if directory:
                # Bag writers (rosbags) refuse an existing folder: reserve the name only.
                if os.path.lexists(temporary):
                    continue
                return temporary
            os.close(os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL,
                             _NEW_FILE_MODE))
            return temporary
        except FileExistsError:
            continue
        except PermissionError as error:
            raise VbnCommonError(f'output folder {folder} is not writable') from error
        except OSError as error:
            raise VbnCommonError(
                f'output folder {folder} is not writable ({error.strerror})') from error
    raise VbnCommonError(f'output folder {folder}: no free temporary name')


def _fsync_path(path: Path) -> None:
    descriptor = os.open(path, os.O_RDONLY)
    try:
        os.fsync(descriptor)
    except OSError:
        # Some file systems cannot fsync folders (EINVAL): the rename is still atomic.
        if not path.is_dir():
            raise
    finally:
        os.close(descriptor)


def _fsync_tree(folder: Path) -> None:
    """Flush every file and folder below ``folder`` (deepest first), then ``folder``."""
    for root, folders, files in os.walk(folder, topdown=False):
        for name in files:
            if not os.path.islink(os.path.join(root, name)):
                _fsync_path(Path(root, name))
        for name in folders:
            if not os.path.islink(os.path.join(root, name)):
                _fsync_path(Path(root, name))
    _fsync_path(folder)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    elif os.path.lexists(path):
        try:
            path.unlink()
        except OSError:
            logger.warning('could not remove the temporary %s', path)


def _replace_folder(temporary: Path, target: Path) -> None:
    """Rename the folder ``temporary`` to ``target``, replacing whatever is there."""
    if not os.path.lexists(target):
        os.rename(temporary, target)
        return
    aside = _temporary_name(target)
    os.rename(target, aside)
    try:
        os.rename(temporary, target)
    except BaseException:
        os.rename(aside, target)
        raise
    _remove(aside)


@contextmanager
def atomic_output(path: str | Path, *, directory: bool = False) -> Iterator[Path]:
    """Write a file or a folder under a temporary name; rename it into place on success.

    Args:
        path: the final output file (or folder with ``directory=True``).
        directory: the output is a folder (a rosbag2 directory, say).

    Yields:
        A hidden temporary sibling of ``path`` in the same folder, for the caller to
        write: for a file, an existing empty file; for a folder, a name that does not
        exist yet (the caller creates the folder, as rosbags' ``Writer`` insists).

    Raises:
        VbnCommonError: the output folder is missing or not writable, ``path`` is a
            folder where a file is meant (or a folder output created nothing), or the
            final rename fails. Exceptions raised by the caller's block pass through
            unchanged after the temporary is removed.

    Notes:
        On a clean exit the file (or every file in the folder, and the folder) is
        fsynced, renamed over ``path`` (``os.replace`` for a file; for a folder the old
        one is renamed aside, the new one renamed in, then the old one removed) and the
        parent folder is fsynced. On an exception the temporary is removed and a
        previous ``path`` is left as it was.

    Example:
        >>> with atomic_output(tmp / 'out.txt') as temporary:  # doctest: +SKIP
        ...     temporary.write_text('done')
    """
    target = Path(path)
    folder = check_output_folder(target)
    if not directory and target.is_dir():
        raise VbnCommonError(f'{target} is a folder; expected a file name')
    temporary = _create_temporary(target, directory)
    try:
        yield temporary
        if not os.path.lexists(temporary):
            raise VbnCommonError(f'{target}: nothing was written')
        if temporary.is_dir():
            _fsync_tree(temporary)
            try:
                _replace_folder(temporary, target)
            except OSError as error:
                raise VbnCommonError(f'cannot write {target} ({error.strerror})') from error
        else:
            _fsync_path(temporary)
            try:
                os.replace(temporary, target)
            except OSError as error:
                raise VbnCommonError(f'cannot write {target} ({error.strerror})') from error
    except BaseException:
        _remove(temporary)
        raise
    _fsync_path(folder)


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    """Write ``data`` to the file ``path`` atomically (see :func:`atomic_output`).

    Args:
        path: the target file.
        data: its whole new content.

    Raises:
        VbnCommonError: the output folder is missing or not writable.
    """
    with atomic_output(path) as temporary:
        temporary.write_bytes(data)


def write_text_atomic(path: str | Path, text: str, encoding: str = 'utf-8') -> None:
    """Write ``text`` to the file ``path`` atomically (see :func:`atomic_output`).

    Args:
        path: the target file.
        text: its whole new content.
        encoding: the text encoding.

    Raises:
        VbnCommonError: the output folder is missing or not writable.
    """
    with atomic_output(path) as temporary:
        temporary.write_text(text, encoding=encoding)

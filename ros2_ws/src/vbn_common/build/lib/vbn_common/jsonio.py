"""Reading and writing the package's JSON files with one-line errors and atomic writes.

World instances, decompositions and scenes are JSON files that users write by hand or
with other tools, so every loader reports a missing file, unreadable bytes, invalid JSON
and an invalid document the same way: one line starting with the path, raised as the
caller's package's error. Writers never leave a half-written file (see ``vbn_common.atomic``).
"""
from __future__ import annotations

from collections.abc import Callable
import json
from pathlib import Path
from typing import Any, TypeVar

from vbn_common.atomic import write_text_atomic
from vbn_common.errors import VbnCommonError, VbnError

__all__ = ['read_json_file', 'write_json_atomic']

T = TypeVar('T')


def read_json_file(path: str | Path, parse: Callable[[Any], T],
                   error_class: type[VbnError] = VbnCommonError) -> T:
    """Read a JSON file and build an object from it.

    Args:
        path: the file.
        parse: builds the object from the decoded JSON; raises a ``VbnError`` naming
            what is invalid.
        error_class: the error to raise, the caller's package's (a world file gives a
            ``LandmarkDbError``, a change set a ``WorldsError``).

    Returns:
        What ``parse`` returns.

    Raises:
        VbnError: of ``error_class``, ``'<path>: <problem>'`` for a missing or
            unreadable file, invalid JSON or an invalid document.
    """
    try:
        text = Path(path).read_text(encoding='utf-8')
    except FileNotFoundError as error:
        raise error_class(f'{path}: no such file') from error
    except (OSError, UnicodeDecodeError) as error:
        raise error_class(f'{path}: cannot read ({error})') from error
    try:
        data = json.loads(text)
    except json.JSONDecodeError as error:
        raise error_class(f'{path}: not valid JSON ({error})') from error
    try:
        return parse(data)
    except VbnError as error:
        raise error_class(f'{path}: {error}') from error


def write_json_atomic(data: Any, path: str | Path, indent: int | None = None) -> None:
    """Write ``data`` as JSON to ``path`` via a temporary file and a rename.

    Args:
        data: a JSON-ready object.
        path: the target file.
        indent: ``None`` for compact JSON, else the indentation (for hand-edited files).

    Raises:
        VbnCommonError: the output folder is missing or not writable.
    """
    if indent is None:
        text = json.dumps(data, separators=(',', ':'))
    else:
        text = json.dumps(data, indent=indent)
    write_text_atomic(path, text + '\n')

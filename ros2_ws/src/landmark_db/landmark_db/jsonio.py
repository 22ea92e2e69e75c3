"""Reading and writing the package's JSON files with one-line errors and atomic writes.

World instances, decompositions and scenes are JSON files that users write by hand or
with other tools, so every loader reports a missing file, unreadable bytes, invalid JSON
and an invalid document the same way: one ``LandmarkDbError`` line starting with the
path. Writers never leave a half-written file (see ``landmark_db.atomic``).
"""
from __future__ import annotations

from collections.abc import Callable
import json
from pathlib import Path
from typing import Any, TypeVar

from landmark_db.atomic import write_text_atomic
from landmark_db.errors import LandmarkDbError

__all__ = ['read_json_file', 'write_json_atomic']

T = TypeVar('T')


def read_json_file(path: str | Path, parse: Callable[[Any], T]) -> T:
    """Read a JSON file and build an object from it.

    Args:
        path: the file.
        parse: builds the object from the decoded JSON; raises ``LandmarkDbError``
            naming what is invalid.

    Returns:
        What ``parse`` returns.

    Raises:
        LandmarkDbError: ``'<path>: <problem>'`` for a missing or unreadable file,
            invalid JSON or an invalid document.
    """
    try:
        text = Path(path).read_text(encoding='utf-8')
    except FileNotFoundError:
        raise LandmarkDbError(f'{path}: no such file') from None
    except (OSError, UnicodeDecodeError) as error:
        raise LandmarkDbError(f'{path}: cannot read ({error})') from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as error:
        raise LandmarkDbError(f'{path}: not valid JSON ({error})') from None
    try:
        return parse(data)
    except LandmarkDbError as error:
        raise LandmarkDbError(f'{path}: {error}') from None


def write_json_atomic(data: Any, path: str | Path, indent: int | None = None) -> None:
    """Write ``data`` as JSON to ``path`` via a temporary file and a rename.

    Args:
        data: a JSON-ready object.
        path: the target file.
        indent: ``None`` for compact JSON, else the indentation (for hand-edited files).

    Raises:
        LandmarkDbError: the output folder is missing or not writable.
    """
    if indent is None:
        text = json.dumps(data, separators=(',', ':'))
    else:
        text = json.dumps(data, indent=indent)
    write_text_atomic(path, text + '\n')

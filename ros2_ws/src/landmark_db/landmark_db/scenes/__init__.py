"""Shipped scenes for the renderer and how ``--scene`` finds them.

``room`` is a 6 m x 3 m room with three obstacles, like the thesis's Room 408 data
set (Section 8.3.2); ``floor`` is a 20 m x 10 m office floor: seven rooms off a
corridor, with furniture. The format is :mod:`landmark_db.scene`'s scene JSON.
"""
from __future__ import annotations

from importlib import resources
from pathlib import Path

from landmark_db.errors import LandmarkDbError
from landmark_db.scene import Scene, load_scene

__all__ = ['resolve_scene', 'shipped_scene_names']


def shipped_scene_names() -> list[str]:
    """Return the names of the scenes shipped with the package, sorted."""
    folder = resources.files(__name__)
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith('.json'))


def resolve_scene(name_or_path: str | Path) -> Scene:
    """Load a scene from a JSON file path or by the name of a shipped scene.

    A path that exists is read as a scene file; otherwise the argument must name a
    shipped scene (``room``, ``floor``).

    Raises:
        LandmarkDbError: unknown name, missing file or invalid scene JSON.
    """
    text = str(name_or_path)
    path = Path(text)
    if not path.exists():
        if text in shipped_scene_names():
            with resources.as_file(resources.files(__name__) / f'{text}.json') as shipped:
                return _load(shipped)
        raise LandmarkDbError(
            f'unknown scene {text!r}: not a file and not a shipped scene '
            f'({", ".join(shipped_scene_names())})')
    if path.is_dir():
        raise LandmarkDbError(f'scene {text!r} is a directory, not a scene JSON file')
    return _load(path)


def _load(path: Path) -> Scene:
    try:
        return load_scene(path)
    except LandmarkDbError as error:
        raise LandmarkDbError(f'invalid scene: {error}') from error
    except (OSError, UnicodeDecodeError) as error:
        raise LandmarkDbError(f'cannot read scene {path}: {error}') from error

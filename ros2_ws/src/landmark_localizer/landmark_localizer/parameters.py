"""The localizer node's parameters: what each is, its default, and whether it is live.

Pure Python (no rclpy): :class:`NodeSettings` are the node's own parameters,
:class:`~landmark_localizer.config.LocalizerConfig` the core's; :func:`parameter_specs`
lists both with their descriptions (from the dataclasses' docstrings) and says which are
read-only, :func:`settings_from_values` checks a full set of values, and
:func:`unknown_parameters` names a misspelt parameter with the closest known one.

Every parameter either takes effect when set at run time or is read-only:

- the core's (thresholds, windows, the two-view method, the seed) from the next frame;
- ``db`` reloads the database (a bad one is refused with the reason, the old one kept);
- the frames, ``tf_broadcast``, ``transform_tolerance``, ``transform_publish_period`` and
  ``odom_max_jump_m`` from the next message or period;
- ``autostart`` (only meaningful at start-up) and ``image_reliable`` (the image
  subscriptions' QoS) are read-only.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from landmark_localizer.config import LocalizerConfig
from landmark_localizer.errors import LocalizerError
from vbn_common.names import BASE_FRAME, MAP_FRAME, ODOM_FRAME
from vbn_common.parameters import attribute_docs, unknown_parameters

__all__ = ['READ_ONLY', 'NodeSettings', 'ParameterSpec', 'config_descriptions',
           'parameter_specs', 'settings_from_values', 'unknown_parameters']

#: Parameters that cannot change once the node runs.
READ_ONLY = frozenset({'autostart', 'image_reliable'})


@dataclass(frozen=True)
class ParameterSpec:
    """One declared parameter: name, default (its type is the parameter's), description."""

    name: str
    default: Any
    description: str
    read_only: bool


@dataclass(frozen=True)
class NodeSettings:
    """The node's own parameters (the core's are :class:`LocalizerConfig`'s).

    Attributes:
        db: The landmark database file (required); setting it at run time reloads the
            database, and a file that cannot be used is refused, the old one kept.
        autostart: Configure and activate at start-up; false: stay unconfigured until a
            lifecycle manager (nav2's, or the ~/change_state service) drives the node.
        tf_broadcast: Broadcast ``map -> odom`` on ``/tf`` (AMCL's parameter).
        transform_tolerance: How far ahead of the image's (or latest odometry's) stamp
            the ``map -> odom`` transform is stamped, seconds (AMCL's parameter).
        transform_publish_period: Republish the last ``map -> odom`` this often, seconds
            (0 disables republishing).
        global_frame_id: The map frame.
        odom_frame_id: The odometry frame.
        base_frame_id: The robot's frame.
        odom_max_jump_m: Consecutive odometry poses further apart than this are a jump:
            the odometry history restarts.
        image_reliable: Subscribe to the images reliable (still depth 1) instead of best
            effort; for raw images over 0.5 MB, which Fast DDS drops between processes when
            best effort (ros2/rmw_fastrtps#739); needs a reliable publisher.
    """

    db: str = ''
    autostart: bool = True
    tf_broadcast: bool = True
    transform_tolerance: float = 0.1
    transform_publish_period: float = 0.1
    global_frame_id: str = MAP_FRAME
    odom_frame_id: str = ODOM_FRAME
    base_frame_id: str = BASE_FRAME
    odom_max_jump_m: float = 1.0
    image_reliable: bool = False

    def __post_init__(self) -> None:
        for name in ('transform_tolerance', 'transform_publish_period', 'odom_max_jump_m'):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise LocalizerError(f'{name} must be a finite number >= 0, got {value}')
        frames = (self.global_frame_id, self.odom_frame_id, self.base_frame_id)
        if not all(frames) or len(set(frames)) != 3:
            raise LocalizerError(f'global_frame_id, odom_frame_id and base_frame_id must be '
                                 f'three different names, got {frames}')


def config_descriptions(cls: type = LocalizerConfig) -> dict[str, str]:
    """Return each field's description from a dataclass's ``Attributes:`` docstring."""
    docs = attribute_docs(cls)
    return {f.name: docs.get(f.name, '') for f in fields(cls)}


def parameter_specs() -> list[ParameterSpec]:
    """Return every parameter of the node: its own settings, then the core's."""
    described = {**config_descriptions(NodeSettings), **config_descriptions(LocalizerConfig)}
    described['db'] += ' (-p db:=FILE)'
    defaults = {**asdict(NodeSettings()), **LocalizerConfig().as_dict()}
    return [ParameterSpec(name, value, described.get(name, ''), name in READ_ONLY)
            for name, value in defaults.items()]


def settings_from_values(values: dict[str, Any], require_db: bool = True
                         ) -> tuple[NodeSettings, LocalizerConfig]:
    """Check a full set of parameter values; return the node's settings and the core's.

    Args:
        values: Every parameter of :func:`parameter_specs` by name (others are ignored).
        require_db: ``db`` must name a file (not yet while the node is unconfigured).

    Returns:
        ``(settings, config)``.

    Raises:
        LocalizerError: a value out of range, or ``db`` empty.
    """
    node_names = {f.name for f in fields(NodeSettings)}
    core_names = {f.name for f in fields(LocalizerConfig)}
    settings = NodeSettings(**{k: v for k, v in values.items() if k in node_names})
    config = LocalizerConfig().with_values({k: v for k, v in values.items()
                                            if k in core_names})
    if require_db and not settings.db:
        raise LocalizerError('parameter db is required (-p db:=FILE)')
    return settings, config

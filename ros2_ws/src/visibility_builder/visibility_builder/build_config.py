"""The builder's settings: one frozen :class:`BuildConfig`, one section per step.

The defaults live in the step configs' dataclasses (each step's module); this module
groups them, names every setting ``section.name`` (the ROS parameter names of the
builder node, ``vbn build --set`` and the database's build parameters) and reads each
setting's description from the dataclasses' docstrings.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any

import numpy as np

from landmark_db.database.codebook import CODE_SIZES
from landmark_db.database.fields import DESCRIPTOR_SIZE
from landmark_db.decomposition import ALGORITHMS
from vbn_common.exploration import ReadConfig
from vbn_common.features import SiftConfig
from vbn_common.parameters import attribute_docs
from vbn_common.workers import available_cores
from visibility_builder.classes import ClassConfig
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.filters import FilterConfig
from visibility_builder.model_views import ModelViewConfig
from visibility_builder.sampled_poses import SamplingConfig
from visibility_builder.scene_points import PointsConfig
from visibility_builder.verification import VerifyConfig

__all__ = ['TOP_SETTINGS', 'BuildConfig', 'DecompositionConfig', 'config_from_flat',
           'flat_config', 'setting_descriptions']


@dataclass(frozen=True)
class DecompositionConfig:
    """The decomposition step (Chapter 5).

    Attributes:
        algorithm: One of ``landmark_db.decomposition.ALGORITHMS``.
        k: Features per landmark.
        rho: Overlap radius in pose-graph steps.
        sigma: A region must cover more than ``sigma`` otherwise uncovered poses.
        seed: Tie-breaking seed.
    """

    algorithm: str = 'best'
    k: int = 8
    rho: int = 1
    sigma: int = 0
    seed: int = 0

    def __post_init__(self) -> None:
        if self.algorithm not in ALGORITHMS:
            raise VisibilityBuilderError(f'unknown algorithm {self.algorithm!r}; choose one '
                                         f'of {", ".join(ALGORITHMS)}')
        for name, least in (('k', 1), ('rho', 0), ('sigma', 0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) \
                    or value < least:
                raise VisibilityBuilderError(f'{name} must be an integer >= {least}, '
                                             f'got {value!r}')


@dataclass(frozen=True)
class BuildConfig:
    """Everything ``build`` needs, one frozen config per step.

    Attributes:
        read: Topics, pose source and tolerances.
        sampling: Grouping frames into poses, graph connectivity.
        sift: SIFT settings (stored in the database for the localizer).
        classes: Algorithm 6.3 (tau, gamma, ratio).
        verify: Geometric verification of the classes.
        filters: Section 6.2.2 filters.
        decomposition: Algorithm, k, rho, sigma.
        model_views: Views and extra features per region.
        points: The scene points kept beside the regions.
        descriptors_per_class: Representative descriptors kept per class.
        descriptor_bytes: Bytes of each stored descriptor: 8, 16, 32 or 64 store the
            code of a product quantizer learnt on the database's descriptors (a third of
            the room's file at 16), 128 stores them whole.
        workers: Processes for SIFT and matching (None: every core).
    """

    read: ReadConfig = field(default_factory=ReadConfig)
    sampling: SamplingConfig = field(default_factory=SamplingConfig)
    sift: SiftConfig = field(default_factory=SiftConfig)
    classes: ClassConfig = field(default_factory=ClassConfig)
    verify: VerifyConfig = field(default_factory=VerifyConfig)
    filters: FilterConfig = field(default_factory=FilterConfig)
    decomposition: DecompositionConfig = field(default_factory=DecompositionConfig)
    model_views: ModelViewConfig = field(default_factory=ModelViewConfig)
    points: PointsConfig = field(default_factory=PointsConfig)
    descriptors_per_class: int = 4
    descriptor_bytes: int = 16
    workers: int | None = None

    def __post_init__(self) -> None:
        if self.descriptors_per_class < 1:
            raise VisibilityBuilderError(
                f'descriptors_per_class must be >= 1, got {self.descriptors_per_class}')
        if self.descriptor_bytes not in (*CODE_SIZES, DESCRIPTOR_SIZE):
            raise VisibilityBuilderError(f'descriptor_bytes must be one of {CODE_SIZES} or '
                                         f'{DESCRIPTOR_SIZE}, got {self.descriptor_bytes!r}')
        if self.workers is not None and self.workers < 1:
            raise VisibilityBuilderError(f'workers must be >= 1, got {self.workers}')

    @property
    def n_workers(self) -> int:
        """Processes to use."""
        return self.workers or available_cores()


_SECTIONS = ('read', 'sampling', 'sift', 'classes', 'verify', 'filters', 'decomposition',
             'model_views', 'points')
TOP_SETTINGS = ('descriptors_per_class', 'descriptor_bytes', 'workers')
"""The settings outside a section (``vbn build --set NAME=VALUE``)."""


def flat_config(config: BuildConfig) -> dict[str, Any]:
    """``{'section.name': value}`` of every setting (ROS parameter names, the database)."""
    out: dict[str, Any] = {}
    for section in _SECTIONS:
        for key, value in asdict(getattr(config, section)).items():
            out[f'{section}.{key}'] = value
    for name in TOP_SETTINGS:
        out[name] = getattr(config, name)
    return out


def config_from_flat(values: dict[str, Any], base: BuildConfig | None = None) -> BuildConfig:
    """Return ``base`` (default: the defaults) with ``{'section.name': value}`` applied.

    Raises:
        VisibilityBuilderError: An unknown name or a value the step refuses.
    """
    base = base or BuildConfig()
    sections: dict[str, dict[str, Any]] = {s: {} for s in _SECTIONS}
    top: dict[str, Any] = {}
    for name, value in values.items():
        section, _, key = name.rpartition('.')
        if not section:
            if name not in TOP_SETTINGS:
                raise VisibilityBuilderError(f'unknown build setting {name!r}')
            top[name] = value
            continue
        if section not in sections or key not in {f.name for f in fields(
                getattr(base, section))}:
            raise VisibilityBuilderError(f'unknown build setting {name!r}')
        sections[section][key] = value
    try:
        changed = {s: replace(getattr(base, s), **v) for s, v in sections.items() if v}
        return replace(base, **changed, **top)
    except TypeError as error:
        raise VisibilityBuilderError(f'bad build setting: {error}') from error


def setting_descriptions(config: BuildConfig | None = None) -> dict[str, str]:
    """``{'section.name': description}`` of every setting, from the config docstrings."""
    config = config or BuildConfig()
    out: dict[str, str] = {}
    for section in _SECTIONS:
        docs = attribute_docs(type(getattr(config, section)))
        for key in asdict(getattr(config, section)):
            out[f'{section}.{key}'] = docs.get(key, '')
    top = attribute_docs(BuildConfig)
    for name in TOP_SETTINGS:
        out[name] = top.get(name, '')
    return out

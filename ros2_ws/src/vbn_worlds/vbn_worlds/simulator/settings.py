"""The four synthetic world settings of the thesis's experiment (Section 8.2, Table 8.1).

Each world parameter of Table 8.1 is drawn from a mixture distribution. The thesis
gives the feature types and the shape-class mixtures; it leaves several parameters
unstated, and this module fixes them, each with its reason:

* **Feature types** (Section 8.2): Type 1 range ``N(0.65, 0.2)`` to ``N(12.5, 1)`` m,
  angular range ``N(25, 3)`` degrees; Type 2 range ``N(0.65, 0.2)`` to ``N(17.5, 2)``
  m, angular range ``N(45, 4)`` degrees. ``N(mu, s)`` has standard deviation ``s``.
  The thesis does not say whether the angular range is the full aperture of the
  visibility cone or its half-angle about the wall normal. We read it as the **full
  aperture** (a Type 1 feature is seen within about 12.5 degrees of its normal), as
  :class:`~landmark_db.scene.SceneFeatures` defines ``angular_extent_deg``: at the
  Table 8.4 visibility counts this reading reproduces Table 8.3's region sizes, while
  the half-angle reading gives regions about twice as large (docs/simulator.md).
  :attr:`FeatureType.angle_is_half_aperture` switches the reading.
* **Shape classes**: rectangular worlds (axis-aligned rectangular perimeter and
  obstacles; obstacle count from ``{U(6, 9) p=.5; N(10, 2) p=.5}``) and irregular
  worlds (perimeter sides from ``{U(4, 4) p=.1; N(5, .5) p=.45; N(7, 2) p=.45}``,
  obstacle count from ``{U(5, 9) p=.5; N(8, 2) p=.5}``). The thesis does not give
  the obstacles' side counts for irregular worlds: they reuse the perimeter's
  side-count mixture.
* **Size**: "an average diameter of 40 m". Rectangular worlds have sides of
  ``N(40, 3)`` m; irregular worlds a vertex radius ``R`` of ``N(22.5, 1.5)`` m with
  each vertex at ``U(0.8, 1) R`` (a diameter of about 40 m). This makes the pose
  count of rectangular worlds about 1.7 times that of irregular ones, near the ratio
  that Tables 8.2 x 8.3 imply (summed region sizes, 9122 vs 5794 for Type 1 and
  11780 vs 7240 for Type 2).
* **Obstacle size** (not given): a vertex radius (half-diagonal for rectangles) of
  ``U(1, 3)`` m, at least :attr:`ShapeClass.clearance` metres from every other wall.
* **Feature count** (not given): a density in features per metre of wall, chosen per
  setting so that the mean number of features visible per pose matches Table 8.4
  (30, 95, 41, 117); ``vbn bench-decomposition --calibrate`` measures it.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from vbn_worlds.errors import WorldsError

__all__ = ['FeatureType', 'Mixture', 'SETTINGS', 'ShapeClass',
           'WorldSetting', 'get_setting', 'small_setting']

@dataclass(frozen=True)
class Mixture:
    """A mixture of uniform and normal components, as the thesis writes them.

    Attributes:
        components: ``(kind, a, b, weight)`` tuples; ``kind`` is ``'U'`` (uniform on
            ``[a, b]``) or ``'N'`` (normal with mean ``a`` and standard deviation ``b``).
    """

    components: tuple[tuple[str, float, float, float], ...]

    def sample(self, rng: np.random.Generator, size: int | None = None) -> np.ndarray:
        """Draw ``size`` values (a 0-d array when ``size`` is None)."""
        weights = np.array([c[3] for c in self.components], dtype=float)
        n = 1 if size is None else size
        choice = rng.choice(len(self.components), size=n, p=weights / weights.sum())
        out = np.empty(n)
        for index, (kind, a, b, _) in enumerate(self.components):
            mask = choice == index
            count = int(mask.sum())
            if kind == 'U':
                out[mask] = rng.uniform(a, b, count)
            else:
                out[mask] = rng.normal(a, b, count)
        return out[0] if size is None else out

    def sample_count(self, rng: np.random.Generator, minimum: int) -> int:
        """Draw one value rounded to an integer of at least ``minimum``."""
        return max(minimum, int(round(float(self.sample(rng)))))


def _normal(mean: float, std: float) -> Mixture:
    return Mixture((('N', mean, std, 1.0),))


@dataclass(frozen=True)
class FeatureType:
    """Visibility properties of the features of one setting.

    Attributes:
        name: ``'Type 1'`` or ``'Type 2'``.
        range_min: distribution of the minimum visibility distance, metres.
        range_max: distribution of the maximum visibility distance, metres.
        angular_range_deg: distribution of the thesis's angular range, degrees.
        density_per_m: features per metre of wall (calibrated, see module docstring).
        angle_is_half_aperture: read ``angular_range_deg`` as the cone's half-angle
            instead of its full aperture (not the default; see module docstring).
    """

    name: str
    range_min: Mixture
    range_max: Mixture
    angular_range_deg: Mixture
    density_per_m: float
    angle_is_half_aperture: bool = False


@dataclass(frozen=True)
class ShapeClass:
    """Shape parameters of the perimeter and the obstacles.

    Attributes:
        name: ``'rectangular'`` or ``'irregular'``.
        perimeter_sides: side-count mixture (ignored for rectangular worlds).
        obstacle_count: obstacle-count mixture.
        obstacle_sides: obstacle side-count mixture (ignored for rectangular worlds).
        size_m: rectangle side length (rectangular) or vertex radius (irregular)
            distribution, metres.
        obstacle_radius_m: obstacle vertex radius (half-diagonal) range, metres.
        clearance: minimum gap between any two polygons, metres.
    """

    name: str
    perimeter_sides: Mixture
    obstacle_count: Mixture
    obstacle_sides: Mixture
    size_m: Mixture
    obstacle_radius_m: tuple[float, float] = (1.0, 3.0)
    clearance: float = 1.0

    @property
    def rectangular(self) -> bool:
        """Whether perimeter and obstacles are axis-aligned rectangles."""
        return self.name == 'rectangular'


@dataclass(frozen=True)
class WorldSetting:
    """One of the experiment's settings: a shape class and a feature type.

    Attributes:
        number: the setting's number in Section 8.2 (0 for custom settings).
        shape: the shape class.
        features: the feature type.
        label: a short description for reports.
    """

    number: int
    shape: ShapeClass
    features: FeatureType
    label: str


_IRREGULAR_SIDES = Mixture((('U', 4, 4, 0.1), ('N', 5, 0.5, 0.45), ('N', 7, 2, 0.45)))

RECTANGULAR = ShapeClass(
    name='rectangular',
    perimeter_sides=Mixture((('U', 4, 4, 1.0),)),
    obstacle_count=Mixture((('U', 6, 9, 0.5), ('N', 10, 2, 0.5))),
    obstacle_sides=Mixture((('U', 4, 4, 1.0),)),
    size_m=_normal(40.0, 3.0),
)
IRREGULAR = ShapeClass(
    name='irregular',
    perimeter_sides=_IRREGULAR_SIDES,
    obstacle_count=Mixture((('U', 5, 9, 0.5), ('N', 8, 2, 0.5))),
    obstacle_sides=_IRREGULAR_SIDES,
    size_m=_normal(22.5, 1.5),
)

# Densities (features per metre of wall) calibrated with
# ``vbn bench-decomposition --calibrate`` so that the mean count of features visible
# per pose matches Table 8.4; the measured means are in docs/simulator.md.
_DENSITY = {1: 6.8, 2: 7.0, 3: 8.3, 4: 7.9}


def _type1(density: float) -> FeatureType:
    return FeatureType('Type 1', _normal(0.65, 0.2), _normal(12.5, 1.0), _normal(25.0, 3.0),
                       density)


def _type2(density: float) -> FeatureType:
    return FeatureType('Type 2', _normal(0.65, 0.2), _normal(17.5, 2.0), _normal(45.0, 4.0),
                       density)


SETTINGS: dict[int, WorldSetting] = {
    1: WorldSetting(1, RECTANGULAR, _type1(_DENSITY[1]), 'rectangular, Type 1 features'),
    2: WorldSetting(2, RECTANGULAR, _type2(_DENSITY[2]), 'rectangular, Type 2 features'),
    3: WorldSetting(3, IRREGULAR, _type1(_DENSITY[3]), 'irregular, Type 1 features'),
    4: WorldSetting(4, IRREGULAR, _type2(_DENSITY[4]), 'irregular, Type 2 features'),
}


def get_setting(number: int) -> WorldSetting:
    """Return setting 1, 2, 3 or 4.

    Raises:
        WorldsError: for any other number.
    """
    if number not in SETTINGS:
        raise WorldsError(f'setting must be 1, 2, 3 or 4, got {number!r}')
    return SETTINGS[number]


def small_setting(setting: WorldSetting, scale: float = 0.25,
                  density_scale: float | None = None) -> WorldSetting:
    """Return a reduced-size variant of ``setting``, small enough for the exact solver.

    The world's size and obstacle count are scaled by ``scale`` (0.25 gives worlds
    about 10 m across with one or two obstacles); obstacle sizes and clearances by
    ``2 x scale`` (at least 0.5 m, so the 0.5 m grid still passes between them);
    feature ranges by ``2 x scale``; the feature density by ``density_scale``
    (default 0.5 for Type 1 and 0.25 for Type 2 features), which gives about 11-19
    features visible per pose, few enough k-subsets for the exact set cover.

    Args:
        setting: the full-size setting.
        scale: linear scale factor in ``(0, 1]``.
        density_scale: factor on the feature density, or None for the default.

    Returns:
        A new setting with the same ``number`` and a label marked as small.

    Raises:
        WorldsError: if ``scale`` is out of range.
    """
    if not 0 < scale <= 1:
        raise WorldsError(f'scale must be in (0, 1], got {scale}')
    if density_scale is None:
        density_scale = 0.5 if setting.features.name == 'Type 1' else 0.25

    def scaled(mixture: Mixture, factor: float) -> Mixture:
        return Mixture(tuple((kind, a * factor, b * factor, w)
                             for kind, a, b, w in mixture.components))

    shape = setting.shape
    rmin, rmax = shape.obstacle_radius_m
    small_shape = replace(
        shape,
        size_m=scaled(shape.size_m, scale),
        obstacle_count=scaled(shape.obstacle_count, scale),
        obstacle_radius_m=(max(0.5, rmin * scale * 2), max(0.75, rmax * scale * 2)),
        clearance=max(0.5, shape.clearance * scale * 2),
    )
    features = setting.features
    small_features = replace(
        features,
        range_max=scaled(features.range_max, scale * 2),
        density_per_m=features.density_per_m * density_scale,
    )
    return WorldSetting(setting.number, small_shape, small_features,
                        f'small ({scale:g}x) {setting.label}')

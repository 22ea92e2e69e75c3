"""Decompositions: regions with their landmarks, and the fixed decomposition JSON.

Decomposition JSON (fixed; other tools depend on it)::

    {
      "algorithm": "B2", "k": 4, "rho": 1, "sigma": 9, "seconds": 0.21,
      "regions": [{"poses": [pose indices], "features": [the k landmark feature ids]}],
      "uncovered": [k-coverable pose indices left uncovered],
      "lower_bound": 31   (optional: no complete decomposition has fewer regions)
    }
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math
from pathlib import Path
from typing import Any

import numpy as np

from landmark_db.errors import LandmarkDbError
from vbn_common.jsonio import read_json_file, write_json_atomic

__all__ = ['Decomposition', 'Region', 'load_decomposition', 'save_decomposition']


@dataclass(eq=False)
class Region:
    """One region of a decomposition (Definition 3.4) and its landmark.

    Attributes:
        poses: sorted unique int64 pose indices of the region.
        features: the region's landmark: k feature ids (not column indices) seen from
            every pose of the region.
    """

    poses: np.ndarray
    features: np.ndarray

    def __post_init__(self) -> None:
        self.poses = np.asarray(self.poses, dtype=np.int64).reshape(-1)
        self.features = np.asarray(self.features, dtype=np.int64).reshape(-1)

    def __len__(self) -> int:
        return int(self.poses.size)


@dataclass(eq=False)
class Decomposition:
    """The output of a decomposition algorithm.

    Attributes:
        algorithm: algorithm name (one of ``ALGORITHMS``).
        k: features per landmark.
        rho: required overlap (graph distance).
        sigma: largest count of otherwise-uncovered poses for which no region is added.
        seconds: wall-clock time the algorithm took, including the rho reduction.
        regions: the regions, in the order the algorithm kept them.
        uncovered: sorted pose indices of k-coverable poses (judged on the
            rho-reduced visibility sets) that no region covers with its whole
            rho-neighbourhood.
        lower_bound: a certified lower bound on the regions of any complete
            decomposition of the same world, k and rho (:mod:`.bound`), when one was
            computed (``best`` at sigma = 0 does); JSON key ``lower_bound``, optional.
    """

    algorithm: str
    k: int
    rho: int
    sigma: int
    seconds: float
    regions: list[Region] = field(default_factory=list)
    uncovered: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    lower_bound: int | None = None

    def __post_init__(self) -> None:
        self.uncovered = np.asarray(self.uncovered, dtype=np.int64).reshape(-1)

    def to_dict(self) -> dict[str, Any]:
        """Return the decomposition JSON structure."""
        data = {
            'algorithm': self.algorithm,
            'k': int(self.k),
            'rho': int(self.rho),
            'sigma': int(self.sigma),
            'seconds': float(self.seconds),
            'regions': [{'poses': r.poses.tolist(), 'features': r.features.tolist()}
                        for r in self.regions],
            'uncovered': self.uncovered.tolist(),
        }
        if self.lower_bound is not None:
            data['lower_bound'] = int(self.lower_bound)
        return data

    @staticmethod
    def from_dict(data: Any) -> Decomposition:
        """Parse the decomposition JSON structure.

        Raises:
            LandmarkDbError: naming the first missing or malformed field.
        """
        if not isinstance(data, dict):
            raise LandmarkDbError('decomposition must be a JSON object')
        for key in ('algorithm', 'k', 'rho', 'sigma', 'regions', 'uncovered'):
            if key not in data:
                raise LandmarkDbError(f"decomposition has no '{key}'")
        if not isinstance(data['algorithm'], str):
            raise LandmarkDbError("decomposition 'algorithm' must be a string")
        ints = {}
        for key in ('k', 'rho', 'sigma'):
            value = data[key]
            if isinstance(value, bool) or not isinstance(value, int):
                raise LandmarkDbError(f"decomposition '{key}' must be an integer, got {value!r}")
            ints[key] = value
        seconds = data.get('seconds', 0.0)
        if (isinstance(seconds, bool) or not isinstance(seconds, (int, float))
                or not math.isfinite(seconds)):
            raise LandmarkDbError(f"decomposition 'seconds' must be a number, got {seconds!r}")
        if not isinstance(data['regions'], list):
            raise LandmarkDbError("decomposition 'regions' must be a list")
        regions = []
        for i, raw in enumerate(data['regions']):
            if not isinstance(raw, dict) or 'poses' not in raw or 'features' not in raw:
                raise LandmarkDbError(f"regions[{i}] must be an object with 'poses' and "
                                      f"'features'")
            regions.append(Region(_int_list(raw['poses'], f'regions[{i}].poses'),
                                  _int_list(raw['features'], f'regions[{i}].features')))
        uncovered = _int_list(data['uncovered'], 'uncovered')
        bound = data.get('lower_bound')
        if bound is not None and (isinstance(bound, bool) or not isinstance(bound, int)
                                  or bound < 0):
            raise LandmarkDbError(f"decomposition 'lower_bound' must be a non-negative "
                                  f'integer, got {bound!r}')
        return Decomposition(data['algorithm'], ints['k'], ints['rho'], ints['sigma'],
                             float(seconds), regions, uncovered, bound)


def load_decomposition(path: str | Path) -> Decomposition:
    """Read a decomposition JSON file.

    Raises:
        LandmarkDbError: if the file is missing, not JSON, or malformed.
    """
    return read_json_file(path, Decomposition.from_dict, LandmarkDbError)


def save_decomposition(decomposition: Decomposition, path: str | Path) -> None:
    """Write a decomposition as JSON, atomically (temporary file, then rename)."""
    write_json_atomic(decomposition.to_dict(), path)


def _int_list(raw: Any, name: str) -> np.ndarray:
    if not isinstance(raw, list) or any(
            isinstance(x, bool) or not isinstance(x, int) for x in raw):
        raise LandmarkDbError(f'{name} must be a list of integers')
    if any(x < 0 or x >= 2**63 for x in raw):
        raise LandmarkDbError(f'{name} holds a negative or too large integer')
    return np.asarray(raw, dtype=np.int64).reshape(-1)

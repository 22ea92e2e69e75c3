"""The batched robust estimation loop shared by the two-view solvers (thesis 7.3 to 7.5).

One MSAC loop (RANSAC scored by a truncated sum of squared errors, Torr and Zisserman
2000) for every solver that fits a model to minimal samples: the pinhole planar
essential matrix (7.5.1), the general essential matrix (7.4) and the linear
combination of views (7.3). Samples are drawn in batches of :data:`RANSAC_BATCH`, each
batch's models solved and scored in one vectorised pass; the loop stops when an
all-inlier sample was drawn with the requested confidence or after ``max_iterations``
samples. An optional ``polish`` refines each new best model (LO-RANSAC,
:func:`optimise_locally` for essential matrices). The panoramic solver of 7.5.2 has no
minimal samples to draw (every pair of correspondences proposes its candidates) and
scores its candidates with the same truncated errors.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
import math
from typing import Any

import numpy as np

from vbn_common.geometry.epipolar import sampson

__all__ = ['RANSAC_BATCH', 'MsacResult', 'iterations_needed', 'msac', 'msac_loop',
           'optimise_locally', 'sample_indices', 'truncated_scores']

#: Minimal samples drawn and solved per batch.
RANSAC_BATCH = 64


@dataclass(frozen=True)
class MsacResult:
    """The best model of an MSAC loop.

    Attributes:
        model: the best model (``None`` when no sample gave one).
        score: its truncated sum of squared errors (``inf`` without a model).
        inliers: ``(n,)`` bool, the data within the threshold of the model.
    """

    model: Any
    score: float
    inliers: np.ndarray


def sample_indices(rng: np.random.Generator, n: int, size: int, count: int) -> np.ndarray:
    """Return ``(count, size)`` random samples of distinct indices below ``n``."""
    return np.argpartition(rng.random((count, n)), size - 1, axis=1)[:, :size]


def iterations_needed(inlier_ratio: float, size: int, confidence: float) -> float:
    """Return how many samples find an all-inlier one with probability ``confidence``."""
    good = inlier_ratio ** size
    if good >= 1.0:
        return 0.0
    if good <= 0.0:
        return math.inf
    return math.log(1.0 - confidence) / math.log(1.0 - good)


def truncated_scores(errors: np.ndarray, threshold: float) -> np.ndarray:
    """Return the MSAC score of each row of ``errors``: ``sum min(e^2, threshold^2)``."""
    return np.sum(np.minimum(errors * errors, threshold * threshold), axis=-1)


def msac_loop(n: int, size: int,
              hypotheses: Callable[[np.ndarray], tuple[Any, np.ndarray]],
              threshold: float, *, max_iterations: int, confidence: float,
              rng: np.random.Generator,
              residuals: Callable[[Any], np.ndarray] | None = None,
              polish: Callable[[Any, float], tuple[Any, float]] | None = None) -> MsacResult:
    """Run batched MSAC over ``n`` data with minimal samples of ``size``.

    Args:
        n: number of data (correspondences), ``n >= size``.
        size: minimal sample size.
        hypotheses: ``samples (m, size) -> (models, errors)``: the models of a batch of
            samples (indexable, ``len(models) == len(errors)``; fewer than ``m`` when
            some samples are degenerate) and their ``(len(models), n)`` errors on all
            data.
        threshold: inlier threshold on the errors.
        max_iterations: samples at most.
        confidence: stop once an all-inlier sample was drawn with this probability.
        rng: the random generator that draws the samples.
        residuals: ``model -> (n,)`` errors; with ``polish``, the polished model's
            inliers come from it.
        polish: ``(model, score) -> (model, score)`` applied to each new best model.

    Returns:
        The best model, its score and its inliers. With ``n == size`` the one sample is
        all data.
    """
    best = MsacResult(None, math.inf, np.zeros(n, dtype=bool))
    needed, drawn = float(max_iterations), 0
    while drawn < min(needed, max_iterations):
        count = min(RANSAC_BATCH, max_iterations - drawn)
        samples = sample_indices(rng, n, size, count) if n > size else np.arange(size)[None]
        models, errors = hypotheses(samples)
        if len(errors):
            scores = truncated_scores(errors, threshold)
            i = int(np.argmin(scores))
            if scores[i] < best.score:
                model, score = models[i], float(scores[i])
                if polish is not None:
                    model, score = polish(model, score)
                    inliers = np.abs(residuals(model)) < threshold
                else:
                    inliers = np.abs(errors[i]) < threshold
                best = MsacResult(model, score, inliers)
                needed = iterations_needed(float(np.mean(inliers)), size, confidence)
        drawn += count
        if n == size:
            break
    return best


def msac(E: np.ndarray, f1: np.ndarray, f2: np.ndarray,
         threshold: float) -> tuple[float, np.ndarray]:
    """Return the MSAC score and the inliers of an essential matrix by Sampson errors."""
    err = sampson(E, f1, f2)
    return float(np.sum(np.minimum(err * err, threshold * threshold))), np.abs(err) < threshold


def optimise_locally(E: np.ndarray, score: float, f1: np.ndarray, f2: np.ndarray,
                     threshold: float, fit, minimum: int) -> tuple[np.ndarray, float]:
    """LO-RANSAC: refit a new best hypothesis on its inliers while the score drops.

    A minimal sample's model is noisy and, with a short baseline, finds few of the
    inliers at the final threshold; least squares on the points within a wider
    threshold, shrinking to the final one, recovers them (iterative local
    optimisation, Chum, Matas and Kittler 2003).
    """
    for factor in (4.0, 3.0, 2.0, 1.5, 1.0, 1.0):
        inliers = np.abs(sampson(E, f1, f2)) < factor * threshold
        if inliers.sum() < minimum:
            continue
        candidate = fit(f1[inliers], f2[inliers])
        new_score, _ = msac(candidate, f1, f2, threshold)
        if new_score < score:
            E, score = candidate, new_score
    return E, score



"""The one MSAC loop of the two-view solvers, on a problem checkable by hand."""
from __future__ import annotations

import math

import numpy as np

from vbn_common.geometry.ransac import (
    RANSAC_BATCH,
    iterations_needed,
    msac_loop,
    sample_indices,
    truncated_scores,
)


def test_iterations_needed_matches_the_formula():
    # half inliers, samples of 4, 99 %: log(0.01) / log(1 - 1/16) = 71.36 samples
    assert math.isclose(iterations_needed(0.5, 4, 0.99), math.log(0.01) / math.log(15 / 16))
    assert iterations_needed(1.0, 4, 0.99) == 0.0
    assert iterations_needed(0.0, 4, 0.99) == math.inf


def test_truncated_scores_cap_each_error_at_the_threshold():
    errors = np.array([[0.0, 1.0, 5.0], [0.5, 0.5, 0.5]])
    assert np.allclose(truncated_scores(errors, 2.0), [0 + 1 + 4, 0.75])


def test_samples_are_distinct_indices():
    samples = sample_indices(np.random.default_rng(0), 10, 4, 50)
    assert samples.shape == (50, 4)
    assert all(len(set(row)) == 4 for row in samples)
    assert samples.min() >= 0 and samples.max() < 10


def _line_hypotheses(x, y):
    """Lines through pairs of points: models (slope, intercept), errors on all points."""
    def hypotheses(samples):
        a, b = samples[:, 0], samples[:, 1]
        ok = x[a] != x[b]
        slope = (y[b] - y[a])[ok] / (x[b] - x[a])[ok]
        intercept = y[a][ok] - slope * x[a][ok]
        models = np.stack([slope, intercept], axis=1)
        return models, y[None, :] - (slope[:, None] * x[None, :] + intercept[:, None])
    return hypotheses


def test_msac_finds_the_line_among_outliers():
    rng = np.random.default_rng(3)
    x = np.linspace(0, 10, 60)
    y = 2.0 * x - 1.0
    outliers = rng.random(60) < 0.4
    y[outliers] += rng.uniform(5, 20, outliers.sum())
    best = msac_loop(60, 2, _line_hypotheses(x, y), 0.01, max_iterations=1000,
                     confidence=0.999, rng=np.random.default_rng(0))
    assert np.allclose(best.model, [2.0, -1.0])
    assert np.array_equal(best.inliers, ~outliers)


def test_msac_stops_early_when_the_data_are_clean():
    x = np.linspace(0, 1, 20)
    calls = []

    def hypotheses(samples):
        calls.append(len(samples))
        return _line_hypotheses(x, 3 * x)(samples)

    msac_loop(20, 2, hypotheses, 1e-6, max_iterations=10_000, confidence=0.99,
              rng=np.random.default_rng(1))
    assert calls == [RANSAC_BATCH]      # all inliers: one batch is enough


def test_polish_and_residuals_decide_the_inliers():
    x = np.linspace(0, 1, 10)
    y = x.copy()
    y[0] = 5.0

    def polish(model, score):
        return np.array([1.0, 0.0]), 0.0           # the exact line

    best = msac_loop(10, 2, _line_hypotheses(x, y), 1e-9, max_iterations=64,
                     confidence=0.99, rng=np.random.default_rng(2),
                     residuals=lambda m: y - (m[0] * x + m[1]), polish=polish)
    assert np.allclose(best.model, [1.0, 0.0]) and best.score == 0.0
    assert best.inliers.tolist() == [False] + [True] * 9


def test_all_degenerate_samples_give_no_model():
    x = np.zeros(5)
    best = msac_loop(5, 2, _line_hypotheses(x, x), 0.1, max_iterations=128,
                     confidence=0.99, rng=np.random.default_rng(0))
    assert best.model is None and best.score == math.inf and not best.inliers.any()

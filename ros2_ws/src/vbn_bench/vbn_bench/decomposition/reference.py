"""The thesis's published results for the synthetic experiment (Section 8.2).

REFERENCE DATA copied from the thesis, not computed here: Table 8.2 (mean number of
regions per decomposition), Table 8.3 (mean number of poses per region) and Table
8.4 (mean number of features visible from a pose), each an average over 300 random
worlds per setting with k = 4, rho = 1, sigma = 9 and alpha = 0.85.
"""
from __future__ import annotations

from landmark_db.defaults import THESIS

__all__ = ['THESIS_ALGORITHMS', 'THESIS_PARAMETERS', 'THESIS_TABLE_8_2', 'THESIS_TABLE_8_3',
           'THESIS_TABLE_8_4', 'THESIS_WORLDS_PER_SETTING']

THESIS_ALGORITHMS = ('A1', 'A2', 'A3', 'B1', 'B2', 'C')
THESIS_PARAMETERS = {'k': THESIS.k, 'rho': THESIS.rho, 'sigma': THESIS.sigma,
                     'alpha': THESIS.alpha}
THESIS_WORLDS_PER_SETTING = 300

# Table 8.2: average number of regions in a decomposition.
THESIS_TABLE_8_2: dict[int, dict[str, float]] = {
    1: {'A1': 173.81, 'A2': 156.96, 'A3': 154.97, 'B1': 127.76, 'B2': 112.63, 'C': 140.10},
    2: {'A1': 59.30, 'A2': 56.45, 'A3': 54.72, 'B1': 44.74, 'B2': 42.10, 'C': 44.17},
    3: {'A1': 112.40, 'A2': 100.46, 'A3': 98.97, 'B1': 82.11, 'B2': 73.08, 'C': 82.29},
    4: {'A1': 44.71, 'A2': 40.00, 'A3': 39.11, 'B1': 31.99, 'B2': 30.02, 'C': 31.11},
}

# Table 8.3: average number of poses per region.
THESIS_TABLE_8_3: dict[int, dict[str, float]] = {
    1: {'A1': 70.76, 'A2': 76.49, 'A3': 75.74, 'B1': 80.60, 'B2': 80.99, 'C': 71.85},
    2: {'A1': 253.88, 'A2': 276.37, 'A3': 272.83, 'B1': 281.63, 'B2': 279.81, 'C': 251.86},
    3: {'A1': 69.04, 'A2': 74.60, 'A3': 73.95, 'B1': 78.63, 'B2': 79.29, 'C': 71.61},
    4: {'A1': 215.15, 'A2': 237.68, 'A3': 234.67, 'B1': 244.44, 'B2': 241.26, 'C': 218.56},
}

# Table 8.4: average number of features visible from a pose.
THESIS_TABLE_8_4: dict[int, float] = {1: 30, 2: 95, 3: 41, 4: 117}

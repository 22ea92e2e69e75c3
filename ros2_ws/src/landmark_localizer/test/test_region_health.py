"""Per-region landmark failures: which regions the changed world broke."""
from __future__ import annotations

import numpy as np
import pytest

from landmark_localizer.health import RegionHealth


def test_a_feature_missed_every_time_fails_and_its_region_goes_stale() -> None:
    health = RegionHealth(min_misses=5, failing_share=0.8, stale_share=0.25)
    landmark = np.arange(8)
    for _ in range(6):
        health.observe(3, landmark, found=np.arange(2, 8), missed=np.array([0, 1, 42]))
    assert health.failing(3).tolist() == [0, 1]            # class 42 is no landmark
    assert health.stale_regions() == [3]
    assert health.summary()[3] == {'landmark': 8, 'failing': 2, 'found': 36, 'missed': 12}


def test_passing_occlusions_and_sparse_evidence_do_not_make_a_region_stale() -> None:
    health = RegionHealth(min_misses=5, failing_share=0.8, stale_share=0.25)
    landmark = np.arange(8)
    for frame in range(40):     # a person hides features 0 and 1 for 8 of 40 frames
        hidden = np.array([0, 1]) if 10 <= frame < 18 else np.zeros(0, np.int64)
        health.observe(0, landmark, found=np.setdiff1d(landmark, hidden), missed=hidden)
    for _ in range(4):          # four misses are not yet evidence
        health.observe(1, landmark, missed=landmark)
    for _ in range(6):          # one failing feature of eight: below a quarter
        health.observe(2, landmark, found=landmark[1:], missed=landmark[:1])
    assert health.failing(0).size == 0 and health.failing(1).size == 0
    assert health.failing(2).tolist() == [0]
    assert health.stale_regions() == []
    assert health.failing(99).size == 0


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ValueError, match='region health'):
        RegionHealth(min_misses=0)

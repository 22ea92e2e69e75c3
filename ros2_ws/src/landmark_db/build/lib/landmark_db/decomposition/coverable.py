"""k-coverable poses (Section 5.1).

Real visibility data has poses that see fewer than k features (near walls, far from
everything). Only the k-coverable poses, |F_v| >= k, are decomposed. Under rho > 0
the test is made on the reduced sets F~_v of Theorem 4.1, since those are the sets the
0-MORDP instance decomposes.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ['coverable_poses']


def coverable_poses(visible: sp.csr_matrix, k: int) -> np.ndarray:
    """Return ``(n,)`` bool: the poses that see at least ``k`` features.

    Args:
        visible: ``(n, f)`` bool CSR visibility (original or reduced).
        k: landmark size.

    Example:
        >>> import scipy.sparse as sp
        >>> coverable_poses(sp.csr_matrix([[1, 1, 0], [0, 1, 0]], dtype=bool), 2).tolist()
        [True, False]
    """
    return np.diff(visible.indptr) >= k

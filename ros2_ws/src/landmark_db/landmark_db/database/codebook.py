"""Compact SIFT descriptors: a product quantizer trained on the database's own descriptors.

Beyond the thesis (a database at most a third of a structure-based peer's
compact map). The thesis stores each representative descriptor whole (Section 6.2.1:
128 bytes); most of a database file is descriptors: the classes', the model views'
(Section 7.2) and the scene points'. A product quantizer (Jégou, Douze and Schmid,
"Product quantization for nearest neighbor search", IEEE TPAMI 2011) cuts a descriptor
into ``m`` sub-vectors of ``128 / m`` values and stores, for each, the index (one byte)
of its nearest of 256 centroids learnt by k-means on that sub-vector over the
database's descriptors. A database of ``n`` descriptors then holds ``m`` bytes for each
and one codebook of ``m * 256 * 128 / m = 32,768`` bytes, whatever ``m``.

The localizer never sees codes: :meth:`DescriptorCodebook.decode` turns them back into
uint8 descriptors when the file is read, and the builder replaces its descriptors by
their decoded codes before writing (:meth:`~landmark_db.database.model.LandmarkDatabase.
quantized`), so the database in memory after a build equals the one read back.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from landmark_db.database.fields import DESCRIPTOR_SIZE, ArrayEquality, read_only, set_field
from landmark_db.errors import LandmarkDbError

__all__ = ['CENTROIDS', 'CODE_SIZES', 'DescriptorCodebook', 'train_codebook']

CENTROIDS = 256
"""Centroids per sub-vector: one byte of code each."""

CODE_SIZES = (8, 16, 32, 64)
"""Bytes a quantized descriptor may take (sub-vectors of 16, 8, 4 or 2 values)."""

_CHUNK = 32768  # descriptors encoded per block (a (block, 256) distance table each)


@dataclass(frozen=True, eq=False)
class DescriptorCodebook(ArrayEquality):
    """A product quantizer of 128-value uint8 descriptors.

    Attributes:
        centroids: ``(m, 256, 128 // m)`` uint8; ``centroids[j, c]`` is centroid ``c``
            of sub-vector ``j`` (values ``j * 128 // m`` to ``(j + 1) * 128 // m - 1``).
        rms_error: the root mean square distance between the descriptors it coded and
            their codes' (SIFT units), 0 when unknown. A distance between a fresh
            descriptor and a stored one is about ``sqrt(d**2 + rms_error**2)`` for the
            original distance ``d`` (the coding error is nearly orthogonal to the
            difference), so matchers that judge distances subtract it
            (:meth:`true_distances`).
    """

    centroids: np.ndarray
    rms_error: float = 0.0

    def __post_init__(self) -> None:
        centroids = np.asarray(self.centroids)
        if centroids.dtype != np.uint8 or centroids.ndim != 3 \
                or centroids.shape[0] not in CODE_SIZES \
                or centroids.shape[1:] != (CENTROIDS, DESCRIPTOR_SIZE // centroids.shape[0]):
            raise LandmarkDbError(
                f'a descriptor codebook is (m, {CENTROIDS}, {DESCRIPTOR_SIZE} / m) uint8 '
                f'with m in {CODE_SIZES}, got {centroids.dtype} {centroids.shape}')
        set_field(self, 'centroids', read_only(np.array(centroids)))
        error = self.rms_error
        if isinstance(error, bool) or not isinstance(error, (int, float, np.floating)) or \
                not np.isfinite(error) or error < 0:
            raise LandmarkDbError(f'a codebook rms_error is a finite number >= 0, got {error!r}')
        set_field(self, 'rms_error', float(error))

    @property
    def code_size(self) -> int:
        """Bytes of one descriptor's code (``m``)."""
        return int(self.centroids.shape[0])

    def encode(self, descriptors: np.ndarray) -> np.ndarray:
        """Return the ``(n, m)`` uint8 codes of ``(n, 128)`` descriptors (nearest centroids)."""
        x = np.asarray(descriptors)
        if x.ndim != 2 or x.shape[1] != DESCRIPTOR_SIZE:
            raise LandmarkDbError(f'descriptors to encode must be (n, {DESCRIPTOR_SIZE}), '
                                  f'got {x.shape}')
        m, _, d = self.centroids.shape
        cents = self.centroids.astype(np.float32)
        norms = np.einsum('jcd,jcd->jc', cents, cents)
        codes = np.empty((len(x), m), np.uint8)
        for start in range(0, len(x), _CHUNK):
            block = x[start:start + _CHUNK].astype(np.float32).reshape(-1, m, d)
            for j in range(m):
                # |x - c|^2 - |x|^2: the same order of centroids for each row.
                scores = norms[j][None, :] - 2.0 * block[:, j, :] @ cents[j].T
                codes[start:start + len(block), j] = np.argmin(scores, axis=1)
        return codes

    def decode(self, codes: np.ndarray) -> np.ndarray:
        """Return the ``(n, 128)`` uint8 descriptors of ``(n, m)`` codes."""
        codes = np.asarray(codes)
        m = self.code_size
        if codes.ndim != 2 or codes.shape[1] != m or codes.dtype != np.uint8:
            raise LandmarkDbError(f'descriptor codes must be (n, {m}) uint8, got '
                                  f'{codes.dtype} {codes.shape}')
        parts = self.centroids[np.arange(m)[None, :], codes]  # (n, m, 128 / m)
        return parts.reshape(len(codes), DESCRIPTOR_SIZE)

    def quantize(self, descriptors: np.ndarray) -> np.ndarray:
        """Return the descriptors as stored: decoded from their codes."""
        return self.decode(self.encode(descriptors))

    def true_distances(self, distances: np.ndarray) -> np.ndarray:
        """Estimate the original distances behind distances to coded descriptors.

        ``sqrt(max(d**2 - rms_error**2, 0))``: unbiased for the squared distance, so a
        ratio test or a distance limit judges as it would have on whole descriptors.
        """
        d = np.asarray(distances, np.float64)
        return np.sqrt(np.maximum(d * d - self.rms_error ** 2, 0.0))


def train_codebook(descriptors: np.ndarray, code_size: int, rng: np.random.Generator,
                   *, samples: int = 16384, iterations: int = 12) -> DescriptorCodebook:
    """Learn a product quantizer from descriptors (k-means++ then Lloyd, per sub-vector).

    Args:
        descriptors: ``(n, 128)`` uint8 (at least one).
        code_size: bytes per code, one of :data:`CODE_SIZES`.
        rng: the seeded generator (the sample and the k-means++ seeds).
        samples: at most this many descriptors, drawn without replacement, train it.
        iterations: Lloyd iterations after the seeding.

    Returns:
        The codebook, with its RMS error over the descriptors that trained it (a few
        SIFT units below the error on others: :func:`~.compact.compact_database`
        measures it on the whole database); with at most 256
        distinct sub-vectors in a column, each is its own centroid, and the codes are
        exact.

    Raises:
        LandmarkDbError: no descriptor, or a code size not in :data:`CODE_SIZES`.
    """
    x = np.asarray(descriptors)
    if x.ndim != 2 or x.shape[1] != DESCRIPTOR_SIZE or len(x) == 0:
        raise LandmarkDbError(f'a codebook needs (n >= 1, {DESCRIPTOR_SIZE}) descriptors, '
                              f'got {x.shape}')
    if code_size not in CODE_SIZES:
        raise LandmarkDbError(f'a descriptor code takes one of {CODE_SIZES} bytes, '
                              f'got {code_size!r}')
    if len(x) > samples:
        x = x[np.sort(rng.choice(len(x), samples, replace=False))]
    d = DESCRIPTOR_SIZE // code_size
    centroids = np.empty((code_size, CENTROIDS, d), np.uint8)
    for j in range(code_size):
        centroids[j] = _kmeans(x[:, j * d:(j + 1) * d], rng, iterations)
    change = DescriptorCodebook(centroids).quantize(x).astype(np.float64) - x
    return DescriptorCodebook(centroids, float(np.sqrt(np.mean(np.sum(change ** 2, axis=1)))))


def _kmeans(sub: np.ndarray, rng: np.random.Generator, iterations: int) -> np.ndarray:
    """``(256, d)`` uint8 centroids of one sub-vector's values."""
    distinct, counts = np.unique(sub, axis=0, return_counts=True)
    if len(distinct) <= CENTROIDS:  # exact: every value its own centroid
        return np.concatenate([distinct, np.repeat(distinct[:1], CENTROIDS - len(distinct),
                                                   axis=0)]).astype(np.uint8)
    # Distinct values weighted by their count: the same k-means, on fewer rows.
    x = distinct.astype(np.float32)
    w = counts.astype(np.float64)
    centres = np.empty((CENTROIDS, x.shape[1]), np.float32)
    centres[0] = x[rng.choice(len(x), p=w / w.sum())]
    nearest = ((x - centres[0]) ** 2).sum(axis=1)
    for c in range(1, CENTROIDS):  # k-means++ seeding
        p = w * nearest
        centres[c] = x[rng.choice(len(x), p=p / p.sum())] if p.sum() > 0 else x[0]
        nearest = np.minimum(nearest, ((x - centres[c]) ** 2).sum(axis=1))
    for _ in range(iterations):
        scores = (centres * centres).sum(axis=1)[None, :] - 2.0 * x @ centres.T
        label = np.argmin(scores, axis=1)
        mass = np.bincount(label, weights=w, minlength=CENTROIDS)
        used = mass > 0
        for k in range(x.shape[1]):
            centres[used, k] = (np.bincount(label, weights=w * x[:, k],
                                            minlength=CENTROIDS)[used] / mass[used])
    return np.clip(np.rint(centres), 0, 255).astype(np.uint8)

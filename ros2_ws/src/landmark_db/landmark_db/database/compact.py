"""A database in the fewest bytes its file needs (schema 5; beyond the thesis).

:func:`compact_database` is the builder's last step before writing, and
``vbn db-update``'s: every descriptor replaced by its product-quantizer code's
(:mod:`.codebook`), trained on the database's own descriptors or reused from the
database being updated, and the scene points rounded and their patches coded as JPEG
(:meth:`~landmark_db.database.points.ScenePoints.compact`). The result equals what the
file gives back when read.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from landmark_db.database.codebook import CODE_SIZES, DescriptorCodebook, train_codebook
from landmark_db.database.fields import DESCRIPTOR_SIZE
from landmark_db.database.model import LandmarkDatabase
from landmark_db.errors import LandmarkDbError

__all__ = ['Compaction', 'compact_database']


@dataclass(frozen=True)
class Compaction:
    """What :func:`compact_database` did.

    Attributes:
        code_bytes: bytes of a stored descriptor (128: whole).
        descriptors: descriptors in the database.
        rms_change: root mean square over descriptors of the distance between each
            descriptor and its code's (SIFT units; a descriptor's norm is about 512).
        coded_patches: patches coded as JPEG (0: kept whole, or none).
    """

    code_bytes: int
    descriptors: int
    rms_change: float
    coded_patches: int

    def to_dict(self) -> dict[str, float | int]:
        """Return the figures for a build report."""
        return {'descriptor_bytes': self.code_bytes, 'descriptors': self.descriptors,
                'descriptor_rms_change': round(self.rms_change, 2),
                'coded_patches': self.coded_patches}


def compact_database(db: LandmarkDatabase, code_bytes: int, patch_quality: int,
                     rng: np.random.Generator,
                     codebook: DescriptorCodebook | None = None
                     ) -> tuple[LandmarkDatabase, Compaction]:
    """Return ``db`` as the file will hold it, and what changed.

    Args:
        db: the database (whole descriptors, or already quantized with ``codebook``).
        code_bytes: bytes per stored descriptor, one of
            :data:`~landmark_db.database.codebook.CODE_SIZES`, or 128 for whole ones.
        patch_quality: JPEG quality of the scene points' patches, 1 to 100, or 0 to
            keep them whole.
        rng: the generator that draws the codebook's training sample and seeds.
        codebook: reuse this codebook (a database update: the regions kept keep their
            codes) instead of training one; its code size must be ``code_bytes``.

    Raises:
        LandmarkDbError: a code size or quality out of range, or a codebook of another
            code size.
    """
    if code_bytes != DESCRIPTOR_SIZE and code_bytes not in CODE_SIZES:
        raise LandmarkDbError(f'descriptor_bytes must be one of {CODE_SIZES} or '
                              f'{DESCRIPTOR_SIZE} (whole), got {code_bytes!r}')
    if isinstance(patch_quality, bool) or not isinstance(patch_quality, (int, np.integer)) \
            or not 0 <= patch_quality <= 100:
        raise LandmarkDbError(f'patch quality must be an integer 0..100 (0: whole), got '
                              f'{patch_quality!r}')
    before = np.concatenate(db.descriptor_arrays())
    trained = codebook is None and code_bytes != DESCRIPTOR_SIZE
    if code_bytes == DESCRIPTOR_SIZE:
        out = db.quantized(None)
    else:
        if trained:
            codebook = train_codebook(before, code_bytes, rng)
        elif codebook.code_size != code_bytes:
            raise LandmarkDbError(f'the codebook codes {codebook.code_size} bytes, not '
                                  f'{code_bytes}')
        out = db.quantized(codebook)
    after = np.concatenate(out.descriptor_arrays())
    change = float(np.sqrt(np.mean(np.sum((after.astype(np.float64) - before) ** 2, axis=1))))
    if trained:  # its error on every descriptor it codes, not only on those it learnt from
        out = replace(out, codebook=replace(codebook, rms_error=change))
    points = out.points.compact(patch_quality or None) if out.points.n_points else out.points
    coded = int(points.patch_mask.sum()) if points.patch_code is not None else 0
    return replace(out, points=points), Compaction(code_bytes, len(before), change, coded)

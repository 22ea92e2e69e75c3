"""The compact database of schema 5: descriptor codes, JPEG patches, rounded points."""
from __future__ import annotations

from dataclasses import replace

from database_samples import large_database, sample_database
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from landmark_db.database import open_database, write_database
from landmark_db.database.codebook import DescriptorCodebook, train_codebook
from landmark_db.database.compact import compact_database
from landmark_db.database.patch_codec import decode_patches, encode_patches
from landmark_db.errors import LandmarkDbError


def clustered(rng: np.random.Generator, centres: int, per: int, noise: float) -> tuple:
    """SIFT-like descriptors: ``centres`` random ones, each repeated with noise."""
    base = rng.integers(0, 120, (centres, 128))
    label = np.repeat(np.arange(centres), per)
    x = np.clip(base[label] + rng.normal(0, noise, (label.size, 128)), 0, 255)
    return np.rint(x).astype(np.uint8), label, base


def test_a_few_distinct_values_are_coded_exactly():
    rng = np.random.default_rng(0)
    x = rng.integers(0, 256, (40, 128)).astype(np.uint8)  # 40 distinct rows < 256
    book = train_codebook(x, 16, np.random.default_rng(1))
    codes = book.encode(x)
    assert codes.shape == (40, 16) and codes.dtype == np.uint8
    assert np.array_equal(book.decode(codes), x)


def test_quantizing_twice_changes_nothing_and_training_is_seeded():
    x, _, _ = clustered(np.random.default_rng(2), 600, 3, 6.0)
    book = train_codebook(x, 16, np.random.default_rng(3))
    once = book.quantize(x)
    assert np.array_equal(book.quantize(once), once)
    again = train_codebook(x, 16, np.random.default_rng(3))
    assert again == book
    assert train_codebook(x, 16, np.random.default_rng(4)) != book


@pytest.mark.parametrize('code_size', [8, 16, 32, 64])
def test_the_codes_keep_each_descriptor_nearest_its_own_feature(code_size):
    # 300 features seen 4 times each with SIFT-like noise: the decoded descriptors still
    # find their own feature's mean first, and more bytes change them less.
    x, label, base = clustered(np.random.default_rng(5), 300, 4, 8.0)
    book = train_codebook(x, code_size, np.random.default_rng(6))
    y = book.quantize(x).astype(float)
    change = np.sqrt(((y - x) ** 2).sum(axis=1)).mean()
    assert change < {8: 200, 16: 150, 32: 110, 64: 70}[code_size]
    nearest = np.argmin(((y[:, None, :] - base[None, :, :]) ** 2).sum(axis=2), axis=1)
    assert np.mean(nearest == label) >= 0.99


def test_bad_codebooks_are_refused():
    x = np.zeros((10, 128), np.uint8)
    with pytest.raises(LandmarkDbError, match='one of'):
        train_codebook(x, 12, np.random.default_rng(0))
    with pytest.raises(LandmarkDbError, match='needs'):
        train_codebook(x[:0], 16, np.random.default_rng(0))
    with pytest.raises(LandmarkDbError, match='uint8'):
        DescriptorCodebook(np.zeros((16, 256, 8), np.float32))
    book = train_codebook(x, 16, np.random.default_rng(0))
    with pytest.raises(LandmarkDbError, match='codes must be'):
        book.decode(np.zeros((3, 8), np.uint8))


def smooth_patches(rng: np.random.Generator, n: int, side: int) -> np.ndarray:
    """Textured patches: a few random gradients and blobs, like the exploration's."""
    u, v = np.meshgrid(np.arange(side), np.arange(side))
    out = np.empty((n, side, side), np.uint8)
    for i in range(n):
        a = rng.normal(0, 4, 3)
        cx, cy = rng.uniform(0, side, 2)
        blob = 60 * np.exp(-((u - cx) ** 2 + (v - cy) ** 2) / (2 * rng.uniform(2, 6) ** 2))
        out[i] = np.clip(100 + a[0] * u + a[1] * v + blob + rng.normal(0, 2, u.shape),
                         0, 255).astype(np.uint8)
    return out


@pytest.mark.parametrize('quality, rms', [(100, 1.0), (80, 4.0)])
def test_patches_come_back_close_at_their_quality(quality, rms):
    patches = smooth_patches(np.random.default_rng(7), 50, 15)
    code = encode_patches(patches, quality)
    back = decode_patches(code, 50, 15)
    assert back.shape == patches.shape and back.dtype == np.uint8
    assert np.sqrt(np.mean((back.astype(float) - patches) ** 2)) < rms
    assert len(code) < patches.nbytes  # (even at 100: the mosaic is entropy-coded)


def test_many_patches_span_several_mosaics():
    patches = smooth_patches(np.random.default_rng(8), 4096 + 70, 7)
    back = decode_patches(encode_patches(patches, 90), len(patches), 7)
    assert np.abs(back.astype(int) - patches).mean() < 3


def test_damaged_or_mismatched_patch_codes_are_refused():
    patches = smooth_patches(np.random.default_rng(9), 10, 9)
    code = encode_patches(patches, 80)
    with pytest.raises(LandmarkDbError, match='holds 10 patches, not 11'):
        decode_patches(code, 11, 9)
    with pytest.raises(LandmarkDbError, match='holds 10 patches, not 9'):
        decode_patches(code, 9, 9)
    with pytest.raises(LandmarkDbError, match='ends after'):
        decode_patches(code[:6], 10, 9)
    with pytest.raises(LandmarkDbError, match='holds more'):
        decode_patches(code + code, 10, 9)
    with pytest.raises(LandmarkDbError, match='damaged'):
        decode_patches(code[:8] + bytes(len(code) - 8), 10, 9)
    with pytest.raises(LandmarkDbError, match='damaged'):
        decode_patches(code, 10, 17)
    with pytest.raises(LandmarkDbError, match='quality'):
        encode_patches(patches, 0)


def test_a_compact_database_is_what_its_file_gives_back(tmp_path):
    sample = sample_database(np.random.default_rng(0))
    db, done = compact_database(sample, 16, 80, np.random.default_rng(0))
    assert db.codebook is not None and db.codebook.code_size == 16
    assert done.code_bytes == 16 and done.coded_patches == 11
    assert done.descriptors == sum(len(d) for d in sample.descriptor_arrays())
    write_database(tmp_path / 'compact.db', db)
    assert open_database(tmp_path / 'compact.db') == db
    # Bytes: the 32 kB codebook pays once a database holds some thousand descriptors.
    large = large_database(np.random.default_rng(7), view_features=200)
    write_database(tmp_path / 'whole.db', large)
    write_database(tmp_path / 'small.db', compact_database(large, 16, 80,
                                                           np.random.default_rng(0))[0])
    assert (tmp_path / 'small.db').stat().st_size < 0.4 * (tmp_path / 'whole.db').stat().st_size
    # Compacting again changes nothing: the codes and the patch code are kept.
    again, _ = compact_database(db, 16, 80, np.random.default_rng(1), db.codebook)
    assert again == db
    # Whole descriptors and patches: only the points' rounding.
    whole, done = compact_database(sample, 128, 0, np.random.default_rng(0))
    assert whole.codebook is None and done.rms_change == 0 and done.coded_patches == 0
    assert np.array_equal(whole.points.patches, sample.points.patches)
    with pytest.raises(LandmarkDbError, match='codes 16 bytes'):
        compact_database(sample, 32, 80, np.random.default_rng(0), db.codebook)
    with pytest.raises(LandmarkDbError, match='descriptor_bytes'):
        compact_database(sample, 12, 80, np.random.default_rng(0))


@settings(max_examples=30, deadline=None, derandomize=True)
@given(st.integers(0, 2**32 - 1))
def test_compact_points_round_within_their_promises(seed):
    rng = np.random.default_rng(seed)
    points = sample_database(rng).points
    shift = rng.uniform(-500, 500, 3)
    shifted = replace(points, xyz=points.xyz + shift,
                      seen_from=points.seen_from + np.r_[shift[:2], 0])
    assert np.abs(shifted.seen_from[:, :2] - shifted.xyz[:, :2]).max() < 4
    small = shifted.compact(None)
    assert np.array_equal(small.xyz.astype(np.float32), small.xyz)
    assert np.abs(small.xyz - shifted.xyz).max() <= 500 * 2.0 ** -23
    # Where seen from: within 2 mm of it when its offset from the point is within 4 m.
    assert np.abs(small.seen_from - shifted.seen_from).max() < 2e-3
    mask = small.patch_mask
    axes = shifted.patch_axes[mask]
    error = np.linalg.norm(small.patch_axes[mask] - axes, axis=2)
    assert np.all(error <= 2.0 ** -11 * np.linalg.norm(axes, axis=2) * 1.01)
    assert np.array_equal(small.patches, shifted.patches) and small.patch_code is None


def test_patches_must_be_what_their_code_decodes_to():
    points = sample_database(np.random.default_rng(0)).points.compact(80)
    assert points.patch_code is not None
    changed = points.patches.copy()
    changed[0, 0, 0] ^= 1
    with pytest.raises(LandmarkDbError, match='decodes to'):
        replace(points, patches=changed)

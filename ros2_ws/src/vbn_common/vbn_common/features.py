"""SIFT features of the exploration images (thesis Section 1.2 and 8.3.2), in parallel.

The thesis extracts Lowe's SIFT from every exploration image (about 420 per 640 x 480
image in its 6 m x 3 m room). Here OpenCV's SIFT does it, with its settings as a frozen
:class:`SiftConfig` that is stored in the database, so that the localizer extracts the
same features at run time. Descriptors are kept as ``uint8``: OpenCV's SIFT descriptors
are integer-valued in 0..255 (normalised, clipped and scaled by 512 before rounding),
so the conversion loses nothing and stores four times less.

Extraction decodes each image in the worker (an :class:`~vbn_common.images.
EncodedImage` ships the compressed bytes, not a decoded array) and runs over a process
pool on every core (``workers``), with a tqdm progress bar on stderr.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import cv2
import numpy as np

from vbn_common.allocator import reuse_freed_memory
from vbn_common.errors import VbnCommonError
from vbn_common.images import EncodedImage, decode_image, exposed
from vbn_common.workers import available_cores, map_in_processes

__all__ = ['ImageFeatures', 'SiftConfig', 'extract_features', 'extract_features_scaled',
           'extract_many']


@dataclass(frozen=True)
class SiftConfig:
    """OpenCV SIFT settings (``cv2.SIFT_create``) plus a cap on keypoints.

    Attributes:
        n_features: Keep the best ``n_features`` keypoints by response (0: all).
        n_octave_layers: Layers per octave (Lowe's 3 finds fewer keypoints that stay
            stable across the 25 cm lattice: 5 gives 17 % more classes on the room bag,
            docs/classes.md, for 21 % more SIFT time).
        contrast_threshold: Rejects weak extrema (higher: fewer keypoints).
        edge_threshold: Rejects edge-like extrema (lower: fewer keypoints).
        sigma: Gaussian of the first octave.
        precise_upscale: OpenCV's ``enable_precise_upscale``: the image doubled before
            the first octave maps pixel ``x`` to ``2 x``. Without it keypoints come out
            shifted by a quarter pixel (OpenCV's own note on the option), the same way
            in every image: relative rotations do not see it, but every bearing in a
            camera's frame does (0.086 deg on a 1,024-column panorama, which tilted
            every estimated direction between exploration views by as much).
    """

    n_features: int = 0
    n_octave_layers: int = 5
    contrast_threshold: float = 0.04
    edge_threshold: float = 10.0
    sigma: float = 1.6
    precise_upscale: bool = False

    def __post_init__(self) -> None:
        if self.n_features < 0 or self.n_octave_layers < 1 or not self.sigma > 0 \
                or self.contrast_threshold < 0 or self.edge_threshold <= 0:
            raise VbnCommonError(f'invalid SIFT settings: {self}')

    def as_dict(self) -> dict[str, Any]:
        """Return the settings as a JSON-able dict (stored in the database)."""
        return asdict(self)

    def create(self) -> Any:
        """Return an OpenCV SIFT detector with these settings."""
        return cv2.SIFT_create(self.n_features, self.n_octave_layers, self.contrast_threshold,
                               self.edge_threshold, self.sigma, cv2.CV_32F,
                               bool(self.precise_upscale))


@dataclass(frozen=True)
class ImageFeatures:
    """The SIFT features of one image.

    Attributes:
        keypoints: (n, 2) float32 pixel coordinates (x = column, y = row).
        sizes: (n,) float32 keypoint diameters in pixels.
        angles: (n,) float32 orientations in degrees.
        responses: (n,) float32 detector responses.
        descriptors: (n, 128) uint8 SIFT descriptors.
    """

    keypoints: np.ndarray
    sizes: np.ndarray
    angles: np.ndarray
    responses: np.ndarray
    descriptors: np.ndarray

    def __len__(self) -> int:
        return int(self.keypoints.shape[0])

    @classmethod
    def empty(cls) -> ImageFeatures:
        """No features (an image where SIFT found nothing)."""
        zero = np.zeros(0, np.float32)
        return cls(np.zeros((0, 2), np.float32), zero, zero, zero,
                   np.zeros((0, 128), np.uint8))


def extract_features(image: np.ndarray, config: SiftConfig = SiftConfig(),
                     detector: Any = None) -> ImageFeatures:
    """Detect SIFT keypoints and compute their descriptors in a grey ``uint8`` image.

    Args:
        image: (H, W) uint8 grey image (colour is converted).
        config: SIFT settings (ignored when ``detector`` is given).
        detector: A detector from :meth:`SiftConfig.create`, to reuse across images.

    Returns:
        The features, sorted by decreasing response.
    """
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    detector = detector if detector is not None else config.create()
    keypoints, descriptors = detector.detectAndCompute(image, None)
    if not keypoints or descriptors is None:
        return ImageFeatures.empty()
    responses = np.array([k.response for k in keypoints], np.float32)
    order = np.argsort(-responses, kind='stable')
    pts = np.array([k.pt for k in keypoints], np.float32)[order]
    return ImageFeatures(
        keypoints=pts,
        sizes=np.array([k.size for k in keypoints], np.float32)[order],
        angles=np.array([k.angle for k in keypoints], np.float32)[order],
        responses=responses[order],
        descriptors=np.clip(np.rint(descriptors[order]), 0, 255).astype(np.uint8))


def extract_features_scaled(image: np.ndarray, scale: float, config: SiftConfig = SiftConfig(),
                            detector: Any = None) -> ImageFeatures:
    """SIFT on the image resized by ``scale``, keypoints given in the full image's pixels.

    SIFT is scale invariant, so the descriptors still match those of full-size images
    (of the features larger than the finest scales the smaller image loses): at 0.5 it
    costs about a fifth (17 against 95 ms on a 1024 x 256 panorama here) and keeps the
    features voting needs. Positions are less precise by ``1 / scale``; whoever needs
    SIFT's precision re-detects at full size where these fall.

    Args:
        image: (H, W) uint8 grey image.
        scale: In (0, 1]; 1 is :func:`extract_features`.
        config: SIFT settings (ignored when ``detector`` is given).
        detector: A detector from :meth:`SiftConfig.create`.

    Returns:
        The features, keypoints and sizes in the full image's pixels.
    """
    if not 0.0 < scale <= 1.0:
        raise ValueError(f'scale must be in (0, 1], got {scale}')
    if scale == 1.0:
        return extract_features(image, config, detector)
    small = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    found = extract_features(small, config, detector)
    # Pixel centres: small pixel i spans full pixels [i / scale, (i + 1) / scale).
    return ImageFeatures(keypoints=((found.keypoints + 0.5) / scale - 0.5).astype(np.float32),
                         sizes=(found.sizes / scale).astype(np.float32), angles=found.angles,
                         responses=found.responses, descriptors=found.descriptors)


_WORKER: dict[str, Any] = {}


def _init_worker(config: SiftConfig) -> None:
    cv2.setNumThreads(1)  # one process per core: no nested threading
    _WORKER['config'] = config
    _WORKER['detector'] = config.create()


def _init_pool_worker(config: SiftConfig, exposure: float = 0.0) -> None:
    _init_worker(config)
    _WORKER['exposure'] = exposure
    reuse_freed_memory()  # SIFT's pyramid would be unmapped and faulted in per image


def _extract_encoded(image: EncodedImage) -> ImageFeatures | str:
    try:
        gray = decode_image(image)
    except VbnCommonError as error:
        return str(error)
    gray = exposed(gray, _WORKER.get('exposure', 0.0))   # 0: as it is
    return extract_features(gray, _WORKER['config'], _WORKER['detector'])


def extract_many(images: Sequence[EncodedImage], config: SiftConfig = SiftConfig(),
                 workers: int | None = None,
                 progress: Callable[[int], None] | None = None,
                 check_stop: Callable[[], None] | None = None,
                 exposure: float = 0.0) -> list[ImageFeatures | str]:
    """Extract the features of many encoded images, in order, over a process pool.

    Args:
        images: The images (compressed or raw), decoded in the workers.
        config: SIFT settings.
        workers: Processes (default: every core; 1 runs in this process).
        progress: Called with the number of images just finished (e.g. a tqdm update).
        check_stop: Called between images, and every half second while the pool works;
            what it raises stops the extraction (the workers are terminated).
        exposure: Brighten each image whose 99th percentile is below this first
            (:func:`~vbn_common.images.exposed`; 0: as it is).

    Returns:
        Per image, its features, or the one-line reason it could not be decoded.
    """
    workers = available_cores() if workers is None else workers
    if workers < 1:
        raise VbnCommonError(f'workers must be at least 1, got {workers}')
    results: list[ImageFeatures | str] = []
    if workers == 1 or len(images) < 4:
        _init_worker(config)
        _WORKER['exposure'] = exposure
        for image in images:
            if check_stop is not None:
                check_stop()
            results.append(_extract_encoded(image))
            if progress:
                progress(1)
        return results
    chunk = max(1, min(16, len(images) // (4 * workers)))
    return map_in_processes(_extract_encoded, images, workers, initializer=_init_pool_worker,
                            initargs=(config, exposure), chunksize=chunk, progress=progress,
                            check_stop=check_stop)

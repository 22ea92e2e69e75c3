"""Per-frame photometric effects: exposure change, blur and sensor noise, seeded.

A recorded camera never gives the same image twice; the localizer and the builder
must cope with that. Each effect is drawn from the frame's generator, so a bag is
reproducible from its seed.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from vbn_worlds.errors import WorldsError

__all__ = ['ImageEffects', 'apply_effects']


@dataclass(frozen=True)
class ImageEffects:
    """Strength of the per-frame effects (all zero: the image is left untouched).

    Attributes:
        exposure: relative exposure change; the gain is drawn uniformly in
            ``[1 - exposure, 1 + exposure]``.
        blur_sigma: the Gaussian blur's sigma is drawn uniformly in ``[0, blur_sigma]``
            pixels.
        noise_sigma: standard deviation of additive Gaussian noise, grey levels.
    """

    exposure: float = 0.0
    blur_sigma: float = 0.0
    noise_sigma: float = 0.0

    def __post_init__(self) -> None:
        for name in ('exposure', 'blur_sigma', 'noise_sigma'):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise WorldsError(f'image effect {name} must be >= 0, got {value}')
        if self.exposure >= 1:
            raise WorldsError(f'exposure change must be below 1, got {self.exposure}')

    @property
    def active(self) -> bool:
        """Return True when any effect is non-zero."""
        return bool(self.exposure or self.blur_sigma or self.noise_sigma)


def apply_effects(image: np.ndarray, effects: ImageEffects,
                  rng: np.random.Generator) -> np.ndarray:
    """Apply exposure gain, blur and noise to a ``uint8`` image.

    Args:
        image: ``(h, w)`` or ``(h, w, 3)`` ``uint8`` image.
        effects: the strengths.
        rng: the frame's generator (always consumed the same way, so that the
            sequence of frames stays reproducible).

    Returns:
        A new ``uint8`` image of the same shape.
    """
    gain = float(rng.uniform(1.0 - effects.exposure, 1.0 + effects.exposure))
    sigma = float(rng.uniform(0.0, effects.blur_sigma))
    out = image.astype(np.float32)
    if effects.exposure:
        out *= gain
    if sigma > 0.05:
        out = cv2.GaussianBlur(out, (0, 0), sigma)
    if effects.noise_sigma:
        out += rng.normal(0.0, effects.noise_sigma, size=out.shape).astype(np.float32)
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)

"""Image-space error metrics on linear HDR images (DESIGN.md section 11).

All take the reference first, then the image, both (H, W, C) arrays, and an optional (H, W)
boolean mask of the pixels to measure (all pixels when omitted); averages run over the masked
pixels and all channels.

* MAE  = mean |x - r|
* RMSE = sqrt(mean (x - r)^2)
* MAPE = mean |x - r| / (|r| + eps), eps = 0.01 by default (a small epsilon against division by
  zero in black pixels; 0.01 is 1 % of a diffuse white)
* PSNR = 20 log10(peak / RMSE) in dB, with peak = 1 (the linear value of display white; HDR
  highlights above it are not clipped)
"""

from __future__ import annotations

import math

import numpy as np

MAPE_EPSILON = 1e-2
PSNR_PEAK = 1.0


def _pixels(reference: np.ndarray, image: np.ndarray, mask: np.ndarray | None):
    reference = np.asarray(reference, dtype=np.float64)
    image = np.asarray(image, dtype=np.float64)
    if reference.shape != image.shape:
        raise ValueError(f"image shape {image.shape} differs from the reference's {reference.shape}")
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != reference.shape[:2]:
            raise ValueError(f"mask shape {mask.shape} does not match the image's {reference.shape[:2]}")
        if not mask.any():
            raise ValueError("the mask selects no pixel")
        return reference[mask], image[mask]
    return reference, image


def mae(reference, image, mask=None) -> float:
    r, x = _pixels(reference, image, mask)
    return float(np.mean(np.abs(x - r)))


def rmse(reference, image, mask=None) -> float:
    r, x = _pixels(reference, image, mask)
    return float(np.sqrt(np.mean((x - r) ** 2)))


def mape(reference, image, mask=None, epsilon: float = MAPE_EPSILON) -> float:
    r, x = _pixels(reference, image, mask)
    return float(np.mean(np.abs(x - r) / (np.abs(r) + epsilon)))


def psnr(reference, image, mask=None, peak: float = PSNR_PEAK) -> float:
    error = rmse(reference, image, mask)
    return math.inf if error == 0 else float(20.0 * math.log10(peak / error))


def all_metrics(reference, image, mask=None) -> dict[str, float]:
    """{"mae", "rmse", "mape", "psnr"} of ``image`` against ``reference``."""
    return {"mae": mae(reference, image, mask), "rmse": rmse(reference, image, mask),
            "mape": mape(reference, image, mask), "psnr": psnr(reference, image, mask)}


def nonfinite_count(image) -> int:
    return int(np.size(image) - np.count_nonzero(np.isfinite(image)))


def firefly_count(reference, image, factor: float = 10.0, floor: float = 1.0) -> int:
    """Pixels whose luminance exceeds ``factor`` times the reference's plus ``floor``: outliers
    that more samples would not average out at the spp of ``image``."""
    weights = np.array([0.2126, 0.7152, 0.0722])
    lum_r = np.asarray(reference, np.float64)[..., :3] @ weights
    lum_x = np.asarray(image, np.float64)[..., :3] @ weights
    return int(np.count_nonzero(lum_x > factor * lum_r + floor))

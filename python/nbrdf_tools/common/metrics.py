"""Image-space error metrics on linear HDR images, one name per definition.

The pixel metrics take the reference first, then the image, both (H, W, C) arrays, and an
optional (H, W) boolean mask of the pixels to measure (all pixels when omitted); averages run
over the masked pixels and all channels.

* ``mae``  = mean |x - r|
* ``rmse`` = sqrt(mean (x - r)^2)
* ``relmse`` = mean (x - r)^2 / (r^2 + eps), eps = 0.01 (relative MSE as in the rendering
  literature, e.g. Rousselle et al. 2011; eps keeps black pixels from dominating)
* ``mape`` = mean |x - r| / (|r| + eps), eps = 0.01 (0.01 is 1 % of a diffuse white)
* ``psnr_peak1``    = 20 log10(1 / RMSE) dB: peak 1, the linear value of display white (HDR
  highlights above it are not clipped); the renders' PSNR
* ``psnr_peak_ref`` = 20 log10(max(reference) / RMSE) dB: peak = the reference's maximum; the
  sphere images' PSNR of ``nbrdf compare`` and :mod:`nbrdf_tools.common.compare_materials`

* ``mae_tonemapped`` / ``rmse_tonemapped`` = ``mae`` / ``rmse`` of the ``tone_map``-ped images
  (display values in [0, 1]: highlights above white count as white)

Whole-image metrics (no mask):

* ``ssim`` - scikit-image's ``structural_similarity`` with Wang et al.'s (2004) settings
  (11x11 Gaussian window of sigma 1.5, K1 = 0.01, K2 = 0.03, population covariances,
  data range 1) on ``tone_map``-ped images, the mean over the channels;
* ``flip_hdr`` - NVIDIA's HDR-FLIP (Andersson et al. 2021, the ``flip-evaluator`` package):
  the mean FLIP error in [0, 1] of two linear HDR images, exposures chosen from the reference.
"""

from __future__ import annotations

import math

import numpy as np

EPSILON = 1e-2
# The tone map of the SSIM images (and the sphere figures): gamma 2.2, clipped to [0, 1].
GAMMA = 2.2


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


def relmse(reference, image, mask=None, epsilon: float = EPSILON) -> float:
    r, x = _pixels(reference, image, mask)
    return float(np.mean((x - r) ** 2 / (r * r + epsilon)))


def mape(reference, image, mask=None, epsilon: float = EPSILON) -> float:
    r, x = _pixels(reference, image, mask)
    return float(np.mean(np.abs(x - r) / (np.abs(r) + epsilon)))


def _psnr(peak: float, error: float) -> float:
    return math.inf if error == 0 else float(20.0 * math.log10(peak / error))


def psnr_peak1(reference, image, mask=None) -> float:
    return _psnr(1.0, rmse(reference, image, mask))


def psnr_peak_ref(reference, image, mask=None) -> float:
    r, _ = _pixels(reference, image, mask)
    return _psnr(max(float(np.max(r)), np.finfo(np.float64).tiny), rmse(reference, image, mask))


def relative_rmse(reference, image, mask=None) -> float:
    """RMSE over the reference's root mean square (the error as a fraction of the signal)."""
    r, _ = _pixels(reference, image, mask)
    return rmse(reference, image, mask) / float(np.sqrt(np.mean(r * r)))


def tone_map(image: np.ndarray) -> np.ndarray:
    """``min(max(x, 1e-12)^(1/2.2), 1)`` of a linear image (float64)."""
    return np.minimum(np.maximum(np.asarray(image, dtype=np.float64), 1e-12) ** (1.0 / GAMMA), 1.0)


def mae_tonemapped(reference, image, mask=None) -> float:
    return mae(tone_map(reference), tone_map(image), mask)


def rmse_tonemapped(reference, image, mask=None) -> float:
    return rmse(tone_map(reference), tone_map(image), mask)


def ssim(reference, image, channel_axis: int = -1) -> float:
    """Mean SSIM of the tone-mapped images (scikit-image, Wang et al.'s settings); the images
    are linear, (H, W, C) by default or with the channels on ``channel_axis``."""
    from skimage.metrics import structural_similarity

    return float(structural_similarity(tone_map(reference), tone_map(image), data_range=1.0,
                                       channel_axis=channel_axis, gaussian_weights=True, sigma=1.5,
                                       use_sample_covariance=False))


def flip_hdr(reference, image) -> float:
    """Mean HDR-FLIP error of two linear (H, W, 3) images (NVIDIA's ``flip-evaluator``)."""
    import flip_evaluator

    r = np.ascontiguousarray(np.maximum(np.asarray(reference, dtype=np.float32), 0.0))
    x = np.ascontiguousarray(np.maximum(np.asarray(image, dtype=np.float32), 0.0))
    if r.shape != x.shape:
        raise ValueError(f"image shape {x.shape} differs from the reference's {r.shape}")
    _, mean, _ = flip_evaluator.evaluate(r, x, "HDR", applyMagma=False)
    return float(mean)


def render_metrics(reference, image, mask=None) -> dict[str, float]:
    """The per-render metrics of the scene scripts, over the masked pixels: ``mae``, ``rmse``,
    ``relmse``, ``mape``, ``psnr_peak1``. (``flip_hdr`` and ``ssim`` are spatial: they take whole
    images and are added where a report wants them.)"""
    return {"mae": mae(reference, image, mask), "rmse": rmse(reference, image, mask),
            "relmse": relmse(reference, image, mask), "mape": mape(reference, image, mask),
            "psnr_peak1": psnr_peak1(reference, image, mask)}


def nonfinite_count(image) -> int:
    return int(np.size(image) - np.count_nonzero(np.isfinite(image)))


def firefly_count(reference, image, factor: float = 10.0, floor: float = 1.0) -> int:
    """Pixels whose luminance exceeds ``factor`` times the reference's plus ``floor``: outliers
    that more samples would not average out at the spp of ``image``."""
    weights = np.array([0.2126, 0.7152, 0.0722])
    lum_r = np.asarray(reference, np.float64)[..., :3] @ weights
    lum_x = np.asarray(image, np.float64)[..., :3] @ weights
    return int(np.count_nonzero(lum_x > factor * lum_r + floor))

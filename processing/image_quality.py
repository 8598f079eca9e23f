"""How close a predicted image is to a measured one: the metrics of the RTI literature.

Pure functions on linear RGB images (H, W, 3) with an optional mask (H, W) of the pixels that
count. The display metrics are computed as the RTI literature computes them, on 8-bit sRGB:
the linear values are scaled (``scale``, chosen from the reference, see
:func:`display_scale`), clipped to [0, 1], sRGB-encoded and rounded to 8 bits, for both images.

==============  =========================================================================
metric          definition
==============  =========================================================================
``psnr``        20 log10(255) - 10 log10(MSE) over the masked pixels and channels of the
                8-bit images, dB (infinite for identical images)
``ssim``        Wang et al. 2004 on the 8-bit images (scikit-image's
                ``structural_similarity``: Gaussian window sigma 1.5, population
                covariance, K1 = 0.01, K2 = 0.03, per channel), averaged over the
                masked pixels at least half a window from the border (as scikit-image
                averages: its border values rest on padding)
``delta_e``     mean CIEDE2000 colour difference over the mask, CIELAB from the display
                sRGB values (D65)
``rel_rmse``    sqrt(sum (p - r)^2 / sum r^2) over the masked pixels, in linear light,
                unclipped: the figure the project's other studies report (all of them
                through :func:`relative_rmse_values`)
==============  =========================================================================

scikit-image implements SSIM and CIEDE2000 as the literature defines them; writing either by
hand would be a second, unchecked copy.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from skimage.color import deltaE_ciede2000, rgb2lab
from skimage.metrics import structural_similarity

from core.colour import linear_to_srgb
from core.errors import InputError

__all__ = [
    "DISPLAY_PERCENTILE",
    "SSIM_WINDOW",
    "ImageQuality",
    "clipped_srgb_8bit",
    "delta_e2000",
    "display_scale",
    "image_quality",
    "psnr_8bit",
    "relative_rmse",
    "relative_rmse_values",
    "ssim_8bit",
]

#: Side of SSIM's Gaussian window (sigma 1.5, truncated at 3.5 sigma, as scikit-image's).
SSIM_WINDOW = 11

#: Percentile of the reference's channel values :func:`display_scale` maps to white: HDR
#: references (simulated fields) have no display range of their own.
DISPLAY_PERCENTILE = 99.5


def _checked(
    predicted: NDArray[np.floating], reference: NDArray[np.floating], mask: NDArray[np.bool_] | None
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    p = np.asarray(predicted, dtype=np.float64)
    r = np.asarray(reference, dtype=np.float64)
    if p.shape != r.shape or p.ndim != 3 or p.shape[2] != 3:
        raise InputError(f"images must both be (H, W, 3), got {p.shape} and {r.shape}")
    m = np.ones(p.shape[:2], dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    if m.shape != p.shape[:2]:
        raise InputError(f"mask must be {p.shape[:2]}, got {m.shape}")
    if not m.any():
        raise InputError("the mask selects no pixel")
    if not (np.isfinite(p[m]).all() and np.isfinite(r[m]).all()):
        raise InputError("images to compare must be finite where the mask selects")
    return p, r, m


def display_scale(reference: NDArray[np.floating], mask: NDArray[np.bool_] | None = None) -> float:
    """The linear scale that maps the reference's :data:`DISPLAY_PERCENTILE` value to white.

    Parameters
    ----------
    reference : ndarray, (..., 3), linear RGB (one image, or a stack of test images)
    mask : ndarray of bool, the reference's leading shape, or None

    Returns
    -------
    float > 0 (1 for an all-black reference)
    """
    r = np.asarray(reference, dtype=np.float64)
    values = r[mask] if mask is not None else r.reshape(-1, 3)
    level = float(np.percentile(values, DISPLAY_PERCENTILE)) if values.size else 0.0
    return 1.0 / level if level > 0 else 1.0


def clipped_srgb_8bit(linear: NDArray[np.floating], scale: float = 1.0) -> NDArray[np.uint8]:
    """Linear RGB as the 8-bit sRGB values a display (and the RTI tools) would hold.

    No tone mapping (for a picture to look at, :func:`render.tonemap.tone_mapped_8bit`
    compresses highlights instead): the values are scaled, clipped to [0, 1], sRGB-encoded and
    rounded, as the RTI literature computes its display metrics.

    Parameters
    ----------
    linear : ndarray, shape (..., 3), linear RGB
    scale : float, the linear value shown as white is ``1 / scale`` (:func:`display_scale`)

    Returns
    -------
    ndarray, shape (..., 3), uint8, sRGB-encoded levels
    """
    encoded = linear_to_srgb(np.clip(np.asarray(linear, dtype=np.float64) * scale, 0.0, 1.0))
    return np.round(np.asarray(encoded, dtype=np.float64) * 255.0).astype(np.uint8)


def psnr_8bit(
    predicted: NDArray[np.floating],
    reference: NDArray[np.floating],
    mask: NDArray[np.bool_] | None = None,
    *,
    scale: float = 1.0,
) -> float:
    """PSNR in dB of the 8-bit sRGB images over the masked pixels (inf when identical)."""
    p, r, m = _checked(predicted, reference, mask)
    a = clipped_srgb_8bit(p, scale)[m].astype(np.float64)
    b = clipped_srgb_8bit(r, scale)[m].astype(np.float64)
    mse = float(np.mean((a - b) ** 2))
    return math.inf if mse == 0 else 20.0 * math.log10(255.0) - 10.0 * math.log10(mse)


def ssim_8bit(
    predicted: NDArray[np.floating],
    reference: NDArray[np.floating],
    mask: NDArray[np.bool_] | None = None,
    *,
    scale: float = 1.0,
) -> float:
    """Mean SSIM of the 8-bit sRGB images over the masked pixels (Wang et al. 2004 settings).

    Images smaller than the 11 x 11 window (the Gaussian's, truncated at 3.5 sigma) are
    refused.
    """
    p, r, m = _checked(predicted, reference, mask)
    if min(p.shape[:2]) < SSIM_WINDOW:
        raise InputError(
            f"SSIM needs images of at least {SSIM_WINDOW} x {SSIM_WINDOW} pixels, got "
            f"{p.shape[1]}x{p.shape[0]}"
        )
    _, full = structural_similarity(  # type: ignore[no-untyped-call]  # skimage: untyped
        clipped_srgb_8bit(p, scale),
        clipped_srgb_8bit(r, scale),
        channel_axis=2,
        data_range=255,
        gaussian_weights=True,
        sigma=1.5,
        use_sample_covariance=False,
        full=True,
    )
    pad = SSIM_WINDOW // 2
    inner = np.zeros_like(m)
    inner[pad:-pad, pad:-pad] = m[pad:-pad, pad:-pad]
    return float(np.mean(full[inner if inner.any() else m]))


def delta_e2000(
    predicted: NDArray[np.floating],
    reference: NDArray[np.floating],
    mask: NDArray[np.bool_] | None = None,
    *,
    scale: float = 1.0,
) -> float:
    """Mean CIEDE2000 difference over the masked pixels, from the display sRGB values."""
    p, r, m = _checked(predicted, reference, mask)
    lab_p = rgb2lab(clipped_srgb_8bit(p, scale)[m][None].astype(np.float64) / 255.0)
    lab_r = rgb2lab(clipped_srgb_8bit(r, scale)[m][None].astype(np.float64) / 255.0)
    difference = deltaE_ciede2000(lab_r, lab_p)  # type: ignore[no-untyped-call]
    return float(np.mean(difference))


def relative_rmse_values(
    predicted: ArrayLike, reference: ArrayLike, mask: ArrayLike | None = None
) -> float:
    """The relative RMSE of any values: sqrt(sum (p - r)^2 / sum r^2), in float64.

    The one formula every relative RMSE of the project goes through: images, a field's
    samples, a benchmark's responses. :func:`relative_rmse` is the checked form for images.

    Parameters
    ----------
    predicted, reference : array_like, the same shape (any), linear values
    mask : array_like of bool, the leading part of that shape (``reference.shape[:mask.ndim]``),
        or None: the values that count (a mask of pixels (H, W) for images (H, W, 3), of
        samples for radiance (P, 3), or of every value)

    Returns
    -------
    float
        0 when the selected reference values are all zero or none is selected; NaN when a
        selected value is NaN (nothing is checked for finiteness).

    Raises
    ------
    InputError
        Shapes that differ, or a mask that is not their leading part.
    """
    p, r = np.asarray(predicted), np.asarray(reference)
    if p.shape != r.shape:
        raise InputError(f"values to compare must have one shape, got {p.shape} and {r.shape}")
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        if m.shape != r.shape[: m.ndim]:
            raise InputError(f"mask {m.shape} is not the leading part of the shape {r.shape}")
        p, r = p[m], r[m]
    p, r = p.astype(np.float64, copy=False), r.astype(np.float64, copy=False)
    energy = float(np.sum(r**2))
    return math.sqrt(float(np.sum((p - r) ** 2)) / energy) if energy > 0 else 0.0


def relative_rmse(
    predicted: NDArray[np.floating],
    reference: NDArray[np.floating],
    mask: NDArray[np.bool_] | None = None,
) -> float:
    """sqrt(sum (p - r)^2 / sum r^2) over the masked pixels, linear light (0 for black r).

    Images (H, W, 3) checked as every metric here checks them (finite, a mask that selects a
    pixel); the sum is :func:`relative_rmse_values`'.
    """
    p, r, m = _checked(predicted, reference, mask)
    return relative_rmse_values(p, r, m)


@dataclass(frozen=True)
class ImageQuality:
    """The four metrics of one predicted image against its reference (see the module)."""

    psnr: float
    ssim: float
    delta_e: float
    rel_rmse: float

    def to_dict(self) -> dict[str, float | None]:
        """As JSON-ready numbers (an infinite PSNR, identical images, is null)."""
        return {k: (v if math.isfinite(v) else None) for k, v in asdict(self).items()}


def image_quality(
    predicted: NDArray[np.floating],
    reference: NDArray[np.floating],
    mask: NDArray[np.bool_] | None = None,
    *,
    scale: float = 1.0,
) -> ImageQuality:
    """Every metric of ``predicted`` against ``reference`` (linear RGB, (H, W, 3))."""
    return ImageQuality(
        psnr=psnr_8bit(predicted, reference, mask, scale=scale),
        ssim=ssim_8bit(predicted, reference, mask, scale=scale),
        delta_e=delta_e2000(predicted, reference, mask, scale=scale),
        rel_rmse=relative_rmse(predicted, reference, mask),
    )

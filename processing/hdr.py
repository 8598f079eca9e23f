"""From decoded exposures to linear radiance per unit exposure time: dark frames and HDR merge.

One reflectance-field image may be a bracket of exposures of the same pose and light. Each
exposure e (time t_e, decoded linear value v_e, 1.0 = saturation) gives a rate

    r_e = (v_e - dark_e) / t_e        (per millisecond)

where dark_e is the dark frame of the same camera pose and exposure time (light off: black
level residue, fixed-pattern offsets, stray light), and the merged rate is the weighted mean

    r = sum_e w_e r_e / sum_e w_e,    w_e = t_e h(v_e),  0 where v_e is saturated

h is a hat on the decoded (pre-dark) value: 1 across the trusted range, falling linearly to 0
at ``top`` (values close to saturation, where the response bends and colour clips) and to a
small floor at black (a near-black value is mostly read noise and quantisation, but it is all a
lone exposure has). The factor t_e weights by the signal collected, which for shot noise is the
maximum-likelihood weighting (the variance of r_e falls as 1 / t_e). Pixels with no usable
exposure (saturated in every one) keep the shortest exposure's rate, a lower bound, and are
marked ``saturated``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from processing.decode import DecodedImage, DecodeError

__all__ = ["HAT_FLOOR", "HAT_LOW", "HAT_TOP", "Exposure", "MergedImage", "hat", "merge_exposures"]

#: Hat of the merge weights: full weight from HAT_LOW up to HAT_KNEE, falling to 0 at HAT_TOP,
#: and HAT_FLOOR at black (fractions of the saturation level).
HAT_LOW = 0.02
HAT_KNEE = 0.9
HAT_TOP = 0.98
HAT_FLOOR = 0.05


@dataclass(frozen=True)
class Exposure:
    """One exposure of a bracket: the decoded image, its time, and its dark frame (optional).

    Attributes
    ----------
    image : DecodedImage
    exposure_ms : float, > 0
    dark : DecodedImage or None, same camera pose and exposure time, light off
    """

    image: DecodedImage
    exposure_ms: float
    dark: DecodedImage | None = None


@dataclass(frozen=True)
class MergedImage:
    """A merged bracket.

    Attributes
    ----------
    rate : ndarray, shape (H, W, 3), float32
        Dark-subtracted linear value per millisecond of exposure (decoded units, 1.0 =
        saturation, per ms).
    saturated : ndarray, shape (H, W, 3), bool
        No exposure was usable there: ``rate`` is a lower bound.
    files : tuple of str, the images merged (and their dark frames)
    """

    rate: NDArray[np.float32]
    saturated: NDArray[np.bool_]
    files: tuple[str, ...]


def hat(values: NDArray[np.floating]) -> NDArray[np.float32]:
    """The merge weight of decoded values (1.0 = saturation); same shape, float32 in [0, 1].

    ``HAT_FLOOR`` at 0 rising linearly to 1 at ``HAT_LOW``, 1 up to ``HAT_KNEE``, falling
    linearly to 0 at ``HAT_TOP`` and 0 above.
    """
    v = np.asarray(values, dtype=np.float32)
    rise = HAT_FLOOR + (1.0 - HAT_FLOOR) * np.clip(v, 0.0, None) / HAT_LOW
    fall = (HAT_TOP - v) / (HAT_TOP - HAT_KNEE)
    return np.clip(np.minimum(rise, fall), 0.0, 1.0).astype(np.float32)


def merge_exposures(exposures: Sequence[Exposure]) -> MergedImage:
    """Dark-subtract and merge a bracket of exposures into one linear rate image.

    Parameters
    ----------
    exposures : sequence of Exposure, one or more, all of one size

    Returns
    -------
    MergedImage

    Raises
    ------
    DecodeError
        The images (or their dark frames) differ in size, or every pixel is saturated in every
        exposure; the message names the files.
    """
    if not exposures:
        raise InputError("a bracket needs at least one exposure")
    files = tuple(str(e.image.path) for e in exposures)
    shape = exposures[0].image.linear.shape
    for exposure in exposures:
        if not exposure.exposure_ms > 0:
            raise InputError(f"{exposure.image.path}: exposure {exposure.exposure_ms} ms")
        for decoded in (exposure.image, exposure.dark):
            if decoded is not None and decoded.linear.shape != shape:
                raise DecodeError(
                    f"{decoded.path}: image of shape {decoded.linear.shape} in a bracket of "
                    f"{shape} (with {files[0]})"
                )
        _check_dark(exposure)
    total = np.zeros(shape, dtype=np.float32)
    weights = np.zeros(shape, dtype=np.float32)
    shortest = min(exposures, key=lambda e: e.exposure_ms)
    fallback = np.zeros(shape, dtype=np.float32)
    for exposure in exposures:
        value = exposure.image.linear
        signal = value if exposure.dark is None else value - exposure.dark.linear
        rate = signal / np.float32(exposure.exposure_ms)
        weight = hat(value) * np.float32(exposure.exposure_ms)
        weight[exposure.image.saturated] = 0.0
        total += weight * rate
        weights += weight
        if exposure is shortest:
            fallback = rate
    usable = weights > 0
    if not usable.any():
        raise DecodeError(
            f"every pixel is saturated in every exposure of {', '.join(files)}; shorten the "
            f"exposure or dim the light"
        )
    merged = np.where(usable, total / np.where(usable, weights, 1.0), fallback)
    darks = tuple(str(e.dark.path) for e in exposures if e.dark is not None)
    return MergedImage(merged.astype(np.float32), ~usable, files + darks)


#: A dark frame whose mean exceeds its light image's by this share of full scale, and is more
#: than twice it, was not taken with the light off (sensor noise and a light behind the object
#: leave the two about equal).
DARK_EXCESS = 0.02


def _check_dark(exposure: Exposure) -> None:
    """Refuse a dark frame brighter than the image it is subtracted from (negative radiance)."""
    if exposure.dark is None:
        return
    lit = float(np.mean(exposure.image.linear))
    dark = float(np.mean(exposure.dark.linear))
    if dark > max(2.0 * lit, lit + DARK_EXCESS):
        raise DecodeError(
            f"{exposure.dark.path}: the dark frame (mean {dark:.3f} of full scale) is brighter "
            f"than the light image it is subtracted from ({exposure.image.path}, mean "
            f"{lit:.3f}): it was taken with the light on or at another exposure; retake it with "
            "the light off at the same exposure"
        )

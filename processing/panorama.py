"""Equirectangular environment panoramas: reading, validating and adjusting.

In memory a panorama is linear float32 RGB radiance of shape (H, W, 3) with W = 2H, mapped to
directions as ``core.directions`` says. Files are read through :mod:`core.image_io`: 8/16-bit
PNG and JPEG (sRGB-decoded to linear unless told otherwise), OpenEXR (any compression the
OpenEXR library knows, DWAB included) and Radiance ``.hdr``; write one with
:func:`core.image_io.write_linear`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from core.directions import panorama_solid_angles, rotate_panorama_yaw
from core.errors import InputError, PanoramaError
from core.field_store import BelowHorizon
from core.image_io import ImageFileError, Transfer, read_linear

__all__ = [
    "MAX_RADIANCE",
    "MIN_HEIGHT",
    "NEGATIVE_TOLERANCE",
    "PANORAMA_SUFFIXES",
    "Panorama",
    "VisibleEnvironments",
    "adjust_panorama",
    "block_below_horizon",
    "downsample_panorama",
    "panorama_from_array",
    "read_panorama",
    "visible_environment",
]

PANORAMA_SUFFIXES = (".exr", ".hdr", ".pic", ".png", ".jpg", ".jpeg")

#: Negative values are lossy-compression and stitching noise (DWA-compressed EXRs carry
#: some, of a few thousandths): they are clamped to zero, and the panorama refused only when
#: their energy (solid-angle weighted) exceeds this share of its positive light.
NEGATIVE_TOLERANCE = 1e-3

#: Largest radiance accepted: the relighting sums (radiance x solid angle x reflectance over
#: thousands of lights, in float32) overflow well before float32's 3.4e38; real skies with a
#: sun span about 1e-3 .. 1e9.
MAX_RADIANCE = 1e12

#: Smallest panorama height, pixels (width 2H): fewer rows cannot hold a sky and a ground.
MIN_HEIGHT = 4


@dataclass(frozen=True)
class Panorama:
    """A validated equirectangular environment.

    Attributes
    ----------
    rgb : ndarray, shape (H, W, 3), float32
        Linear radiance, finite and non-negative, W = 2H.
    source : str
        Where it came from (a file path, or a description for arrays).
    negative_pixels : int
        Pixels that held small negative values (compression noise), clamped to zero.
    negative_share : float
        Their energy as a share of the positive light (solid-angle weighted).
    """

    rgb: NDArray[np.float32]
    source: str
    negative_pixels: int = 0
    negative_share: float = 0.0

    @property
    def note(self) -> str | None:
        """One line about what reading changed (negative pixels clamped), or None."""
        if not self.negative_pixels:
            return None
        return (
            f"note: {self.source}: {self.negative_pixels} pixels with small negative values "
            f"(lossy compression or stitching) clamped to zero, {self.negative_share:.2g} of "
            "the light"
        )

    @property
    def height(self) -> int:
        """Rows, H."""
        return int(self.rgb.shape[0])

    @property
    def width(self) -> int:
        """Columns, W = 2H."""
        return int(self.rgb.shape[1])


def panorama_from_array(
    rgb: NDArray[np.floating], *, source: str = "<array>", resample: bool = False
) -> Panorama:
    """Validate an array as a panorama (see :func:`read_panorama` for the rules).

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3) or (H, W), linear radiance
    source : str
        Named in error messages.
    resample : bool
        Resize an image that is not 2:1 to width 2H instead of refusing it.
    """
    image = np.asarray(rgb)
    if image.ndim == 2:
        image = np.repeat(image[:, :, None], 3, axis=2)
    if image.ndim != 3 or image.shape[2] not in (3, 4):
        raise PanoramaError(f"{source}: expected an (H, W, 3) RGB image, got shape {image.shape}")
    if image.shape[0] < MIN_HEIGHT:
        raise PanoramaError(
            f"{source}: {image.shape[1]}x{image.shape[0]} pixels is too small for an "
            f"environment; a panorama needs at least {2 * MIN_HEIGHT}x{MIN_HEIGHT}"
        )
    image = np.ascontiguousarray(image[:, :, :3], dtype=np.float32)
    height, width = image.shape[:2]
    if width != 2 * height:
        if not resample:
            raise PanoramaError(
                f"{source}: an equirectangular panorama must be twice as wide as high, got "
                f"{width}x{height}; pass resample=True (CLI: --resample) to resize it"
            )
        image = cv2.resize(image, (2 * height, height), interpolation=cv2.INTER_AREA)
    finite = np.isfinite(image)
    if not finite.all():
        row, col, _ = np.argwhere(~finite)[0]
        count = int((~finite).sum())
        raise PanoramaError(
            f"{source}: {count} NaN or infinite values (first at row {row}, col {col})"
        )
    highest = float(image.max())
    if highest > MAX_RADIANCE:
        positive = image[image > 0]
        raise PanoramaError(
            f"{source}: radiance up to {highest:.3g} (dynamic range {highest / positive.min():.3g}"
            f" : 1); values above {MAX_RADIANCE:g} overflow the relighting sums: check the "
            "file's units, or scale it down before use"
        )
    negative_pixels, negative_share = 0, 0.0
    if float(image.min()) < 0.0:
        weight = panorama_solid_angles(image.shape[0], image.shape[1])[:, :, None]
        negative = float((np.minimum(image, 0.0) * weight).sum())
        light = float((np.maximum(image, 0.0) * weight).sum())
        negative_share = -negative / light if light > 0 else float("inf")
        negative_pixels = int((image < 0).any(axis=2).sum())
        if negative_share > NEGATIVE_TOLERANCE:
            row, col, _ = np.unravel_index(int(np.argmin(image)), image.shape)
            raise PanoramaError(
                f"{source}: {negative_pixels} pixels hold negative radiance (lowest "
                f"{float(image.min()):.4g} at row {row}, col {col}), {negative_share:.2g} of "
                f"the light, more than compression noise ({NEGATIVE_TOLERANCE:g}): light "
                "cannot be negative; check how the panorama was made"
            )
        image = np.maximum(image, np.float32(0.0))
    if not image.any():
        raise PanoramaError(f"{source}: the panorama holds no light (every pixel is zero)")
    return Panorama(
        rgb=np.asarray(image, dtype=np.float32),
        source=source,
        negative_pixels=negative_pixels,
        negative_share=negative_share,
    )


def read_panorama(
    path: str | os.PathLike[str], *, resample: bool = False, transfer: Transfer | None = None
) -> Panorama:
    """Read an equirectangular panorama as linear float32 RGB.

    Parameters
    ----------
    path : path to an ``.exr``, ``.hdr``, ``.png``, ``.jpg`` or ``.jpeg`` file
    resample : bool
        Resize an image that is not 2:1 to width 2H instead of refusing it.
    transfer : {"srgb", "linear"}, optional
        Encoding of PNG/JPEG values; default sRGB (decoded to linear). EXR and HDR are linear.

    Raises
    ------
    PanoramaError
        Unreadable or truncated file, unknown format, not 2:1 (without ``resample``), NaN or
        infinite values, negative values beyond compression noise, or no light at all.
    """
    file = Path(path)
    suffix = file.suffix.lower()
    if suffix not in PANORAMA_SUFFIXES:
        raise PanoramaError(
            f"{file}: unknown image format {suffix!r}; use one of {PANORAMA_SUFFIXES}"
        )
    try:
        rgb = read_linear(file, transfer=transfer or "srgb")
    except ImageFileError as error:
        raise PanoramaError(str(error)) from error
    return panorama_from_array(rgb, source=str(path), resample=resample)


def adjust_panorama(panorama: Panorama, *, yaw_deg: float = 0.0, exposure: float = 1.0) -> Panorama:
    """Rotate an environment about ``+z`` and scale its radiance (the lighting controls).

    Parameters
    ----------
    panorama : Panorama
    yaw_deg : float
        Counter-clockwise rotation seen from above, degrees (light from azimuth phi then
        arrives from phi + yaw).
    exposure : float
        Radiance scale, > 0.
    """
    if not (np.isfinite(exposure) and exposure > 0):
        raise PanoramaError(
            f"{panorama.source}: exposure must be a positive number, got {exposure}"
        )
    if not np.isfinite(yaw_deg):
        raise PanoramaError(f"{panorama.source}: yaw must be a finite angle, got {yaw_deg}")
    rgb = panorama.rgb
    if yaw_deg % 360.0 != 0.0:
        rgb = rotate_panorama_yaw(rgb, yaw_deg)
    if exposure != 1.0:
        if float(panorama.rgb.max()) * exposure > MAX_RADIANCE:
            raise PanoramaError(
                f"{panorama.source}: exposure {exposure:g} takes its radiance to "
                f"{float(panorama.rgb.max()) * exposure:.3g}, above {MAX_RADIANCE:g} (the "
                "relighting sums would overflow); choose a smaller exposure"
            )
        rgb = rgb * np.float32(exposure)
    return replace(panorama, rgb=np.ascontiguousarray(rgb, dtype=np.float32))


def downsample_panorama(rgb: NDArray[np.floating], height: int) -> NDArray[np.float32]:
    """Pre-filter a panorama to ``height`` rows by solid-angle-weighted block means.

    Each output pixel holds the mean radiance of the input pixels it covers, weighted by their
    solid angle, so the solid-angle integral (the total light) is unchanged.

    Parameters
    ----------
    rgb : ndarray, shape (H, 2H, 3), linear radiance
    height : int, a divisor of H

    Returns
    -------
    ndarray, shape (height, 2 height, 3), float32
    """
    image = np.asarray(rgb, dtype=np.float64)
    rows = image.shape[0]
    if height < 1 or rows % height:
        raise InputError(f"the panorama's {rows} rows cannot be split into {height} equal blocks")
    factor = rows // height
    omega = panorama_solid_angles(rows, image.shape[1])
    shape = (height, factor, 2 * height, factor)
    energy = (image * omega[:, :, None]).reshape(*shape, 3).sum(axis=(1, 3))
    area = omega.reshape(shape).sum(axis=(1, 3))
    return (energy / area[:, :, None]).astype(np.float32)


def visible_environment(panorama: Panorama, below_horizon: BelowHorizon) -> Panorama:
    """The panorama as the captured object sees it: :func:`block_below_horizon` when blocked."""
    return block_below_horizon(panorama) if below_horizon == "blocked" else panorama


class VisibleEnvironments:
    """:func:`visible_environment` of the last panorama, kept while the same one lights.

    An engine relights many frames under one panorama (the viewer's drags, a sequence); the
    blocked copy is made once per panorama (by identity), so the caches keyed on the panorama
    downstream (a pre-filter) keep working.
    """

    def __init__(self, below_horizon: BelowHorizon) -> None:
        self.below_horizon = below_horizon
        self._last: tuple[Panorama, Panorama] | None = None

    def __call__(self, panorama: Panorama) -> Panorama:
        """The panorama as seen (see :func:`visible_environment`)."""
        if self._last is None or self._last[0] is not panorama:
            self._last = (panorama, visible_environment(panorama, self.below_horizon))
        return self._last[1]


def block_below_horizon(panorama: Panorama) -> Panorama:
    """The panorama with the light from below the horizon (rig ``z < 0``) removed.

    What a base, table or turntable under the object does to the environment (a capture that
    states ``below_horizon = "blocked"``, :data:`core.field_store.BELOW_HORIZON`). Rows wholly
    below the horizon become black; a row the horizon crosses (odd heights) keeps the share of
    its solid angle above it.
    """
    height = panorama.rgb.shape[0]
    top = np.pi * np.arange(height) / height
    bottom = np.pi * np.arange(1, height + 1) / height
    above = np.cos(top) - np.cos(np.minimum(bottom, np.pi / 2))
    share = np.clip(above / (np.cos(top) - np.cos(bottom)), 0.0, 1.0).astype(np.float32)
    if share.min() >= 1.0:
        return panorama
    rgb = panorama.rgb * share[:, None, None]
    return replace(panorama, rgb=np.ascontiguousarray(rgb, dtype=np.float32))

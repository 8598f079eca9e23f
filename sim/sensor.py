"""A photo sensor for the synthetic camera: linear radiance to the numbers a real camera records.

Off by default: the synthetic camera's output is noiseless linear radiance. With a
:class:`Sensor`, each pixel collects

    e = min(Poisson(L * sensitivity * exposure_s) + N(0, read_noise), full_well)   electrons
    DN = clip(round(black_level + e * gain), 0, white_level)

with gain = (white_level - black_level) / full_well DN per electron, so a saturated pixel reads
``white_level``. Every channel is sampled at every pixel (:func:`expose`); a Bayer sensor keeps
one channel per site (:func:`bayer_mosaic`). From the digital numbers come the outputs a capture
session meets: 8-bit sRGB (an ordinary photo), 16-bit linear, and the raw mosaic as a DNG
(:mod:`sim.sensor_files`), which the processing code decodes with a real RAW decoder (rawpy).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core.colour import linear_to_srgb
from core.errors import InputError

__all__ = [
    "BAYER_PATTERNS",
    "Sensor",
    "auto_exposure_time",
    "bayer_mosaic",
    "expose",
    "linear_from_dn",
    "radiance_from_dn",
    "to_linear16",
    "to_srgb8",
]

#: Colour (0 R, 1 G, 2 B) of the 2x2 CFA sites in row-major order: (0,0), (0,1), (1,0), (1,1).
BAYER_PATTERNS: dict[str, tuple[int, int, int, int]] = {
    "RGGB": (0, 1, 1, 2),
    "BGGR": (2, 1, 1, 0),
    "GRBG": (1, 0, 2, 1),
    "GBRG": (1, 2, 0, 1),
}


@dataclass(frozen=True)
class Sensor:
    """Parameters of a linear photo sensor (defaults: a 14-bit camera at ISO ~100).

    Attributes
    ----------
    exposure_s : float
        Exposure time, seconds.
    sensitivity : float
        Photo-electrons per second per unit of scene radiance (lens and quantum efficiency in
        one number). With the defaults a white Lambertian surface under unit irradiance
        (radiance 1/pi) fills about half the well.
    full_well : float
        Electrons at saturation.
    read_noise : float
        Read noise, electrons RMS.
    black_level, white_level : int
        Digital numbers of no light and of saturation.
    pattern : str
        Bayer pattern of the raw mosaic, one of :data:`BAYER_PATTERNS`.
    noise : bool
        False gives the expected digital numbers (rounded), for exact tests.
    """

    exposure_s: float = 1.0 / 60.0
    sensitivity: float = 1.9e6
    full_well: float = 20_000.0
    read_noise: float = 3.0
    black_level: int = 512
    white_level: int = 16_383
    pattern: str = "RGGB"
    noise: bool = True

    def __post_init__(self) -> None:
        for name in ("exposure_s", "sensitivity", "full_well"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"sensor {name} must be a positive number, got {value}")
        if not (math.isfinite(self.read_noise) and self.read_noise >= 0):
            raise InputError(f"sensor read_noise must be >= 0 electrons, got {self.read_noise}")
        if not 0 <= self.black_level < self.white_level <= 65_535:
            raise InputError(
                f"sensor levels must satisfy 0 <= black < white <= 65535, got black "
                f"{self.black_level}, white {self.white_level}"
            )
        if self.pattern not in BAYER_PATTERNS:
            raise InputError(
                f"unknown Bayer pattern {self.pattern!r}; use one of {', '.join(BAYER_PATTERNS)}"
            )

    @property
    def gain(self) -> float:
        """Digital numbers per electron."""
        return (self.white_level - self.black_level) / self.full_well

    @property
    def saturation_radiance(self) -> float:
        """Scene radiance that just fills the well at this exposure."""
        return self.full_well / (self.sensitivity * self.exposure_s)


def expose(
    rgb: NDArray[np.floating], sensor: Sensor, seed: int | np.random.Generator = 0
) -> NDArray[np.uint16]:
    """Record linear radiance as digital numbers, every channel at every pixel.

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3), linear radiance >= 0
    sensor : Sensor
    seed : int or numpy Generator
        Noise seed: the same seed gives the same image (captures are reproducible per pose).

    Returns
    -------
    ndarray, shape (H, W, 3), uint16 digital numbers in [0, white_level]
    """
    radiance = np.asarray(rgb, dtype=np.float64)
    if radiance.ndim != 3 or radiance.shape[2] != 3:
        raise InputError(f"expected an (H, W, 3) radiance image, got shape {radiance.shape}")
    if not np.isfinite(radiance).all() or (radiance < 0).any():
        raise InputError("radiance must be finite and non-negative to be exposed")
    mean_electrons = radiance * (sensor.sensitivity * sensor.exposure_s)
    rng = np.random.default_rng(seed)
    if sensor.noise:
        # Poisson counts above the well cannot be stored anyway; capping the mean keeps the
        # sampler's argument bounded for very bright suns.
        electrons = rng.poisson(np.minimum(mean_electrons, 4.0 * sensor.full_well)).astype(
            np.float64
        )
        electrons += rng.normal(0.0, sensor.read_noise, size=electrons.shape)
    else:
        electrons = mean_electrons
    # The converter's range ends at the full well, so saturated pixels read exactly white.
    electrons = np.minimum(electrons, sensor.full_well)
    dn = np.rint(sensor.black_level + electrons * sensor.gain)
    return np.clip(dn, 0, sensor.white_level).astype(np.uint16)


def bayer_mosaic(dn: NDArray[np.uint16], pattern: str = "RGGB") -> NDArray[np.uint16]:
    """Keep one channel per site as a Bayer colour filter array does.

    Parameters
    ----------
    dn : ndarray, shape (H, W, 3), H and W even
    pattern : str, one of :data:`BAYER_PATTERNS`

    Returns
    -------
    ndarray, shape (H, W), same dtype
    """
    if pattern not in BAYER_PATTERNS:
        raise InputError(
            f"unknown Bayer pattern {pattern!r}; use one of {', '.join(BAYER_PATTERNS)}"
        )
    height, width = dn.shape[:2]
    if height % 2 or width % 2:
        raise InputError(f"a Bayer mosaic needs an even image size, got {width}x{height}")
    mosaic = np.empty((height, width), dtype=dn.dtype)
    for site, channel in enumerate(BAYER_PATTERNS[pattern]):
        row, col = divmod(site, 2)
        mosaic[row::2, col::2] = dn[row::2, col::2, channel]
    return mosaic


def linear_from_dn(dn: NDArray[np.integer], sensor: Sensor) -> NDArray[np.float32]:
    """Black-subtracted digital numbers scaled so saturation is 1 (may dip below 0 from noise)."""
    span = sensor.white_level - sensor.black_level
    return ((np.asarray(dn, dtype=np.float32) - sensor.black_level) / span).astype(np.float32)


def radiance_from_dn(dn: NDArray[np.integer], sensor: Sensor) -> NDArray[np.float32]:
    """Invert :func:`expose` in expectation: digital numbers back to scene radiance."""
    return (linear_from_dn(dn, sensor) * sensor.saturation_radiance).astype(np.float32)


def to_linear16(dn: NDArray[np.integer], sensor: Sensor) -> NDArray[np.uint16]:
    """16-bit linear output: 0 is black, 65535 is saturation (noise below black is clipped)."""
    scaled = np.rint(np.clip(linear_from_dn(dn, sensor), 0.0, 1.0) * 65535.0)
    return scaled.astype(np.uint16)


def to_srgb8(dn: NDArray[np.integer], sensor: Sensor) -> NDArray[np.uint8]:
    """8-bit sRGB output, as an ordinary photo: saturation maps to 255."""
    return np.rint(linear_to_srgb(linear_from_dn(dn, sensor)) * 255.0).astype(np.uint8)


def auto_exposure_time(
    rgb: NDArray[np.floating],
    sensor: Sensor,
    mask: NDArray[np.bool_] | None = None,
    percentile: float = 99.0,
    target: float = 0.8,
) -> float:
    """Exposure time that puts the ``percentile`` of the brightest channel at ``target`` well.

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3), linear radiance
    sensor : Sensor (its sensitivity and full well are used)
    mask : ndarray, shape (H, W), bool, optional
        Pixels that count (for example the object's coverage).
    percentile, target : float
        Percent in (0, 100] and fraction of the full well in (0, 1].

    Returns
    -------
    float, seconds
    """
    if not (0 < percentile <= 100 and 0 < target <= 1):
        raise InputError(
            f"need 0 < percentile <= 100 and 0 < target <= 1, got {percentile}, {target}"
        )
    peak = np.asarray(rgb, dtype=np.float64).max(axis=2)
    values = peak[mask] if mask is not None else peak.ravel()
    level = float(np.percentile(values, percentile)) if values.size else 0.0
    if level <= 0:
        raise InputError("the image has no light to expose for")
    return target * sensor.full_well / (sensor.sensitivity * level)

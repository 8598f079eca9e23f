"""Light intensity and falloff from a white Lambertian target.

A flat white target of known albedo rho lies at the object's place, face up. Under one light it
has radiance

    L(x) = rho / pi  E0  g(x),    g(x) = cos(theta(x))                 (distant light)
                                  g(x) = D^2 cos(theta(x)) / r(x)^2    (point light at D)

with E0 the irradiance the light delivers at the origin on a surface facing it, theta the angle
of incidence at x and r the distance from the light to x. Every target pixel the calibrated
camera sees gives one equation, and the least-squares E0 is the light's intensity. For point
lights the falloff exponent p of ``E ~ 1 / r^p`` is fitted too, from ``log(L / cos)`` against
``log r`` (2 for an ideal point light; a bare LED in a reflector or a diffuser shows less).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.calibrated_camera import CalibratedCamera, as_calibrated
from core.camera_model import PinholeCamera
from core.directions import normalize
from core.errors import InputError
from processing.calibration import ImageInput, linear_luminance, load_image

__all__ = ["LightIntensities", "WhiteReference", "light_intensity_and_falloff"]

F64 = NDArray[np.float64]
#: Pixels whose incidence cosine is below this are left out: grazing light magnifies any error
#: in the target's flatness or the light's direction.
MIN_COSINE = 0.1


@dataclass(frozen=True)
class WhiteReference:
    """A flat square white target, face up (normal ``+z``), at ``centre`` in the rig frame.

    Attributes
    ----------
    albedo : float, diffuse reflectance in (0, 1]
    half_size : float, half its side, scene units
    centre : (x, y, z)
    margin : float, fraction of the half side left out at the edges (mixed pixels, curl)
    """

    albedo: float = 0.8
    half_size: float = 1.5
    centre: tuple[float, float, float] = (0.0, 0.0, 0.0)
    margin: float = 0.05

    def __post_init__(self) -> None:
        if not 0 < self.albedo <= 1 or not self.half_size > 0 or not 0 <= self.margin < 1:
            raise InputError(f"invalid white reference {self}")


@dataclass(frozen=True)
class LightIntensities:
    """What :func:`light_intensity_and_falloff` measures; arrays of shape (T,), float64.

    Attributes
    ----------
    relative : intensities over their mean (what relighting divides the field by)
    irradiance : E0, irradiance at the origin on a surface facing the light, in the images'
        linear units (for 16-bit images: 65535 = 1) given the target's albedo
    falloff_exponent : fitted p of E ~ 1 / r^p for point lights; NaN for distant lights
    residual : RMS relative residual of the model over the target's pixels
    pixels : number of target pixels used
    """

    relative: F64
    irradiance: F64
    falloff_exponent: F64
    residual: F64
    pixels: NDArray[np.int64]


def _target_pixels(
    camera: CalibratedCamera, target: WhiteReference, step: int
) -> tuple[NDArray[np.intp], NDArray[np.intp], F64]:
    """Rows, cols and rig points (N, 3) of the pixel centres that see the target."""
    rows, cols = np.mgrid[0 : camera.intrinsics.height : step, 0 : camera.intrinsics.width : step]
    rows, cols = rows.ravel(), cols.ravel()
    rays = camera.rays(cols + 0.5, rows + 0.5)
    centre = np.asarray(target.centre, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        along = (centre[2] - camera.position[2]) / rays[:, 2]
    ahead = np.isfinite(along) & (along > 0)
    points = camera.position + np.where(ahead, along, 0.0)[:, None] * rays
    reach = target.half_size * (1.0 - target.margin)
    inside = (
        ahead
        & (np.abs(points[:, 0] - centre[0]) <= reach)
        & (np.abs(points[:, 1] - centre[1]) <= reach)
    )
    return rows[inside], cols[inside], points[inside]


def light_intensity_and_falloff(
    images: Sequence[ImageInput],
    camera: CalibratedCamera | PinholeCamera,
    directions: ArrayLike,
    *,
    distances: ArrayLike | None = None,
    target: WhiteReference | None = None,
    names: Sequence[str] | None = None,
    step: int = 2,
    saturation: float = 0.98,
) -> LightIntensities:
    """Each light's intensity (and falloff) from images of a white target.

    Parameters
    ----------
    images : sequence of T arrays (H, W) or (H, W, 3) or paths, one light each
        uint8 is sRGB-decoded, uint16 (65535 = 1) and floats are linear.
    camera : CalibratedCamera or PinholeCamera, the camera that took them
    directions : array_like (T, 3), toward the lights (from the mirror sphere)
    distances : array_like (T,) or float, optional
        Point lights at these distances from the origin; None for distant lights.
    target : WhiteReference, optional (default: albedo 0.8, half side 1.5, at the origin)
    names : sequence of str, optional, how errors name the images
    step : int, use every ``step``-th pixel in each direction
    saturation : float
        Integer images: pixels at or above this fraction of full scale are left out.

    Returns
    -------
    LightIntensities
    """
    cam = as_calibrated(camera)
    ref = target or WhiteReference()
    towards = normalize(directions).reshape(-1, 3)
    count = len(images)
    if len(towards) != count:
        raise InputError(f"got {len(towards)} light directions for {count} images")
    labels = [f"white-target image {i}" for i in range(count)] if names is None else list(names)
    if len(labels) != count:
        raise InputError(f"got {len(labels)} names for {count} images")
    if distances is None:
        reach = np.full(count, np.nan)
    else:
        reach = np.broadcast_to(np.asarray(distances, dtype=np.float64), (count,)).copy()
        if not (np.isfinite(reach) & (reach > 0)).all():
            raise InputError(f"light distances must be positive, got {reach}")
    rows, cols, points = _target_pixels(cam, ref, step)
    if len(rows) < 10:
        raise InputError("the white target covers almost none of the camera's view")
    irradiance = np.empty(count)
    exponent = np.full(count, np.nan)
    residual = np.empty(count)
    used = np.empty(count, dtype=np.int64)
    for t, (image, label) in enumerate(zip(images, labels, strict=True)):
        array = load_image(image, label)
        if (array.shape[1], array.shape[0]) != (cam.intrinsics.width, cam.intrinsics.height):
            raise InputError(
                f"{label}: size {array.shape[1]}x{array.shape[0]} differs from the camera's"
            )
        radiance = linear_luminance(array, label)[rows, cols]
        if np.issubdtype(array.dtype, np.integer):
            unsaturated = radiance < saturation
        else:
            unsaturated = np.ones(len(radiance), dtype=bool)
        if math.isnan(reach[t]):
            cosine = np.full(len(points), towards[t, 2])
            distance = np.ones(len(points))
            geometry = cosine
        else:
            offset = reach[t] * towards[t] - points
            distance = np.linalg.norm(offset, axis=1)
            cosine = offset[:, 2] / distance
            geometry = cosine * reach[t] ** 2 / distance**2
        keep = unsaturated & (cosine > MIN_COSINE)
        if keep.sum() < 10:
            raise InputError(
                f"{label}: the light barely reaches the white target (or saturates it); "
                f"{int(keep.sum())} usable pixels"
            )
        g, value = geometry[keep], radiance[keep] * math.pi / ref.albedo
        irradiance[t] = float(value @ g / (g @ g))
        if irradiance[t] <= 0:
            raise InputError(f"{label}: the white target is black under this light")
        residual[t] = math.sqrt(float(np.mean((value - irradiance[t] * g) ** 2))) / irradiance[t]
        used[t] = int(keep.sum())
        if not math.isnan(reach[t]):
            exponent[t] = _falloff_exponent(value / cosine[keep], distance[keep])
    return LightIntensities(
        relative=irradiance / irradiance.mean(),
        irradiance=irradiance,
        falloff_exponent=exponent,
        residual=residual,
        pixels=used,
    )


def _falloff_exponent(value: F64, distance: F64) -> float:
    """The exponent p of ``value ~ distance^-p`` by least squares on logarithms.

    NaN without spread in r (``distance``) or with fewer than 10 positive values.
    """
    good = value > 0
    log_r = np.log(distance[good])
    if len(log_r) < 10 or np.ptp(log_r) < 1e-3:
        return math.nan
    slope = np.polyfit(log_r, np.log(value[good]), 1)[0]
    return float(-slope)

"""The reflectance lobe: diffuse plus GGX, the one definition the simulator and the fits share.

    f(wi, wo) = rho_d / pi + F0 D(h) G(wi, wo) / (4 cos(theta_i) cos(theta_o))

- h = normalize(wi + wo), the half vector; cos(theta) are dot products with the normal n.
- D: the GGX (Trowbridge-Reitz) distribution of roughness alpha,
  D(h) = alpha^2 / (pi ((n.h)^2 (alpha^2 - 1) + 1)^2).
- G: the separable Smith masking-shadowing for GGX, G = G1(wi) G1(wo),
  G1(v) = 2 (n.v) / ((n.v) + sqrt(alpha^2 + (1 - alpha^2) (n.v)^2)).
- F0: a constant RGB reflectance (no angular Fresnel term); rho_d: RGB diffuse albedo.
  Lambertian is F0 = 0.

Zero when either direction is below the surface. A ``blendbsdf`` averages its two BSDFs, so in
Mitsuba 3 the sum is a blend of weight 0.5 of ``diffuse`` (reflectance 2 rho_d) and
``roughconductor`` (``distribution: ggx``, ``alpha``, ``material: none``,
``specular_reflectance: 2 F0``), which evaluates the same D and separable Smith G (checked in
the Mitsuba sources and by the comparison in ``tests/sim/test_mitsuba_reference.py``; the
reflectances are ``srgb`` textures with ``unbounded: true``, since 2 rho_d may exceed 1).

The numba kernels that shade (the simulator's camera and ground truth, the per-sample models'
relighting) call :func:`shade_light`, the sum f(wi, wo) cos(theta_i) of one light at one
sample; the split-sum tables of the precomputed lighting and the per-sample fits use its parts
(:func:`half_vector_cosine`, :func:`specular_lobe`).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "brdf",
    "cosine",
    "ggx_distribution",
    "half_vector_cosine",
    "shade_light",
    "smith_g1",
    "specular_lobe",
    "toward_eye",
]

#: A direction or an RGB triple as the numba kernels pass it: three floats.
Triple = tuple[float, float, float]


def ggx_distribution(cos_h: ArrayLike, alpha: ArrayLike) -> NDArray[np.float64]:
    """GGX normal distribution D for cos(normal, half vector); broadcast; 1/sr."""
    c = np.asarray(cos_h, dtype=np.float64)
    a2 = np.asarray(alpha, dtype=np.float64) ** 2
    denominator = np.pi * (c * c * (a2 - 1.0) + 1.0) ** 2
    return np.where(c > 0, a2 / denominator, 0.0)


def smith_g1(cos_v: ArrayLike, alpha: ArrayLike) -> NDArray[np.float64]:
    """Smith masking G1 for GGX of a direction with cos(normal, v) = ``cos_v``; broadcast."""
    c = np.asarray(cos_v, dtype=np.float64)
    a2 = np.asarray(alpha, dtype=np.float64) ** 2
    root = np.sqrt(a2 + (1.0 - a2) * c * c)
    return np.where(c > 0, 2.0 * c / np.maximum(c + root, 1e-300), 0.0)


def brdf(
    normals: ArrayLike,
    wi: ArrayLike,
    wo: ArrayLike,
    rho_d: ArrayLike,
    f0: ArrayLike,
    alpha: ArrayLike,
) -> NDArray[np.float64]:
    """Evaluate f(wi, wo) per RGB channel, 1/sr.

    Parameters
    ----------
    normals, wi, wo : array_like, shape (..., 3), unit vectors (light and view point away)
    rho_d, f0 : array_like, shape (..., 3)
    alpha : array_like, shape (...)

    Returns
    -------
    ndarray, shape (..., 3), float64; zero where wi or wo is below the surface
    """
    n, i, o = np.broadcast_arrays(
        np.asarray(normals, dtype=np.float64),
        np.asarray(wi, dtype=np.float64),
        np.asarray(wo, dtype=np.float64),
    )
    cos_i = np.einsum("...k,...k->...", n, i)
    cos_o = np.einsum("...k,...k->...", n, o)
    half = i + o
    length = np.sqrt(np.einsum("...k,...k->...", half, half))
    cos_h = np.einsum("...k,...k->...", n, half) / np.maximum(length, 1e-300)
    a = np.asarray(alpha, dtype=np.float64)
    lit = (cos_i > 0) & (cos_o > 0)
    safe = np.where(lit, 4.0 * cos_i * cos_o, 1.0)
    specular = ggx_distribution(cos_h, a) * smith_g1(cos_i, a) * smith_g1(cos_o, a) / safe
    value = np.asarray(rho_d, dtype=np.float64) / np.pi + np.asarray(f0) * specular[..., None]
    return np.where(lit[..., None], value, 0.0)


@numba.njit(cache=True, inline="always")
def specular_lobe(cos_i: float, cos_o: float, cos_h: float, alpha: float) -> float:
    """D(h) G(wi, wo) / (4 cos_i cos_o) for one pair of directions above the surface (1/sr).

    The scalar form of :func:`brdf`'s specular part for the numba kernels (:func:`shade_light`,
    the per-sample fits, the precomputed lighting's tables; tests hold it equal to
    :func:`brdf`); ``cos_i`` and ``cos_o`` must be positive.
    """
    if cos_h <= 0.0:
        return 0.0
    a2 = alpha * alpha
    t = cos_h * cos_h * (a2 - 1.0) + 1.0
    g1_i = 2.0 * cos_i / (cos_i + math.sqrt(a2 + (1.0 - a2) * cos_i * cos_i))
    g1_o = 2.0 * cos_o / (cos_o + math.sqrt(a2 + (1.0 - a2) * cos_o * cos_o))
    return a2 / (math.pi * t * t) * g1_i * g1_o / (4.0 * cos_i * cos_o)


@numba.njit(cache=True, inline="always")
def cosine(normal: Triple, direction: Triple) -> float:
    """cos(theta) = n . w of two unit vectors, for the numba kernels (x, y, z summed in order).

    Parameters
    ----------
    normal, direction : tuple of 3 floats, unit vectors

    Returns
    -------
    float, in [-1, 1]
    """
    return normal[0] * direction[0] + normal[1] * direction[1] + normal[2] * direction[2]


@numba.njit(cache=True, inline="always")
def half_vector_cosine(normal: Triple, wi: Triple, wo: Triple) -> float:
    """cos(theta_h): the normal against the half vector h = normalize(wi + wo) (numba).

    Parameters
    ----------
    normal, wi, wo : tuple of 3 floats, unit vectors (light ``wi`` and view ``wo`` point away
        from the surface)

    Returns
    -------
    float, in [-1, 1] (wi = -wo, where h is undefined, gives 0)
    """
    hx, hy, hz = wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]
    length = max(math.sqrt(hx * hx + hy * hy + hz * hz), 1e-300)
    return (normal[0] * hx + normal[1] * hy + normal[2] * hz) / length


@numba.njit(cache=True, inline="always")
def shade_light(
    normal: Triple,
    wi: Triple,
    wo: Triple,
    rho_d: Triple,
    f0: Triple,
    alpha: float,
    with_lobe: bool,
) -> Triple:
    """The shading of one light at one sample: f(wi, wo) max(0, n . wi), per RGB channel.

    The numba form of :func:`brdf` times the cosine, (rho_d / pi + F0 S(wi, wo)) cos(theta_i),
    that every shading kernel calls (the simulator's camera and ground truth, the per-sample
    models' relighting; tests hold it equal to :func:`brdf`). Multiplied by a light's
    irradiance at normal incidence (or radiance x sr), it is the radiance the light reflects
    toward ``wo``.

    Parameters
    ----------
    normal, wi, wo : tuple of 3 floats, unit vectors (light ``wi`` and view ``wo`` point away
        from the surface)
    rho_d, f0 : tuple of 3 floats, diffuse albedo and F0, RGB (tuples, not array rows: the
        kernels' loops then keep them in registers)
    alpha : float, GGX roughness, > 0 (read only ``with_lobe``)
    with_lobe : bool
        False: the diffuse term alone (a Lambertian fit, whose F0 and alpha are not used).

    Returns
    -------
    tuple of 3 floats, 1/sr; zero when ``wi`` or ``wo`` is below the surface
    """
    cos_i = cosine(normal, wi)
    cos_o = cosine(normal, wo)
    if cos_i <= 0.0 or cos_o <= 0.0:
        return 0.0, 0.0, 0.0
    if not with_lobe:
        return (
            rho_d[0] / math.pi * cos_i,
            rho_d[1] / math.pi * cos_i,
            rho_d[2] / math.pi * cos_i,
        )
    specular = specular_lobe(cos_i, cos_o, half_vector_cosine(normal, wi, wo), alpha)
    return (
        (rho_d[0] / math.pi + f0[0] * specular) * cos_i,
        (rho_d[1] / math.pi + f0[1] * specular) * cos_i,
        (rho_d[2] / math.pi + f0[2] * specular) * cos_i,
    )


@numba.njit(cache=True, inline="always")
def toward_eye(
    points: NDArray[np.floating], p: int, eye: NDArray[np.float64], distant: bool
) -> Triple:
    """Unit direction from sample ``p`` toward the eye, for the shading kernels.

    ``distant``: ``eye`` is that direction already (a pixel field's camera); else the eye's
    position, and the direction is from ``points[p]`` to it (float32 points are widened, as
    ``float()`` would). The one view direction of the shading kernels, the fits' and the
    camera blend's.
    """
    if distant:
        return eye[0], eye[1], eye[2]
    vx, vy, vz = eye[0] - points[p, 0], eye[1] - points[p, 1], eye[2] - points[p, 2]
    length = math.sqrt(vx * vx + vy * vy + vz * vz)
    return vx / length, vy / length, vz / length

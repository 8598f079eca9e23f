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
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["brdf", "ggx_distribution", "smith_g1", "specular_lobe", "toward_eye"]


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

    The scalar form of :func:`brdf`'s specular part for the numba kernels (the simulator's
    shading, the per-sample fits and their relighting; tests hold it equal to :func:`brdf`);
    ``cos_i`` and ``cos_o`` must be positive.
    """
    if cos_h <= 0.0:
        return 0.0
    a2 = alpha * alpha
    t = cos_h * cos_h * (a2 - 1.0) + 1.0
    g1_i = 2.0 * cos_i / (cos_i + math.sqrt(a2 + (1.0 - a2) * cos_i * cos_i))
    g1_o = 2.0 * cos_o / (cos_o + math.sqrt(a2 + (1.0 - a2) * cos_o * cos_o))
    return a2 / (math.pi * t * t) * g1_i * g1_o / (4.0 * cos_i * cos_o)


@numba.njit(cache=True, inline="always")
def toward_eye(
    points: NDArray[np.float64], p: int, eye: NDArray[np.float64], distant: bool
) -> tuple[float, float, float]:
    """Unit direction from sample ``p`` toward the eye, for the shading kernels.

    ``distant``: ``eye`` is that direction already (a pixel field's camera); else the eye's
    position, and the direction is from ``points[p]`` to it.
    """
    if distant:
        return eye[0], eye[1], eye[2]
    vx, vy, vz = eye[0] - points[p, 0], eye[1] - points[p, 1], eye[2] - points[p, 2]
    length = math.sqrt(vx * vx + vy * vy + vz * vz)
    return vx / length, vy / length, vz / length

"""Per-sample models relit at frame rate: what depends on the samples is computed once.

The exact model relighting (:func:`render.engines.model_shading.relight_models`) sums every
light of a 64 x 128 grid for every sample: about 2 s per lighting at 50,000 points. Here the
sum is split the way real-time renderers split it, so that a new yaw or exposure costs a few
small dot products per sample:

    L_p = rho_d / pi  sum_d cos_d V_d E_d  +  F0  sum_d S(w_d, v) cos_d V_d E_d

- **Diffuse, with the shadow marks**: the sample's transfer t_p(w) = max(0, n_p . w) V_p(w) and
  the lighting are projected onto real spherical harmonics of bands 0..``BANDS - 1``; the sum
  is their dot product, sum_k t_pk e_k (precomputed radiance transfer). t_p is computed once per
  field over a direction grid; e once per panorama, and a yaw rotates it (each band's
  (cos m phi, sin m phi) pairs turn by m yaw): no re-projection.
- **Specular, split sum**: sum_d S cos V E ~= V_p(R) * Lbar(R, alpha) * A(n . v, alpha), with R
  the mirror direction, Lbar the panorama averaged under the GGX lobe centred on R (pre-filtered
  once per panorama for :data:`ALPHAS`, looked up at R turned back by the yaw), A the lobe's
  directional albedo (a table), and V_p(R) the shadow marks at R, from their own harmonics.

Exposure scales the result. What the split costs in accuracy is measured against the exact
grid sum per material (``python -m bench.interactive``; ``docs/relighting.md``). Linear-basis
models (PTM, HSH) need no split: their lighting is B_k summed over the rotated grid lights.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numba
import numpy as np
from numpy.typing import NDArray

from core.brdf import cosine, half_vector_cosine, specular_lobe, toward_eye
from core.colour import REC709_LUMINANCE
from core.directions import (
    panorama_bilinear_cell,
    panorama_directions,
    panorama_solid_angles,
)
from core.errors import InputError
from core.light_set import LightSet, grid_lights
from processing.interpolation import interpolation_weights

__all__ = [
    "ALPHAS",
    "BANDS",
    "BRIGHT_LIGHTS",
    "LIGHT_GRID",
    "PanoramaPrefilter",
    "SampleTransfer",
    "lobe_albedo",
    "prefilter_panorama",
    "rotate_sh_yaw",
    "sample_transfer",
    "sh_basis",
    "sh_norms",
    "shade_precomputed",
]

#: Spherical-harmonic bands of the diffuse transfer and the shadow marks (bands 0..4: 25
#: coefficients per sample).
BANDS = 5
#: GGX roughness levels of the pre-filtered panorama (interpolated between, clamped outside).
ALPHAS = (0.03, 0.06, 0.1, 0.15, 0.22, 0.32, 0.45, 0.65, 1.0)
#: Rows of the pre-filtered panorama (2 x as many columns).
PREFILTER_HEIGHT = 32
#: Rows of the direction grid the transfer is integrated over (2 x as many columns).
TRANSFER_HEIGHT = 24
#: Rows of the grid the panorama is summed into, as the exact reference's (2 x as many columns).
LIGHT_GRID = 64
#: Cosines of the view angle in the albedo table.
ALBEDO_COSINES = 48
#: Samples per block of the shading loop (one scratch allocation each).
BLOCK = 512
#: Grid blocks summed exactly, the most luminous (measured: ``python -m bench.interactive``).
BRIGHT_LIGHTS = 32
#: The normal of the frame the lobe's albedo is tabulated in.
_UP = (0.0, 0.0, 1.0)


@lru_cache(maxsize=4)
def sh_norms(bands: int = BANDS) -> NDArray[np.float64]:
    """K_lm = sqrt((2l + 1) / 4 pi (l - m)! / (l + m)!), times sqrt 2 for m > 0; (bands, bands)."""
    norms = np.zeros((bands, bands))
    for degree in range(bands):
        for m in range(degree + 1):
            ratio = math.factorial(degree - m) / math.factorial(degree + m)
            norms[degree, m] = math.sqrt((2 * degree + 1) / (4 * math.pi) * ratio)
            if m > 0:
                norms[degree, m] *= math.sqrt(2.0)
    return norms


@numba.njit(cache=True, inline="always")
def _sh_eval(
    x: float, y: float, z: float, norms: NDArray[np.float64], out: NDArray[np.float64]
) -> None:
    # Real spherical harmonics Y_lm at a unit direction, index l (l + 1) + m: associated
    # Legendre functions by the standard recurrences in cos(theta) = z, with sin^m(theta)
    # cos(m phi) and sin^m(theta) sin(m phi) by the recurrence of complex powers of x + iy;
    # ``norms`` from :func:`sh_norms`.
    bands = norms.shape[0]
    c_m, s_m = 1.0, 0.0  # sin^m(theta) (cos m phi, sin m phi)
    p_mm = 1.0  # P_m^m / sin^m(theta), with the Condon-Shortley sign
    for m in range(bands):
        if m > 0:
            c_m, s_m = c_m * x - s_m * y, c_m * y + s_m * x
            p_mm *= -(2.0 * m - 1.0)
        p_prev2, p_prev = 0.0, p_mm
        for degree in range(m, bands):
            if degree == m:
                p = p_mm
            elif degree == m + 1:
                p = z * (2.0 * m + 1.0) * p_mm
            else:
                p = ((2.0 * degree - 1.0) * z * p_prev - (degree + m - 1.0) * p_prev2) / (
                    degree - m
                )
            if degree > m:
                p_prev2, p_prev = p_prev, p
            centre = degree * (degree + 1)
            if m == 0:
                out[centre] = norms[degree, 0] * p
            else:
                out[centre + m] = norms[degree, m] * p * c_m
                out[centre - m] = norms[degree, m] * p * s_m


@numba.njit(cache=True, parallel=True)
def _sh_rows(
    directions: NDArray[np.float64], norms: NDArray[np.float64], out: NDArray[np.float64]
) -> None:
    for i in numba.prange(directions.shape[0]):
        _sh_eval(directions[i, 0], directions[i, 1], directions[i, 2], norms, out[i])


def sh_basis(directions: NDArray[np.floating], bands: int = BANDS) -> NDArray[np.float64]:
    """Real spherical harmonics of bands 0..``bands - 1`` at unit directions.

    Parameters
    ----------
    directions : ndarray, shape (N, 3), unit vectors in the rig frame (z up)
    bands : int, >= 1

    Returns
    -------
    ndarray, shape (N, bands^2), float64; column l (l + 1) + m is Y_lm (orthonormal over the
    sphere; m > 0 the cos(m phi) functions, m < 0 the sin(|m| phi) ones)
    """
    d = np.ascontiguousarray(directions, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] != 3:
        raise InputError(f"directions must have shape (N, 3), got {d.shape}")
    if bands < 1:
        raise InputError(f"bands must be at least 1, got {bands}")
    out = np.zeros((len(d), bands * bands))
    _sh_rows(d, sh_norms(bands), out)
    return out


def rotate_sh_yaw(coefficients: NDArray[np.floating], yaw_deg: float) -> NDArray[np.float64]:
    """Coefficients (B, C) of a function turned ``yaw_deg`` counter-clockwise about +z.

    The function's value from azimuth phi moves to phi + yaw (the panorama's yaw control):
    each band's pair (a cos m phi + b sin m phi) becomes a' = a cos m yaw - b sin m yaw,
    b' = a sin m yaw + b cos m yaw.
    """
    c = np.asarray(coefficients, dtype=np.float64)
    bands = math.isqrt(c.shape[0])
    if bands * bands != c.shape[0]:
        raise InputError(f"{c.shape[0]} coefficients are not a whole number of bands")
    out = c.copy()
    yaw = math.radians(yaw_deg)
    for degree in range(bands):
        centre = degree * (degree + 1)
        for m in range(1, degree + 1):
            a, b = c[centre + m], c[centre - m]
            cos, sin = math.cos(m * yaw), math.sin(m * yaw)
            out[centre + m] = a * cos - b * sin
            out[centre - m] = a * sin + b * cos
    return out


@numba.njit(cache=True, parallel=True)
def _prefilter(
    outputs: NDArray[np.float64],
    directions: NDArray[np.float64],
    rgb: NDArray[np.float64],
    omega: NDArray[np.float64],
    alphas: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:
    # With n = v = R (the split sum's assumption): each output direction's lobe-weighted mean
    # radiance sum(S cos E) / sum(S cos omega), for every roughness. S cos is the specular
    # part of core.brdf.shade_light (its half-vector cosine and lobe), with cos_o = 1 exactly
    # (n = v), the half vector's cosine found once for every roughness.
    for o in numba.prange(outputs.shape[0]):
        mirror = (outputs[o, 0], outputs[o, 1], outputs[o, 2])
        weight = np.zeros(alphas.shape[0])
        light = np.zeros((alphas.shape[0], 3))
        for d in range(directions.shape[0]):
            towards = (directions[d, 0], directions[d, 1], directions[d, 2])
            cos_i = cosine(mirror, towards)
            if cos_i <= 0.0:
                continue
            cos_h = half_vector_cosine(mirror, towards, mirror)
            for a in range(alphas.shape[0]):
                w = specular_lobe(cos_i, 1.0, cos_h, alphas[a]) * cos_i
                weight[a] += w * omega[d]
                light[a, 0] += w * rgb[d, 0]
                light[a, 1] += w * rgb[d, 1]
                light[a, 2] += w * rgb[d, 2]
        for a in range(alphas.shape[0]):
            if weight[a] > 0.0:
                out[a, o, 0] = light[a, 0] / weight[a]
                out[a, o, 1] = light[a, 1] / weight[a]
                out[a, o, 2] = light[a, 2] / weight[a]


@dataclass(frozen=True)
class PanoramaPrefilter:
    """What a panorama contributes, at yaw 0 and exposure 1.

    Attributes
    ----------
    lights : LightSet, the panorama summed into the :data:`LIGHT_GRID` grid (non-empty blocks)
    bright : LightSet, its :data:`BRIGHT_LIGHTS` most luminous blocks, summed exactly
    sh : ndarray, shape (BANDS^2, 3), float64, the harmonics of the other blocks
        (radiance x sr)
    specular : ndarray, shape (len(ALPHAS), PREFILTER_HEIGHT, 2 PREFILTER_HEIGHT, 3), float32,
        the other blocks' radiance averaged under the GGX lobe of each roughness around each
        direction
    """

    lights: LightSet
    bright: LightSet
    sh: NDArray[np.float64]
    specular: NDArray[np.float32]


def prefilter_panorama(rgb: NDArray[np.floating], bright: int | None = None) -> PanoramaPrefilter:
    """Pre-filter a panorama (H, 2H, 3) of linear radiance for :func:`shade_precomputed`.

    The ``bright`` most luminous grid blocks are kept apart, to
    be summed exactly: a sun or a lamp is where harmonics ring and the split sum's lobe, centred
    on the mirror direction, is most wrong at grazing views.
    """
    lights = grid_lights(np.asarray(rgb), LIGHT_GRID).nonempty()
    assert lights.solid_angle_sr is not None  # grid lights know their blocks
    order = np.argsort(-(lights.rgb @ REC709_LUMINANCE.astype(np.float64)), kind="stable")
    kept, rest = order[:bright], order[bright:]
    sh = sh_basis(lights.directions[rest]).T @ lights.rgb[rest]
    height = PREFILTER_HEIGHT
    outputs = panorama_directions(height, 2 * height).reshape(-1, 3)
    specular = np.zeros((len(ALPHAS), len(outputs), 3))
    _prefilter(
        np.ascontiguousarray(outputs), np.ascontiguousarray(lights.directions[rest]),
        np.ascontiguousarray(lights.rgb[rest]),
        np.ascontiguousarray(lights.solid_angle_sr[rest]), np.asarray(ALPHAS), specular,
    )  # fmt: skip
    brightest = LightSet(lights.directions[kept], lights.rgb[kept], lights.solid_angle_sr[kept])
    maps = specular.reshape(len(ALPHAS), height, 2 * height, 3).astype(np.float32)
    return PanoramaPrefilter(lights, brightest, sh, maps)


@numba.njit(cache=True, parallel=True)
def _albedo(
    alphas: NDArray[np.float64], cosines: NDArray[np.float64], out: NDArray[np.float64]
) -> None:
    # The specular part of core.brdf.shade_light (its half-vector cosine and lobe) times the
    # cosine, integrated over the light directions, in the surface's frame: normal +z, the
    # view in the xz plane.
    rows, cols = 256, 256
    for c in numba.prange(cosines.shape[0]):
        cos_o = cosines[c]
        view = (math.sqrt(max(0.0, 1.0 - cos_o * cos_o)), 0.0, cos_o)
        for i in range(rows):
            theta = (i + 0.5) * 0.5 * math.pi / rows
            cos_i, sin_i = math.cos(theta), math.sin(theta)
            omega = sin_i * (0.5 * math.pi / rows) * (2.0 * math.pi / cols)
            for j in range(cols):
                phi = (j + 0.5) * 2.0 * math.pi / cols
                towards = (sin_i * math.cos(phi), sin_i * math.sin(phi), cos_i)
                cos_h = half_vector_cosine(_UP, towards, view)
                for a in range(alphas.shape[0]):
                    out[a, c] += specular_lobe(cos_i, cos_o, cos_h, alphas[a]) * cos_i * omega


@lru_cache(maxsize=1)
def lobe_albedo() -> NDArray[np.float64]:
    """The GGX lobe's directional albedo A(cos_o, alpha) = integral of S cos_i over w_i.

    Returns
    -------
    ndarray, shape (len(ALPHAS), ALBEDO_COSINES), float64; column c is the view cosine
    (c + 0.5) / ALBEDO_COSINES (a 256 x 256 quadrature of the upper hemisphere)
    """
    cosines = (np.arange(ALBEDO_COSINES) + 0.5) / ALBEDO_COSINES
    out = np.zeros((len(ALPHAS), ALBEDO_COSINES))
    _albedo(np.asarray(ALPHAS), cosines, out)
    return out


@dataclass(frozen=True)
class SampleTransfer:
    """Each sample's diffuse transfer and shadow marks, as harmonics.

    Attributes
    ----------
    diffuse : ndarray, shape (P, BANDS^2), float32, of max(0, n . w) V(w) (sr)
    visibility : ndarray, shape (P, BANDS^2), float32, of V(w)
    """

    diffuse: NDArray[np.float32]
    visibility: NDArray[np.float32]


# Arrays one by one on purpose: numba kernels take arrays and scalars, not the fit and the
# interpolation weights that hold them.
@numba.njit(cache=True, parallel=True)
def _transfer(
    normals: NDArray[np.float64],
    source: NDArray[np.int64],
    lit: NDArray[np.uint8],
    indices: NDArray[np.int64],
    weights: NDArray[np.float64],
    directions: NDArray[np.float64],
    omega: NDArray[np.float64],
    basis: NDArray[np.float64],
    diffuse: NDArray[np.float32],
    visibility: NDArray[np.float32],
) -> None:
    for p in numba.prange(normals.shape[0]):
        q = source[p]
        normal = (normals[p, 0], normals[p, 1], normals[p, 2])
        for g in range(directions.shape[0]):
            v = 0.0
            for k in range(indices.shape[1]):
                v += weights[g, k] * lit[q, indices[g, k]]
            if v <= 0.0:
                continue
            cos = cosine(normal, (directions[g, 0], directions[g, 1], directions[g, 2]))
            for b in range(basis.shape[1]):
                visibility[p, b] += v * basis[g, b] * omega[g]
                if cos > 0.0:
                    diffuse[p, b] += cos * v * basis[g, b] * omega[g]


def sample_transfer(
    normals: NDArray[np.floating],
    source: NDArray[np.int64],
    lit: NDArray[np.uint8],
    mark_directions: NDArray[np.floating],
    reaches: NDArray[np.floating] | None = None,
) -> SampleTransfer:
    """Project each sample's transfer and shadow marks onto the harmonics.

    Parameters
    ----------
    normals : ndarray, shape (P, 3), the fitted normals
    source : ndarray, shape (P,), int64, whose marks each sample uses
        (:func:`render.engines.model_shading.fill_sources`)
    lit : ndarray, shape (P, M), uint8, the shadow marks at ``mark_directions``
    mark_directions : ndarray, shape (M, 3), unit vectors (rig frame)
    reaches : ndarray, shape (3,), optional; light from w reaches the samples only where
        w . reaches > 0 (a pixel field's object plane, its camera's z axis)

    Returns
    -------
    SampleTransfer, integrated over a TRANSFER_HEIGHT x 2 TRANSFER_HEIGHT direction grid, marks
    interpolated barycentrically (``clamp`` policy, as the exact relighting does)
    """
    height = TRANSFER_HEIGHT
    directions = panorama_directions(height, 2 * height).reshape(-1, 3)
    omega = np.array(panorama_solid_angles(height, 2 * height)).ravel()
    if reaches is not None:
        omega = omega * (directions @ np.asarray(reaches, dtype=np.float64) > 0.0)
    marks = interpolation_weights(mark_directions, directions, "barycentric", policy="clamp")
    basis = sh_basis(directions)
    p_count = len(normals)
    diffuse = np.zeros((p_count, basis.shape[1]), np.float32)
    visibility = np.zeros((p_count, basis.shape[1]), np.float32)
    _transfer(
        np.ascontiguousarray(normals, dtype=np.float64), np.ascontiguousarray(source),
        np.ascontiguousarray(lit), np.ascontiguousarray(marks.indices),
        np.ascontiguousarray(marks.weights), np.ascontiguousarray(directions), omega, basis,
        diffuse, visibility,
    )  # fmt: skip
    return SampleTransfer(diffuse, visibility)


@numba.njit(cache=True, inline="always")
def _bilinear(
    maps: NDArray[np.float32],
    level: int,
    cell: tuple[int, int, int, int, float, float],
    c: int,
) -> float:
    r0, r1, c0, c1, fr, fc = cell
    top = maps[level, r0, c0, c] * (1.0 - fc) + maps[level, r0, c1, c] * fc
    bottom = maps[level, r1, c0, c] * (1.0 - fc) + maps[level, r1, c1, c] * fc
    return top * (1.0 - fr) + bottom * fr


# The fit's arrays one by one on purpose, as render.engines.models's kernel takes them: numba
# kernels take arrays and scalars, not a ParametricFit, a SampleTransfer or a prefilter.
@numba.njit(cache=True, parallel=True)
def shade_precomputed(
    samples: NDArray[np.int64],
    source: NDArray[np.int64],
    normals: NDArray[np.float64],
    rho_d: NDArray[np.float32],
    f0: NDArray[np.float32],
    alpha: NDArray[np.float32],
    points: NDArray[np.float64],
    eye: NDArray[np.float64],
    distant: bool,
    with_lobe: bool,
    diffuse: NDArray[np.float32],
    visibility: NDArray[np.float32],
    light_sh: NDArray[np.float64],
    specular: NDArray[np.float32],
    alphas: NDArray[np.float64],
    albedo: NDArray[np.float64],
    norms: NDArray[np.float64],
    yaw: float,
    exposure: float,
    out: NDArray[np.float32],
) -> None:
    """Radiance of ``samples`` into ``out`` (P, 3) from the precomputed terms (module doc).

    ``light_sh`` is the panorama's harmonics already turned by the yaw and scaled by the
    exposure; ``specular`` the pre-filtered maps at yaw 0 (``yaw`` in radians turns the lookup,
    ``exposure`` scales it); ``albedo`` is :func:`lobe_albedo`, ``norms`` :func:`sh_norms`.
    """
    # Not core.brdf.shade_light per light (there are no lights here): its sum over the grid,
    # split. The diffuse term is its rho_d / pi times the harmonics' sum of cos V E; the
    # specular term F0 times the split sum of its lobe times the cosine (the tables of
    # _prefilter and _albedo, made with its half-vector cosine and lobe), looked up at the
    # lobe's dominant direction: it differs from the exact sum by the split's approximation
    # (module doc), measured by bench.interactive.
    bands2 = light_sh.shape[0]
    n_cos = albedo.shape[1]
    height, width = specular.shape[1], specular.shape[2]
    blocks = (samples.shape[0] + BLOCK - 1) // BLOCK
    for block in numba.prange(blocks):
        basis = np.zeros(bands2)  # one allocation per block of samples, not per sample
        for j in range(block * BLOCK, min((block + 1) * BLOCK, samples.shape[0])):
            p = samples[j]
            q = source[p]
            nx, ny, nz = normals[p, 0], normals[p, 1], normals[p, 2]
            vx, vy, vz = toward_eye(points, p, eye, distant)
            cos_o = cosine((nx, ny, nz), (vx, vy, vz))
            if cos_o <= 0.0:
                continue
            e_r = e_g = e_b = 0.0
            for b in range(bands2):
                t = diffuse[p, b]
                e_r += t * light_sh[b, 0]
                e_g += t * light_sh[b, 1]
                e_b += t * light_sh[b, 2]
            out[p, 0] = rho_d[q, 0] / math.pi * max(e_r, 0.0)
            out[p, 1] = rho_d[q, 1] / math.pi * max(e_g, 0.0)
            out[p, 2] = rho_d[q, 2] / math.pi * max(e_b, 0.0)
            if not with_lobe:
                continue
            a = alpha[q]
            # The lobe's dominant direction leans from the mirror direction toward the normal
            # as the surface roughens (Lagarde and de Rousiers 2014, Frostbite).
            rx, ry, rz = 2.0 * cos_o * nx - vx, 2.0 * cos_o * ny - vy, 2.0 * cos_o * nz - vz
            smooth = min(max(1.0 - a, 0.0), 1.0)
            lean = smooth * (math.sqrt(smooth) + a)
            rx, ry, rz = nx + lean * (rx - nx), ny + lean * (ry - ny), nz + lean * (rz - nz)
            length = math.sqrt(rx * rx + ry * ry + rz * rz)
            rx, ry, rz = rx / length, ry / length, rz / length
            _sh_eval(rx, ry, rz, norms, basis)
            seen = 0.0
            for b in range(bands2):
                seen += visibility[p, b] * basis[b]
            seen = min(max(seen, 0.0), 1.0)
            if seen <= 0.0:
                continue
            level = 0
            while level < alphas.shape[0] - 2 and alphas[level + 1] < a:
                level += 1
            t_alpha = (a - alphas[level]) / (alphas[level + 1] - alphas[level])
            t_alpha = min(max(t_alpha, 0.0), 1.0)
            x_cos = min(max(cos_o * n_cos - 0.5, 0.0), n_cos - 1.0)
            i_cos = min(int(x_cos), n_cos - 2)
            f_cos = x_cos - i_cos
            low = albedo[level, i_cos] * (1.0 - f_cos) + albedo[level, i_cos + 1] * f_cos
            high = albedo[level + 1, i_cos] * (1.0 - f_cos) + albedo[level + 1, i_cos + 1] * f_cos
            scale = seen * ((1.0 - t_alpha) * low + t_alpha * high) * exposure
            cell = panorama_bilinear_cell(rx, ry, rz, yaw, height, width)
            for c in range(3):
                mean = (1.0 - t_alpha) * _bilinear(specular, level, cell, c) + t_alpha * (
                    _bilinear(specular, level + 1, cell, c)
                )
                out[p, c] += f0[q, c] * scale * mean

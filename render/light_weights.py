"""How much light each measured light direction must carry: the W of the relighting sums.

Relit radiance is sum_t W_t F[t, p] (per camera, see :mod:`render.engines.paper_sums`); the
schemes differ in how an environment becomes W (T, 3), in irradiance:

- ``sampled`` (paper eq. 3): the environment's K sampled lights (a ``LightSet``), each spread
  over the measured lights by the interpolation weights: W_t = sum_k E_k w(l_k, t).
- ``pixels`` (paper eq. 2): every panorama pixel is a light, restricted to the hemisphere
  around the sample's normal: W_t(n) = sum over pixels with n . w > 0 of L(w) dw w(w, t). The
  weights depend on directions only, so the sum over pixels is gathered once per lighting, per
  normal. Exact mode: one row of W per sample. Binned mode: normals rounded to the nearest of B
  Fibonacci directions; only pixels within the bin radius of a normal's horizon can switch
  sides, which bounds the error (measured in the tests and the closing note).
- ``projection`` (the light stage): the panorama's Voronoi cells around the T measured light
  directions themselves, no intermediate sampling (the K -> T limit): W_t = the light of cell t.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from core.colour import REC709_LUMINANCE
from core.directions import fibonacci_sphere, panorama_directions, panorama_solid_angles
from core.errors import InputError
from core.light_set import LightSet
from processing.interpolation import InterpolationMethod, OutsidePolicy, interpolation_weights
from processing.lights import disassemble_lights
from processing.panorama import downsample_panorama

__all__ = [
    "LightWeights",
    "pixel_light_weights",
    "projection_light_weights",
    "sampled_light_weights",
]

#: Normal bins gathered at once (bounds the (pixels x bins) hemisphere mask in memory).
BIN_CHUNK = 64


@dataclass(frozen=True)
class LightWeights:
    """Irradiance carried by each measured light, for one lighting.

    Attributes
    ----------
    rgb : ndarray, shape (B, T, 3), float32
        W of each row (B = 1 unless the weights depend on the sample's normal).
    sample_rows : ndarray, shape (P,), int64, or None
        The row of ``rgb`` each sample uses (None: row 0 for every sample).
    outside_fraction : float
        Share of the lighting's luminous energy arriving from outside the measured lights'
        region (below the lowest ring, say), handled by the interpolation policy.
    scheme : str, "sampled", "pixels" or "projection"
    """

    rgb: NDArray[np.float32]
    sample_rows: NDArray[np.int64] | None
    outside_fraction: float
    scheme: str


def _energy_share(rgb: NDArray[np.float64], selected: NDArray[np.bool_]) -> float:
    energy = rgb @ REC709_LUMINANCE.astype(np.float64)
    total = float(energy.sum())
    return float(energy[selected].sum()) / total if total > 0 else 0.0


def sampled_light_weights(
    lights: LightSet,
    measured: NDArray[np.float64],
    method: InterpolationMethod = "paper",
    *,
    m: int = 3,
    policy: OutsidePolicy = "clamp",
) -> LightWeights:
    """W of eq. 3: every sampled light's irradiance spread over the measured lights.

    Parameters
    ----------
    lights : LightSet, K lights (directions (K, 3), rgb (K, 3) in radiance x sr)
    measured : ndarray, shape (T, 3), unit vectors of the measured lights
    method, m, policy : see :func:`processing.interpolation.interpolation_weights`
    """
    weights = interpolation_weights(measured, lights.directions, method, m=m, policy=policy)
    rgb = np.zeros((len(measured), 3))
    spread = weights.weights[:, :, None] * lights.rgb[:, None, :]
    np.add.at(rgb, weights.indices.ravel(), spread.reshape(-1, 3))
    return LightWeights(
        rgb.astype(np.float32)[None],
        None,
        _energy_share(lights.rgb, weights.outside),
        "sampled",
    )


def pixel_light_weights(
    rgb: NDArray[np.floating],
    measured: NDArray[np.float64],
    normals: NDArray[np.floating] | None = None,
    method: InterpolationMethod = "paper",
    *,
    m: int = 3,
    policy: OutsidePolicy = "clamp",
    normal_bins: int | None = 4096,
    grid_height: int | None = 64,
) -> LightWeights:
    """W of eq. 2: every panorama pixel a light, over the hemisphere of each sample's normal.

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3), linear radiance of the panorama
    measured : ndarray, shape (T, 3), unit vectors of the measured lights
    normals : ndarray, shape (P, 3), optional
        Sample normals; None (pixel fields without normals) drops the hemisphere test.
    method, m, policy : interpolation over the measured lights
    normal_bins : int or None
        Round normals to this many Fibonacci directions; None for one row per sample (exact).
    grid_height : int or None
        Pre-filter the panorama to this many rows (solid-angle-weighted block means, see
        :func:`processing.panorama.downsample_panorama`); None for every pixel.
    """
    image = np.asarray(rgb, dtype=np.float32)
    if grid_height is not None and grid_height < image.shape[0]:
        image = downsample_panorama(image, grid_height)
    height, width = image.shape[:2]
    directions = panorama_directions(height, width).reshape(-1, 3)
    energy = (image * panorama_solid_angles(height, width)[:, :, None]).reshape(-1, 3)
    lit = energy.sum(axis=1) > 0
    directions, energy = directions[lit], energy[lit].astype(np.float64)
    weights = interpolation_weights(measured, directions, method, m=m, policy=policy)
    t_count = len(measured)
    # One sparse (T x pixels) matrix per channel: the light each pixel hands to each light t.
    rows, cols = (
        weights.indices.ravel(),
        np.repeat(np.arange(len(directions)), weights.indices.shape[1]),
    )
    spread = [
        scipy.sparse.csr_matrix(
            ((weights.weights * energy[:, c : c + 1]).ravel(), (rows, cols)),
            shape=(t_count, len(directions)),
        )
        for c in range(3)
    ]
    outside = _energy_share(energy, weights.outside)
    if normals is None:
        full = np.stack([np.asarray(s.sum(axis=1)).ravel() for s in spread], axis=1)
        return LightWeights(full.astype(np.float32)[None], None, outside, "pixels")
    sample_normals = np.asarray(normals, dtype=np.float64)
    if normal_bins is None:
        bins, sample_rows = sample_normals, np.arange(len(sample_normals), dtype=np.int64)
    else:
        if normal_bins < 1:
            raise InputError(f"normal bins must be at least 1, got {normal_bins}")
        bins = fibonacci_sphere(normal_bins)
        _, nearest = cKDTree(bins).query(sample_normals)
        sample_rows = np.asarray(nearest, dtype=np.int64)
    out = np.zeros((len(bins), t_count, 3), dtype=np.float32)
    for start in range(0, len(bins), BIN_CHUNK):
        chunk = bins[start : start + BIN_CHUNK]
        above = (directions @ chunk.T > 0).astype(np.float64)  # (pixels, bins in chunk)
        for c in range(3):
            out[start : start + len(chunk), :, c] = (spread[c] @ above).T
    return LightWeights(out, sample_rows, outside, "pixels")


def projection_light_weights(
    rgb: NDArray[np.floating], measured: NDArray[np.float64]
) -> LightWeights:
    """W of the full projection: the light of each measured light's Voronoi cell.

    Light from outside the measured region falls in the cell of the nearest measured light
    (the ``clamp`` policy by construction).
    """
    image = np.asarray(rgb, dtype=np.float32)
    lights = disassemble_lights(image, measured)
    height = image.shape[0]
    # Energy outside: pixels whose nearest-direction interpolation is flagged outside.
    coarse = downsample_panorama(image, min(height, 64))
    h, w = coarse.shape[:2]
    flagged = interpolation_weights(
        measured, panorama_directions(h, w).reshape(-1, 3), "nearest"
    ).outside
    energy = (coarse * panorama_solid_angles(h, w)[:, :, None]).reshape(-1, 3).astype(np.float64)
    return LightWeights(
        lights.rgb.astype(np.float32)[None], None, _energy_share(energy, flagged), "projection"
    )

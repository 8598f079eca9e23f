"""Importance sampling of an environment panorama into K directions.

The paper's step (section 3.3) is error diffusion with threshold modulation (Zhou & Fang 2003)
run on the panorama's luminance. Here the diffused quantity is a *density*: luminance x pixel
solid angle (so samples follow light on the sphere, not pixel area), times an optional user
modulation map, scaled so that its sum, the expected number of samples, is K. ``paper=True``
drops the solid-angle weight, as the paper did.

Samplers (all return unit directions, rig frame):

========================  ========================================================================
``tmed``                  error diffusion with threshold modulation, Zhou & Fang 2003 (default)
``ostromoukhov``          variable-coefficient error diffusion, Ostromoukhov 2001
``floyd-steinberg``       classic error diffusion, Floyd & Steinberg 1976
``uniform``               a Fibonacci lattice, randomly rotated: uniform on the sphere (with a
                          modulation map: inverse-CDF sampling of modulation x solid angle)
``cdf``                   inverse-CDF (marginal row, conditional column) sampling of the density
``median-cut``            Debevec 2005 median cut of the density
========================  ========================================================================

Error diffusion runs on a grid coarse enough for the density to be a grey level (see
:func:`diffusion_grid`); each dot becomes the pixel nearest its cell's density centroid. The
samplers give about K points; ``exact=True`` (the default) returns exactly K: a second pass
rescales the density by K / count, and any remaining surplus or deficit is settled by the cells
that were closest to the threshold (see :func:`settle_count`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

import cv2
import numpy as np
from numpy.typing import NDArray

from core.colour import luminance
from core.directions import (
    direction_from_angles,
    fibonacci_sphere,
    panorama_azimuths,
    panorama_inclinations,
    panorama_pixel_points,
    panorama_row_solid_angles,
)
from core.errors import InputError
from processing.halftone import DIFFUSION_METHODS, error_diffuse
from processing.median_cut import median_cut_sample

__all__ = [
    "SAMPLERS",
    "SampleSet",
    "SamplerName",
    "diffusion_grid",
    "resample_modulation",
    "sample_environment",
    "sampling_density",
    "settle_count",
]

SamplerName = Literal["tmed", "ostromoukhov", "floyd-steinberg", "uniform", "cdf", "median-cut"]
SAMPLERS: tuple[SamplerName, ...] = get_args(SamplerName)

#: Error-diffusion grid cells per wanted sample: the mean cell holds half a dot (mid-grey).
CELLS_PER_SAMPLE = 2.0


@dataclass(frozen=True)
class SampleSet:
    """Directions chosen by a sampler.

    Attributes
    ----------
    directions : ndarray, shape (K, 3), float64 unit vectors, rig frame
    method : str, the sampler's name
    density : ndarray, shape (H, W), float64, the density that was sampled (sums to K)
    """

    directions: NDArray[np.float64]
    method: str
    density: NDArray[np.float64]

    @property
    def k(self) -> int:
        """Number of directions, K."""
        return int(self.directions.shape[0])


def resample_modulation(
    modulation: NDArray[np.floating], height: int, width: int
) -> NDArray[np.float64]:
    """Resize a modulation map of any resolution to (H, W); RGB maps use their luminance.

    Values must be finite and non-negative; zero forbids samples, larger values attract them.
    """
    m = np.asarray(modulation, dtype=np.float32)
    if m.ndim == 3:
        m = luminance(m[:, :, :3])
    if m.ndim != 2 or m.size == 0:
        raise InputError(f"modulation map must be an (H, W) or (H, W, 3) image, got {m.shape}")
    if not np.all(np.isfinite(m)) or float(m.min()) < 0:
        raise InputError("modulation map must be finite and non-negative")
    shrinking = m.shape[0] > height
    interpolation = cv2.INTER_AREA if shrinking else cv2.INTER_LINEAR
    resized = cv2.resize(m, (width, height), interpolation=interpolation)
    # Interpolation must not leak samples into regions the user zeroed.
    nearest = cv2.resize(m, (width, height), interpolation=cv2.INTER_NEAREST)
    return np.where(nearest > 0, np.maximum(resized, 0.0), 0.0).astype(np.float64)


def sampling_density(
    rgb: NDArray[np.floating],
    k: float,
    *,
    paper: bool = False,
    modulation: NDArray[np.floating] | None = None,
) -> NDArray[np.float64]:
    """The density that samplers follow, scaled to sum to ``k``.

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3), linear radiance (W = 2H)
    k : float, expected number of samples
    paper : bool
        Use plain luminance, as the paper did, instead of luminance x pixel solid angle.
    modulation : ndarray, optional
        Multiplies the density; any resolution (resampled to H x W).

    Returns
    -------
    ndarray, shape (H, W), float64
    """
    height, width = rgb.shape[:2]
    density = luminance(rgb).astype(np.float64)
    if not paper:
        density *= panorama_row_solid_angles(height, width)[:, None]
    if modulation is not None:
        density *= resample_modulation(modulation, height, width)
    total = float(density.sum())
    if not total > 0:
        raise InputError(
            "nothing to sample: the density is zero everywhere (black panorama, or a "
            "modulation map that is zero wherever there is light)"
        )
    return density * (k / total)


def sample_environment(
    rgb: NDArray[np.floating],
    k: int = 64,
    *,
    method: SamplerName = "tmed",
    seed: int = 0,
    exact: bool | None = None,
    paper: bool = False,
    modulation: NDArray[np.floating] | None = None,
    cells_per_sample: float = CELLS_PER_SAMPLE,
) -> SampleSet:
    """Choose about (or, with ``exact``, exactly) ``k`` light directions from a panorama.

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3)
        Linear radiance, W = 2H (apply yaw and exposure before, see ``processing.environment``).
    k : int
        Number of samples wanted, 1 <= k <= H x W.
    method : SamplerName
    seed : int
        Seeds the random threshold (error diffusion), the lattice rotation (uniform) or the
        draws (cdf). The same seed gives the same samples.
    exact : bool, optional
        Return exactly ``k`` samples. Default: on. Only error diffusion can miss ``k``.
    paper : bool
        Sample plain pixel luminance, without the solid-angle weight.
    modulation : ndarray, optional
        User map multiplying the density; zero forbids samples.
    cells_per_sample : float
        Error-diffusion grid cells per wanted sample (see :func:`diffusion_grid`).

    Returns
    -------
    SampleSet
    """
    if method not in SAMPLERS:
        raise InputError(f"unknown sampler {method!r}; choose one of {', '.join(SAMPLERS)}")
    height, width = rgb.shape[:2]
    if not 1 <= k <= height * width:
        raise InputError(
            f"k must be between 1 and the number of pixels ({height * width}), got {k}"
        )
    # Uniform sampling ignores the light; only solid angle and the modulation shape it.
    light = np.ones_like(rgb[:, :, :3]) if method == "uniform" else rgb
    density = sampling_density(light, k, paper=paper, modulation=modulation)
    if method in DIFFUSION_METHODS:
        directions = _diffusion_samples(
            density, k, method, seed, exact is not False, cells_per_sample
        )
    elif method == "uniform":
        directions = (
            _fibonacci_sphere(k, seed) if modulation is None else _cdf_samples(density, k, seed)
        )
    elif method == "cdf":
        directions = _cdf_samples(density, k, seed)
    else:
        directions = median_cut_sample(density, k)
    return SampleSet(directions=directions, method=method, density=density)


def diffusion_grid(
    density: NDArray[np.float64], k: int, cells_per_sample: float = CELLS_PER_SAMPLE
) -> tuple[NDArray[np.float64], NDArray[np.intp], NDArray[np.intp]]:
    """Sum a density into the equirectangular grid that error diffusion runs on.

    Error diffusion places dots well only where the density is a grey level: at 10^-4 dots per
    pixel (K = 64 over a 1024 x 512 panorama) the error takes thousands of rows to reach the
    threshold and no dot ever appears. So the density is summed into an h x 2h grid of about
    ``cells_per_sample * k`` cells (default 2: the mean cell at mid-grey, the tones Zhou & Fang's
    threshold modulation was designed for); the grid is refined while it has fewer lit cells
    than that.

    Returns
    -------
    grid : ndarray, shape (h, 2h), float64, sums of ``density`` (total preserved exactly)
    row_edges, col_edges : ndarray of int, shape (h + 1,), (2h + 1,), pixel bounds of the cells
    """
    height, width = density.shape
    if not cells_per_sample > 0:
        raise InputError(f"cells_per_sample must be positive, got {cells_per_sample}")
    h = min(height, max(1, round(float(np.sqrt(k * cells_per_sample / 2.0)))))
    while True:
        row_edges = (np.arange(h + 1) * height) // h
        col_edges = (np.arange(2 * h + 1) * width) // (2 * h)
        grid = np.add.reduceat(
            np.add.reduceat(density, row_edges[:-1], axis=0), col_edges[:-1], axis=1
        )
        if h == height or np.count_nonzero(grid) >= cells_per_sample * k:
            return grid, row_edges, col_edges
        h = min(height, 2 * h)


def _diffusion_samples(
    density: NDArray[np.float64],
    k: int,
    method: str,
    seed: int,
    exact: bool,
    cells_per_sample: float,
) -> NDArray[np.float64]:
    grid, row_edges, col_edges = diffusion_grid(density, k, cells_per_sample)
    fired, margin = error_diffuse(grid, method=method, seed=seed)
    count = int(fired.sum())
    if exact and count != k and count > 0:
        # Counts scale almost linearly with the density, so one rescaled pass lands close.
        fired, margin = error_diffuse(grid * (k / count), method=method, seed=seed)
    if exact:
        fired = settle_count(fired, margin, grid > 0, k)
    elif not fired.any():
        raise InputError(f"{method} error diffusion placed no sample for k = {k}; use exact mode")
    inclinations = panorama_inclinations(density.shape[0])
    azimuths = panorama_azimuths(density.shape[1])
    samples = []
    for r, c in zip(*np.nonzero(fired), strict=True):
        rows = slice(row_edges[r], row_edges[r + 1])
        cols = slice(col_edges[c], col_edges[c + 1])
        cell = direction_from_angles(azimuths[None, cols], inclinations[rows, None])
        samples.append(_cell_sample(density[rows, cols], cell))
    return np.array(samples, dtype=np.float64)


def _cell_sample(
    density: NDArray[np.float64], directions: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The pixel of a diffusion cell nearest its density centroid, among pixels with density."""
    centroid = np.einsum("ij,ijk->k", density, directions)
    closeness = np.where(density > 0, directions @ centroid, -np.inf)
    return directions.reshape(-1, 3)[int(np.argmax(closeness))]


def settle_count(
    fired: NDArray[np.bool_], margin: NDArray[np.floating], allowed: NDArray[np.bool_], k: int
) -> NDArray[np.bool_]:
    """Make a halftone have exactly ``k`` dots, changing the fewest, most marginal pixels.

    Parameters
    ----------
    fired : ndarray, shape (H, W), bool, the halftone
    margin : ndarray, shape (H, W), value minus threshold at each pixel when it was decided
    allowed : ndarray, shape (H, W), bool, pixels that may receive a dot (density > 0)
    k : int

    Returns
    -------
    ndarray, shape (H, W), bool, with exactly ``k`` dots (a new array)
    """
    result = fired.copy()
    count = int(result.sum())
    if count > k:
        # Drop the dots that fired with the least to spare.
        on = np.flatnonzero(result)
        drop = on[np.argsort(margin.ravel()[on], kind="stable")[: count - k]]
        result.ravel()[drop] = False
    elif count < k:
        off = np.flatnonzero(~result & allowed)
        if off.size < k - count:
            raise InputError(f"only {count + off.size} pixels can hold samples, fewer than k = {k}")
        add = off[np.argsort(-margin.ravel()[off], kind="stable")[: k - count]]
        result.ravel()[add] = True
    return result


def _fibonacci_sphere(k: int, seed: int) -> NDArray[np.float64]:
    """K near-uniform directions (spherical Fibonacci lattice) under a seeded random rotation."""
    lattice = fibonacci_sphere(k)
    q = np.random.default_rng(seed).normal(size=4)  # uniform random rotation (unit quaternion)
    w, x, y, zq = q / np.linalg.norm(q)
    rotation = np.array(
        [
            [1 - 2 * (y * y + zq * zq), 2 * (x * y - zq * w), 2 * (x * zq + y * w)],
            [2 * (x * y + zq * w), 1 - 2 * (x * x + zq * zq), 2 * (y * zq - x * w)],
            [2 * (x * zq - y * w), 2 * (y * zq + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    return lattice @ rotation.T


def _cdf_samples(density: NDArray[np.float64], k: int, seed: int) -> NDArray[np.float64]:
    """Inverse-CDF sampling of a piecewise-constant density on the sphere.

    Rows are drawn from the marginal (stratified), columns from the row's conditional; each point
    is then spread uniformly in azimuth and cos(inclination) inside its pixel, so the samples are
    continuous and never coincide. ``density`` already carries the solid-angle (sin theta) weight.
    """
    height, width = density.shape
    rng = np.random.default_rng(seed)
    row_mass = density.sum(axis=1)
    row_cdf = np.cumsum(row_mass) / row_mass.sum()
    u = (np.arange(k) + rng.random(k)) / k
    rows = np.minimum(np.searchsorted(row_cdf, u, side="right"), height - 1)
    col_cdf = np.cumsum(density, axis=1)
    v = rng.random(k) * col_cdf[rows, -1]
    cols = np.array(
        [np.searchsorted(col_cdf[r], x, side="right") for r, x in zip(rows, v, strict=True)]
    )
    cols = np.minimum(cols, width - 1)
    return panorama_pixel_points(rows, cols, rng.random(k), rng.random(k), height, width)

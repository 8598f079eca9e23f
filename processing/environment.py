"""Controllable environment lighting: a panorama and its controls -> the lights that relight.

The one lighting pipeline of the project: both relighting engines, ``rig sample`` and the
benchmarks take their lighting from :func:`light_environment`. The controls (the paper's
"controllable" lighting) are a yaw rotation and an exposure scale, applied to the panorama
first, and for sampled lighting the sampler, K and a modulation map that steers where samples
go without changing how much light there is: the disassembling still gathers all of it.

============ ================================================================================
lighting     what the panorama becomes (``LightingControls.lighting``)
============ ================================================================================
``sampled``  K directions sampled by ``method`` (TMED by default), all the light gathered into
             their spherical Voronoi cells (:func:`processing.lights.disassemble_lights`);
             with ``centroids`` each light sits at its cell's energy-weighted centroid
``grid``     the panorama summed exactly into ``grid_height`` x 2 ``grid_height`` blocks, one
             light at each block's centroid (:func:`core.light_set.grid_lights`)
``panorama`` no lights: the engine integrates the adjusted panorama pixel by pixel
============ ================================================================================
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Literal, get_args

import numpy as np
from numpy.typing import NDArray

from core.directions import panorama_directions, panorama_solid_angles
from core.errors import InputError
from core.image_io import read_linear
from core.light_set import LightSet, grid_lights
from processing.lights import disassemble_lights
from processing.panorama import Panorama, adjust_panorama
from processing.sampling import SamplerName, sample_environment

__all__ = [
    "LIGHTINGS",
    "EnvironmentLighting",
    "Lighting",
    "LightingControls",
    "adjust_environment",
    "cell_centroids",
    "light_environment",
    "read_modulation_map",
]

Lighting = Literal["sampled", "grid", "panorama"]
#: What a panorama becomes (see the module docstring).
LIGHTINGS: tuple[Lighting, ...] = get_args(Lighting)


@dataclass(frozen=True)
class LightingControls:
    """How to turn a panorama into lights.

    Attributes
    ----------
    lighting : {"sampled", "grid", "panorama"}, see the module docstring
    k, method, seed, exact, paper : sampled lighting (see
        :func:`processing.sampling.sample_environment`); ``paper`` diffuses plain pixel
        luminance as the paper did
    modulation : ndarray, optional, any resolution: multiplies the sampling density (sampled
        lighting; zero forbids samples)
    centroids : bool, sampled lighting: each light at its cell's energy-weighted centroid
    grid_height : int, optional, grid lighting: rows of blocks (None: every pixel)
    yaw_deg : float, counter-clockwise rotation of the environment seen from above, degrees
    exposure : float, radiance scale, > 0
    """

    lighting: Lighting = "sampled"
    k: int = 64
    method: SamplerName = "tmed"
    seed: int = 0
    exact: bool | None = None
    paper: bool = False
    modulation: NDArray[np.floating] | None = None
    centroids: bool = False
    grid_height: int | None = None
    yaw_deg: float = 0.0
    exposure: float = 1.0

    def __post_init__(self) -> None:
        if self.lighting not in LIGHTINGS:
            raise InputError(
                f"unknown lighting {self.lighting!r}; use one of {', '.join(LIGHTINGS)}"
            )
        if self.modulation is not None and self.lighting != "sampled":
            raise InputError(
                f"a modulation map steers sampled lights; {self.lighting} lighting uses every "
                "part of the panorama (sample K lights to modulate them)"
            )


@dataclass(frozen=True)
class EnvironmentLighting:
    """The adjusted panorama and the lights it became (None for ``panorama`` lighting)."""

    panorama: Panorama
    lights: LightSet | None
    controls: LightingControls

    def light_set(self) -> LightSet:
        """The lights; InputError for ``panorama`` lighting, which has none."""
        if self.lights is None:
            raise InputError("panorama lighting has no lights: sample or grid the panorama")
        return self.lights

    def to_json(self) -> dict[str, Any]:
        """The ``lights.json`` document (directions in the rig frame, rgb in radiance x sr)."""
        lights = self.light_set()
        if lights.solid_angle_sr is None:
            raise InputError("only lights gathered from a panorama are written as lights.json")
        c = self.controls
        return {
            "k": lights.k,
            "method": c.method,
            "panorama": {
                "path": self.panorama.source,
                "width": self.panorama.width,
                "height": self.panorama.height,
            },
            "controls": {
                "seed": c.seed,
                "paper": c.paper,
                "yaw_deg": c.yaw_deg,
                "exposure": c.exposure,
                "modulation": c.modulation is not None,
            },
            "directions": lights.directions.tolist(),
            "rgb": lights.rgb.tolist(),
            "solid_angle_sr": lights.solid_angle_sr.tolist(),
        }


def adjust_environment(panorama: Panorama, controls: LightingControls) -> Panorama:
    """The panorama as the controls relight with it: rotated by the yaw, scaled by exposure."""
    return adjust_panorama(panorama, yaw_deg=controls.yaw_deg, exposure=controls.exposure)


def light_environment(
    panorama: Panorama, controls: LightingControls | None = None
) -> EnvironmentLighting:
    """Apply the controls and turn the panorama into lights (see the module docstring)."""
    c = controls or LightingControls()
    adjusted = adjust_environment(panorama, c)
    lights: LightSet | None = None
    if c.lighting == "grid":
        lights = grid_lights(adjusted.rgb, c.grid_height)
    elif c.lighting == "sampled":
        samples = sample_environment(
            adjusted.rgb,
            c.k,
            method=c.method,
            seed=c.seed,
            exact=c.exact,
            paper=c.paper,
            modulation=c.modulation,
        )
        lights = disassemble_lights(adjusted.rgb, samples.directions)
        if c.centroids:
            lights = cell_centroids(lights, adjusted.rgb)
    return EnvironmentLighting(panorama=adjusted, lights=lights, controls=c)


def cell_centroids(lights: LightSet, rgb: NDArray[np.floating]) -> LightSet:
    """The lights moved to their cells' energy-weighted centroid directions.

    The centroid keeps the cell's first moment, so anything linear in the direction (a cosine
    that does not clip inside the cell) is exact; it halves the error of glossy lobes under the
    courtyard at K = 128-256 (docs/models.md). A cell without light keeps its sample.

    Parameters
    ----------
    lights : LightSet gathered from ``rgb`` (it has labels)
    rgb : ndarray, shape (H, 2H, 3), the panorama they were gathered from
    """
    if lights.labels is None:
        raise InputError("only lights gathered from a panorama have cells to centre")
    image = np.asarray(rgb, dtype=np.float64)
    height, width = image.shape[:2]
    weight = (image.sum(axis=2) * panorama_solid_angles(height, width)).ravel()
    pixel_directions = panorama_directions(height, width).reshape(-1, 3)
    labels = lights.labels.ravel()
    moments = np.stack(
        [np.bincount(labels, weight * pixel_directions[:, i], lights.k) for i in range(3)],
        axis=1,
    )
    length = np.linalg.norm(moments, axis=1, keepdims=True)
    directions = np.where(length > 0, moments / np.maximum(length, 1e-300), lights.directions)
    return LightSet(directions, lights.rgb, lights.solid_angle_sr, lights.labels)


def read_modulation_map(path: str | os.PathLike[str]) -> NDArray[np.float32]:
    """Read a user modulation map: any resolution, values taken as linear weights.

    8/16-bit images are read without sRGB decoding (a painted mask means what it shows: 50 %
    grey halves the density); RGB maps use their luminance when resampled.
    """
    image = read_linear(path, transfer="linear")
    if not np.all(np.isfinite(image)) or float(image.min()) < 0:
        raise InputError(f"{path}: modulation map values must be finite and non-negative")
    if not image.any():
        raise InputError(f"{path}: the modulation map is zero everywhere: it forbids every sample")
    return image

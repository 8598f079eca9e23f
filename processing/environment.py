"""Controllable environment lighting: panorama + controls -> sampled, disassembled lights.

The controls (the paper's "controllable" lighting) are a yaw rotation and an exposure scale,
applied to the panorama before sampling, and a modulation map that steers where samples go
without changing how much light there is: the disassembling still gathers all of it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from core.image_io import read_linear
from processing.lights import LightSet, disassemble_lights
from processing.panorama import Panorama, adjust_panorama
from processing.sampling import SamplerName, sample_environment

__all__ = ["EnvironmentLighting", "LightingControls", "light_environment", "read_modulation_map"]


@dataclass(frozen=True)
class LightingControls:
    """How to turn a panorama into lights (see :func:`processing.sampling.sample_environment`)."""

    k: int = 64
    method: SamplerName = "tmed"
    seed: int = 0
    exact: bool | None = None
    paper: bool = False
    modulation: NDArray[np.floating] | None = None
    yaw_deg: float = 0.0
    exposure: float = 1.0


@dataclass(frozen=True)
class EnvironmentLighting:
    """The adjusted panorama and the lights it was disassembled into."""

    panorama: Panorama
    lights: LightSet
    controls: LightingControls

    def to_json(self) -> dict[str, Any]:
        """The ``lights.json`` document (directions in the rig frame, rgb in radiance x sr)."""
        c = self.controls
        return {
            "k": self.lights.k,
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
            "directions": self.lights.directions.tolist(),
            "rgb": self.lights.rgb.tolist(),
            "solid_angle_sr": self.lights.solid_angle_sr.tolist(),
        }


def light_environment(
    panorama: Panorama, controls: LightingControls | None = None
) -> EnvironmentLighting:
    """Apply the controls, sample the panorama and gather all its light into the samples."""
    c = controls or LightingControls()
    adjusted = adjust_panorama(panorama, yaw_deg=c.yaw_deg, exposure=c.exposure)
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
    return EnvironmentLighting(panorama=adjusted, lights=lights, controls=c)


def read_modulation_map(path: str | os.PathLike[str]) -> NDArray[np.float32]:
    """Read a user modulation map: any resolution, values taken as linear weights.

    8/16-bit images are read without sRGB decoding (a painted mask means what it shows: 50 %
    grey halves the density); RGB maps use their luminance when resampled.
    """
    image = read_linear(path, transfer="linear")
    if not np.all(np.isfinite(image)) or float(image.min()) < 0:
        raise InputError(f"{path}: modulation map values must be finite and non-negative")
    return image

"""Files of a sampled environment: ``lights.json``, ``overlay.png`` and ``lights.png``."""

from __future__ import annotations

import os
from pathlib import Path

from core.atomic import write_json_atomic
from core.image_io import write_srgb8
from core.progress import progress_bar
from processing.environment import EnvironmentLighting, LightingControls, light_environment
from processing.panorama import Panorama
from render.overlay import disassembled_picture, sample_overlay
from render.tonemap import auto_exposure

__all__ = ["write_lighting_outputs"]


def write_lighting_outputs(
    panorama: Panorama,
    controls: LightingControls,
    directory: str | os.PathLike[str],
) -> EnvironmentLighting:
    """Sample and disassemble ``panorama`` and write the three files into ``directory``.

    ``overlay.png`` shows the tone-mapped panorama with the Voronoi cell borders and samples;
    ``lights.png`` fills each cell with its light's mean radiance, at the same exposure.
    The steps are reported (:mod:`core.progress`) when they take more than a second (a first
    run compiles the numerical kernels, which are cached afterwards).
    """
    steps = progress_bar(total=3, desc="sample and gather", unit="step", delay=1.0)
    with steps:
        lighting = light_environment(panorama, controls)
        out = Path(directory)
        out.mkdir(parents=True, exist_ok=True)
        exposure = auto_exposure(lighting.panorama.rgb)
        write_json_atomic(out / "lights.json", lighting.to_json())
        steps.set_description("overlay.png")
        steps.update()
        write_srgb8(
            out / "overlay.png",
            sample_overlay(lighting.panorama.rgb, lighting.light_set(), exposure=exposure),
        )
        steps.set_description("lights.png")
        steps.update()
        picture = disassembled_picture(lighting.light_set(), exposure=exposure)
        write_srgb8(out / "lights.png", picture)
        steps.update()
    return lighting

"""What the simulator knows of a simulated capture that its images do not say.

A capture on the simulated rig records the scene's name and point count in the rig config
snapshot; the object's surface samples are the scene's, and the camera's radiometric scale is
its sensor's. :func:`simulated_capture_sources` returns them in the shape
``processing.process_dataset.FieldSources`` asks for.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from sim.scenes import build_scene
from sim.sensor import Sensor

__all__ = ["SimulatedSources", "sensor_radiance_scale", "simulated_capture_sources"]


@dataclass(frozen=True)
class SimulatedSources:
    """A synthetic scene's points and, for a simulated camera, its sensor's scale.

    Attributes
    ----------
    points, normals : ndarray, shape (P, 3), float32, the scene's surface samples
    spacing : float, sqrt(area / P) of the scene's sampling
    radiance_scale : float or None, decoded value per unit radiance per millisecond (None when
        the images did not come from the simulated camera)
    light_model : dict or None, the simulated light (a point light where the config says so)
    provenance : dict, the scene and its point count
    """

    points: NDArray[np.float32]
    normals: NDArray[np.float32]
    spacing: float
    radiance_scale: float | None
    light_model: dict[str, Any] | None
    provenance: dict[str, Any] = field(default_factory=dict)


def sensor_radiance_scale(sensor: Sensor | None = None) -> float:
    """Decoded value (1.0 = saturation) per unit radiance per millisecond of a sensor."""
    s = sensor or Sensor()
    return s.sensitivity / (1000.0 * s.full_well)


def simulated_capture_sources(
    rig_config: Mapping[str, Any], *, scene: str | None = None, points: int | None = None
) -> SimulatedSources:
    """The sources of a capture's field from its rig config snapshot.

    Parameters
    ----------
    rig_config : mapping, a dataset's ``rig_config`` (its ``camera`` section names the scene)
    scene : str, optional, a synthetic scene for a capture that is not simulated (or another)
    points : int, optional, scene points (default: the config's, else 20 000)

    Raises
    ------
    InputError
        No scene given and the capture is not simulated.
    """
    camera: dict[str, Any] = dict(rig_config.get("camera") or {})
    simulated = camera.get("backend") == "simulated"
    name = scene or (camera.get("scene") if simulated else None)
    if name is None:
        raise InputError("not a simulated capture: no synthetic scene to take the points from")
    count = points or int(camera.get("points", 20_000))
    samples = build_scene(name, count)
    # The synthetic scenes float: their ground truth is lit from every direction.
    light_model: dict[str, Any] = {
        "type": "directional",
        "irradiance": 1.0,
        "below_horizon": "open",
    }
    if simulated and camera.get("light_distance") is not None:
        distance = float(camera["light_distance"])
        light_model = {"type": "point", "distance": distance, "irradiance_at_origin": 1.0,
                       "below_horizon": "open"}  # fmt: skip
    return SimulatedSources(
        points=samples.points,
        normals=samples.normals,
        spacing=samples.spacing,
        # The simulated camera's sensor: the rig config has no sensor keys.
        radiance_scale=sensor_radiance_scale() if simulated else None,
        light_model=light_model,
        provenance={"scene": name, "scene_points": count},
    )

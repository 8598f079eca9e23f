"""What the relighting engines share about a panorama: the user's controls to its lights.

Every engine (:class:`render.relighter.Relighter`, :class:`render.model_relight.ModelRelighter`,
:class:`render.predictor_relight.PredictorRelighter`) is lit the same way: its mode turns the
user's controls into the lighting it takes (``lighting_controls``), the panorama is seen as the
object sees it (its horizon, :class:`processing.panorama.VisibleEnvironments`), and the engine
takes the result (:meth:`PanoramaLitEngine.take_panorama`; by default
:func:`processing.environment.light_environment` and ``set_environment``).
"""

from __future__ import annotations

import time
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from core.field_store import ReflectanceField
from processing.environment import EnvironmentLighting, LightingControls, light_environment
from processing.panorama import Panorama, VisibleEnvironments

__all__ = ["PanoramaLitEngine"]


class _ControlledMode(Protocol):
    def lighting_controls(
        self,
        *,
        yaw_deg: float = 0.0,
        exposure: float = 1.0,
        modulation: NDArray[np.floating] | None = None,
    ) -> LightingControls: ...


class PanoramaLitEngine:
    """The base of the engines: ``set_lighting`` from a panorama and the user's controls.

    Parameters
    ----------
    field_store : ReflectanceField, whose statement of what lies below its horizon applies

    Attributes
    ----------
    settings : the engine's mode (it says which lighting it takes from the controls); set by
        the engine
    """

    settings: _ControlledMode

    def __init__(self, field_store: ReflectanceField) -> None:
        self._visible = VisibleEnvironments(field_store.below_horizon)

    def set_lighting(
        self,
        panorama: Panorama,
        *,
        yaw_deg: float = 0.0,
        exposure: float = 1.0,
        modulation: NDArray[np.floating] | None = None,
    ) -> float:
        """Light with a panorama under the user's controls; returns the seconds it took."""
        start = time.perf_counter()
        controls = self.settings.lighting_controls(
            yaw_deg=yaw_deg, exposure=exposure, modulation=modulation
        )
        self.take_panorama(self._visible(panorama), controls)
        return time.perf_counter() - start

    def take_panorama(self, panorama: Panorama, controls: LightingControls) -> None:
        """Take the panorama as the object sees it, under ``controls`` (engines may override)."""
        self.set_environment(light_environment(panorama, controls))

    def set_environment(self, lighting: EnvironmentLighting) -> None:
        """Take a lighting made by :func:`light_environment` (each engine its own way)."""
        raise NotImplementedError

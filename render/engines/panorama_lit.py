"""What the relighting engines share about a panorama: the user's controls, applied once.

The user's controls on a panorama (:class:`PanoramaControls`: yaw, exposure, a modulation map)
are applied in one place, :meth:`PanoramaControls.adjusted`, to the panorama as the object sees
it (its horizon, :class:`processing.panorama.VisibleEnvironments`); the result, an
:class:`AdjustedPanorama`, is what the mode's choice and the guards judge and what every
engine (:class:`render.engines.interpolated.Relighter`,
:class:`render.engines.models.ModelRelighter`,
:class:`render.engines.predicted.PredictorRelighter`) is lit by
(:meth:`PanoramaLitEngine.take_lighting`): the mode says which lights it takes
(``lighting_controls``), made from the adjusted panorama without adjusting it again.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from core.field_store import ReflectanceField
from processing.environment import EnvironmentLighting, LightingControls, light_environment
from processing.panorama import (
    Panorama,
    VisibleEnvironments,
    adjust_panorama,
    visible_environment,
)

__all__ = ["AdjustedPanorama", "PanoramaControls", "PanoramaLitEngine"]


@dataclass(frozen=True, kw_only=True)
class PanoramaControls:
    """The user's controls on a panorama.

    Attributes
    ----------
    yaw_deg : float, counter-clockwise rotation seen from above, degrees
    exposure : float, radiance scale, > 0
    modulation : ndarray, shape (h, w), float, optional: multiplies the sampling density of
        the sampled modes (the paper's threshold modulation), in the panorama's own frame
    """

    yaw_deg: float = 0.0
    exposure: float = 1.0
    modulation: NDArray[np.floating] | None = None

    @property
    def turn(self) -> tuple[float, float]:
        """The yaw and exposure: what the adjustment of the panorama depends on."""
        return (self.yaw_deg, self.exposure)

    def adjusted(self, visible: Panorama) -> AdjustedPanorama:
        """``visible`` (a panorama past the object's horizon) rotated and scaled: the one place.

        The horizon goes first, as the engines always did: the blocked copy is then made once
        per panorama, and the pre-filter of the models' precomputed lighting, keyed on it, kept.
        """
        seen = adjust_panorama(visible, yaw_deg=self.yaw_deg, exposure=self.exposure)
        return AdjustedPanorama(visible=visible, seen=seen, controls=self)

    def as_seen(self, panorama: Panorama, field: ReflectanceField) -> Panorama:
        """``panorama`` as ``field``'s object sees it: its horizon applied, rotated, scaled."""
        return self.adjusted(visible_environment(panorama, field.below_horizon)).seen


@dataclass(frozen=True)
class AdjustedPanorama:
    """A panorama under the user's controls, adjusted once.

    Attributes
    ----------
    visible : Panorama, as read, past the object's horizon (yaw 0, exposure 1)
    seen : Panorama, ``visible`` rotated by the yaw and scaled by the exposure: what the object
        sees, what the mode's choice and the guards judge and what the lights are made of
    controls : PanoramaControls, what it was adjusted by (and the modulation of its lights)
    """

    visible: Panorama
    seen: Panorama
    controls: PanoramaControls

    def environment(self, controls: LightingControls) -> EnvironmentLighting:
        """The lighting ``controls`` make of the seen panorama, recorded under ``controls``.

        ``controls`` carry the yaw and exposure the seen panorama already holds; the lights
        are made with them neutral, so nothing is rotated or scaled twice.
        """
        neutral = replace(controls, yaw_deg=0.0, exposure=1.0)
        made = light_environment(self.seen, neutral)
        return replace(made, panorama=self.seen, controls=controls)

    def lights_as(self, other: AdjustedPanorama | None) -> bool:
        """Whether ``other`` lights as this does (same panorama, controls and map, by identity)."""
        if other is None:
            return False
        mine, theirs = self.controls, other.controls
        return (
            self.visible is other.visible
            and mine.turn == theirs.turn
            and mine.modulation is theirs.modulation
        )


class _ControlledMode(Protocol):
    def lighting_controls(
        self,
        *,
        yaw_deg: float = 0.0,
        exposure: float = 1.0,
        modulation: NDArray[np.floating] | None = None,
    ) -> LightingControls: ...


class PanoramaLitEngine:
    """The base of the engines: lit by a panorama adjusted once by the user's controls.

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
        """Light with a bare panorama under the user's controls; returns the seconds it took.

        For a caller that holds a panorama and no request: :meth:`adjust`, then
        :meth:`take_lighting`. A relighting of the library goes through
        :func:`render.relighting.prepare_relighting`, which adjusts the panorama once for the
        mode's choice, the guards and the engine.
        """
        start = time.perf_counter()
        controls = PanoramaControls(yaw_deg=yaw_deg, exposure=exposure, modulation=modulation)
        self.take_lighting(self.adjust(panorama, controls))
        return time.perf_counter() - start

    def adjust(self, panorama: Panorama, controls: PanoramaControls) -> AdjustedPanorama:
        """``panorama`` past this field's horizon, under ``controls`` (adjusted once).

        The blocked copy is kept while the same panorama (by identity) comes back, so a sequence
        of yaws adjusts one visible panorama and the pre-filter keyed on it stands.
        """
        return controls.adjusted(self._visible(panorama))

    def take_lighting(self, adjusted: AdjustedPanorama) -> EnvironmentLighting:
        """Light with a panorama already adjusted; returns the lighting (panorama and lights).

        The lights are made of ``adjusted.seen``. An engine that lights with the bare panorama
        and overrides :meth:`take_panorama` turns and scales it itself (the models' precomputed
        lighting rotates the harmonics of a panorama pre-filtered once, so a new yaw costs no
        new pre-filter): it is handed the panorama before the controls beside the lighting
        made here, which it shows.
        """
        c = adjusted.controls
        controls = self.settings.lighting_controls(
            yaw_deg=c.yaw_deg, exposure=c.exposure, modulation=c.modulation
        )
        environment = adjusted.environment(controls)
        turns_itself = type(self).take_panorama is not PanoramaLitEngine.take_panorama
        if controls.lighting == "panorama" and turns_itself:
            self.take_panorama(adjusted.visible, environment)
        else:
            self.set_environment(environment)
        return environment

    def take_panorama(self, visible: Panorama, lighting: EnvironmentLighting) -> None:
        """Light with ``visible`` turned and scaled by the engine itself (engines may override).

        Parameters
        ----------
        visible : Panorama, before the controls (past the field's horizon)
        lighting : EnvironmentLighting, what the controls made of it (the adjusted panorama,
            recorded under the controls): the lighting the engine shows

        Called by :meth:`take_lighting` only for an override; this default takes ``lighting``.
        """
        self.set_environment(lighting)

    def set_environment(self, lighting: EnvironmentLighting) -> None:
        """Take a lighting made by :func:`light_environment` (each engine its own way)."""
        raise NotImplementedError

"""The relighting engine: a field, a lighting and a view in, a relit image out.

State lives here (the open field, the current lighting's weights, the current view's camera
blend and splat plan), so an interactive loop pays only for what changed. A new lighting at an
unchanged view is one pass over the view's blended field (built once per view, :class:`ViewField`);
a new view under an unchanged lighting blends the per-camera relit samples, each computed once
per lighting (:func:`relight_camera`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Literal, get_args

import numba
import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.errors import InputError
from core.field_store import ReflectanceField
from core.light_set import LightSet
from processing.environment import EnvironmentLighting, LightingControls
from processing.interpolation import InterpolationMethod, OutsidePolicy
from processing.sample_models import SampleModels
from processing.sampling import SamplerName
from render.engines.panorama_lit import PanoramaLitEngine
from render.engines.paper_sums import (
    ViewBlend,
    ViewField,
    blend_cameras,
    blend_field,
    relight_camera,
    relight_view,
)
from render.field_view import FieldView
from render.light_weights import (
    LightWeights,
    pixel_light_weights,
    projection_light_weights,
    sampled_light_weights,
)

__all__ = [
    "SCHEMES",
    "Predictor",
    "RelightSettings",
    "Relighter",
    "RelitImage",
    "Scheme",
    "best_settings",
]

Scheme = Literal["sampled", "pixels", "projection"]
#: How the panorama lights the measured field (see :class:`RelightSettings`).
SCHEMES: tuple[Scheme, ...] = get_args(Scheme)
#: What predicts an unmeasured light or view: ("model", name, 0) or ("interpolation", method,
#: m), m the neighbours of the paper's cosine interpolation (0 for the other methods).
Predictor = tuple[str, str, int]


@dataclass(frozen=True)
class RelightSettings:
    """How to relight by interpolating the measured values; a relighting mode.

    The defaults are the paper's pipeline with our sampling improvements; a relighting mode in
    the sense of :class:`render.engines.modes.RelightMode`.

    Attributes
    ----------
    scheme : "sampled" (eq. 3), "pixels" (eq. 2, rearranged) or "projection" (Voronoi cells
        of the measured lights)
    k, sampler, seed, paper : environment sampling (``sampled`` only); ``paper`` diffuses
        plain pixel luminance as the paper did
    interpolation, m : over the measured lights; n, view_interpolation : over the cameras
    policy : light from outside the measured lights' region ("clamp" or "zero")
    normal_bins, grid_height : ``pixels`` only (see ``pixel_light_weights``)
    """

    scheme: Scheme = "sampled"
    k: int = 64
    sampler: SamplerName = "tmed"
    seed: int = 0
    paper: bool = False
    interpolation: InterpolationMethod = "paper"
    m: int = 3
    view_interpolation: InterpolationMethod = "paper"
    n: int = 3
    policy: OutsidePolicy = "clamp"
    normal_bins: int | None = 4096
    grid_height: int | None = 64

    #: Interpolation relights from the field's values; a fit only informs its warnings.
    uses_models = False

    def __post_init__(self) -> None:
        if self.scheme not in SCHEMES:
            raise InputError(f"unknown scheme {self.scheme!r}; use one of {', '.join(SCHEMES)}")

    @classmethod
    def paper_configuration(cls, k: int = 64) -> RelightSettings:
        """The paper exactly: TMED on pixel luminance, Voronoi gathering, cosine m x n, eq. 3."""
        return cls(scheme="sampled", k=k, sampler="tmed", paper=True, interpolation="paper")

    @property
    def sampled_k(self) -> int | None:
        """K of the sampled lighting, None when every panorama pixel lights."""
        return self.k if self.scheme == "sampled" else None

    def lighting_controls(
        self,
        *,
        yaw_deg: float = 0.0,
        exposure: float = 1.0,
        modulation: NDArray[np.floating] | None = None,
    ) -> LightingControls:
        """The lighting this mode takes from a panorama under the user's controls."""
        if self.scheme != "sampled":
            return LightingControls(
                lighting="panorama", modulation=modulation, yaw_deg=yaw_deg, exposure=exposure
            )
        return LightingControls(
            lighting="sampled",
            k=self.k,
            method=self.sampler,
            seed=self.seed,
            paper=self.paper,
            modulation=modulation,
            yaw_deg=yaw_deg,
            exposure=exposure,
        )

    def predictors(self) -> tuple[Predictor, Predictor]:
        """What predicts an unmeasured light, and an uncaptured view."""
        m = self.m if self.interpolation == "paper" else 0
        n = self.n if self.view_interpolation == "paper" else 0
        return ("interpolation", self.interpolation, m), (
            "interpolation",
            self.view_interpolation,
            n,
        )

    def exact_lighting(self, grid_height: int) -> RelightSettings:
        """The same interpolation with every panorama pixel as a light."""
        del grid_height  # eq. 2 sums every pixel already
        return replace(self, scheme="pixels", paper=False)

    def describe(self, models: SampleModels | None = None) -> str:
        """A short name for reports."""
        del models
        return f"{self.scheme}, {self.interpolation}"

    def open(self, field_store: ReflectanceField, models: SampleModels | None = None) -> Relighter:
        """The engine of this mode."""
        del models  # interpolation relights from the field's values
        return Relighter(field_store, self)


def best_settings(field_store: ReflectanceField) -> RelightSettings:
    """The most accurate interpolation of a field's values, as measured on the simulator.

    Every panorama pixel as a light (eq. 2 over each normal's hemisphere) with barycentric
    interpolation over the measured lights and cameras: the lowest error of the linear schemes
    in the accuracy study (docs/relighting.md). Whether per-sample models do better is decided
    per field by :func:`render.engines.modes.most_accurate_mode`.
    """
    del field_store  # every field supports it
    return RelightSettings(
        scheme="pixels", interpolation="barycentric", view_interpolation="barycentric"
    )


@dataclass(frozen=True)
class RelitImage:
    """One relit view.

    Attributes
    ----------
    rgb : ndarray, shape (H, W, 3), float32, linear radiance (0 where uncovered)
    coverage : ndarray, shape (H, W), bool
    radiance : ndarray, shape (P, 3), float32, relit samples (0 where not needed or holes)
    needed : ndarray, shape (P,), bool, the samples this view shows (the ones relit)
    holes : ndarray, shape (P,), bool, needed samples no chosen camera sees
    outside_fraction : float, share of the light from outside the measured region
    seconds : dict, time of each stage of this frame
    """

    rgb: NDArray[np.float32]
    coverage: NDArray[np.bool_]
    radiance: NDArray[np.float32]
    needed: NDArray[np.bool_]
    holes: NDArray[np.bool_]
    outside_fraction: float
    seconds: dict[str, float] = field(default_factory=dict)


class Relighter(PanoramaLitEngine):
    """Relight one field under changing lightings and views."""

    settings: RelightSettings

    def __init__(self, field_store: ReflectanceField, settings: RelightSettings | None = None):
        self.field = field_store
        super().__init__(field_store)
        self.settings = settings or RelightSettings()
        self._lighting: LightWeights | None = None
        self._environment: EnvironmentLighting | None = None
        self._view: tuple[ViewBlend, FieldView] | None = None
        self._view_field: ViewField | None = None
        # (S, P, 3): each measured camera's radiance under the lighting, filled as views need
        # them (np.zeros maps pages on first write, so unused cameras cost no memory).
        self._camera_radiance: NDArray[np.float32] | None = None
        self._radiance_ready = np.zeros(field_store.shape[0], dtype=bool)
        self._view_changed = True
        self._spacing: float | None = None
        if self.settings.scheme == "pixels" and field_store.normals is None:
            # Pixel fields without normals: eq. 2 without the hemisphere test.
            self.settings = replace(self.settings, normal_bins=None)

    @property
    def lights(self) -> LightSet | None:
        """The sampled lights of the current lighting (``sampled`` scheme only)."""
        return None if self._environment is None else self._environment.lights

    @property
    def environment(self) -> EnvironmentLighting | None:
        """The current lighting: the panorama as relit (yaw, exposure) and its lights."""
        return self._environment

    def set_environment(self, lighting: EnvironmentLighting) -> None:
        """Compute the light weights of a lighting (from :func:`light_environment`)."""
        s = self.settings
        rgb = lighting.panorama.rgb
        measured = self.field.light_directions
        if s.scheme == "sampled":
            if lighting.lights is None:
                raise InputError("the sampled scheme needs sampled lights, not a bare panorama")
            self._lighting = sampled_light_weights(
                lighting.lights, measured, s.interpolation, m=s.m, policy=s.policy
            )
        elif s.scheme == "pixels":
            self._lighting = pixel_light_weights(
                rgb,
                measured,
                self.field.normals,
                s.interpolation,
                m=s.m,
                policy=s.policy,
                normal_bins=s.normal_bins,
                grid_height=s.grid_height,
            )
        else:
            self._lighting = projection_light_weights(rgb, measured)
        self._environment = lighting
        self._radiance_ready[:] = False

    def set_view(self, camera: PinholeCamera) -> float:
        """Blend the cameras for a view and plan its splats; returns the seconds it took."""
        start = time.perf_counter()
        view = FieldView(self.field, camera, spacing=self._spacing)
        self._spacing = view.spacing
        blend = blend_cameras(
            self.field, camera, self.settings.view_interpolation, n=self.settings.n,
            needed=view.needed,
        )  # fmt: skip
        self._view = (blend, view)
        self._view_field = None
        self._view_changed = True
        return time.perf_counter() - start

    def render(self) -> RelitImage:
        """Relight the current view under the current lighting."""
        if self._lighting is None or self._view is None:
            raise InputError("set a lighting and a view before rendering")
        blend, view = self._view
        start = time.perf_counter()
        if self._view_changed:
            radiance = self._blend_camera_radiance(blend)
            self._view_changed = False
        else:
            if self._view_field is None:
                self._view_field = blend_field(self.field, blend)
            radiance = relight_view(self._view_field, self._lighting)
        relit = time.perf_counter()
        rgb = view.image(radiance)
        done = time.perf_counter()
        return RelitImage(
            rgb=rgb,
            coverage=view.coverage,
            radiance=radiance,
            needed=view.needed,
            holes=blend.holes,
            outside_fraction=self._lighting.outside_fraction,
            seconds={"relight": relit - start, "splat": done - relit},
        )

    def _blend_camera_radiance(self, blend: ViewBlend) -> NDArray[np.float32]:
        assert self._lighting is not None
        s_count, _, p_count = self.field.shape
        if self._camera_radiance is None:
            self._camera_radiance = np.zeros((s_count, p_count, 3), dtype=np.float32)
        for camera in blend.cameras:
            if not self._radiance_ready[camera]:
                self._camera_radiance[camera] = relight_camera(
                    self.field, int(camera), self._lighting
                )
                self._radiance_ready[camera] = True
        radiance = np.empty((p_count, 3), dtype=np.float32)
        _blend_radiance(blend.cameras, blend.weights, self._camera_radiance, radiance)
        return radiance


@numba.njit(cache=True, parallel=True)
def _blend_radiance(
    cameras: NDArray[np.int64],
    weights: NDArray[np.float32],
    camera_radiance: NDArray[np.float32],
    out: NDArray[np.float32],
) -> None:
    """out[p] = sum_c weights[c, p] camera_radiance[cameras[c], p]: one pass, no temporaries."""
    for p in numba.prange(out.shape[0]):
        r = g = b = numba.float32(0.0)
        for row in range(cameras.shape[0]):
            w = weights[row, p]
            if w != 0.0:
                source = camera_radiance[cameras[row], p]
                r += w * source[0]
                g += w * source[1]
                b += w * source[2]
        out[p, 0] = r
        out[p, 1] = g
        out[p, 2] = b

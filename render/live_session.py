"""Over 500 lines because one session holds the viewer's state and redoes only what changed.

A live relighting session: the viewer's state, and one frame per change of its controls.

The browser viewer (``rig view``) is a page over this class. The session holds the field, the
two modes a person switches between (the paper's configuration and the best mode: for a field
of points the mode chosen by held-out lights, :func:`render.engines.modes.most_accurate_mode`;
for a field of pixels, an RTI capture, ``rig relight --env --fast``'s choice under each
panorama, :func:`render.environment_choice.choose_environment_mode`, made once a panorama at
its first frame and kept as it turns) and the loaded panoramas and modulation maps. Each frame
is a :class:`render.relighting.RelightRequest` run through the library's relighting, as ``rig
relight`` runs one, kept in a :class:`render.relighting.RelightingCache` so that a change costs
what it changes: a new yaw, exposure or panorama relights, an orbit or zoom re-plans the view,
a new K or sampler opens the paper's mode anew (its engine holds no precomputation).

Controls are plain data (:class:`LiveControls`, built from the page's JSON with every value
checked); a frame (:class:`LiveFrame`) carries the 8-bit pictures the page shows, the linear
image it saves, the guards' warnings and the time of each stage.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any, Literal, get_args

import cv2
import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.colour import luminance
from core.errors import InputError
from core.field_store import ReflectanceField
from core.splat import require_outside
from processing.environment import EnvironmentLighting
from processing.image_quality import relative_rmse_values
from processing.panorama import Panorama
from processing.sampling import SAMPLERS, SamplerName
from render.engines.interpolated import RelightSettings, RelitImage
from render.engines.models import ModelRelightSettings
from render.engines.modes import ModeChoice, RelightMode
from render.environment_choice import EnvironmentChoice, choose_environment_mode
from render.output import display_picture
from render.overlay import sample_overlay
from render.relighting import (
    LitRelighting,
    PanoramaControls,
    RelightingCache,
    RelightRequest,
    relighting_warnings,
)
from render.tonemap import auto_exposure, tone_mapped_8bit

__all__ = [
    "LIVE_MODES",
    "PANORAMA_PICTURE_HEIGHT",
    "LiveControls",
    "LiveFrame",
    "LiveMode",
    "LiveSession",
    "TruthComparison",
    "TruthRenderer",
    "error_picture",
]

LiveMode = Literal["paper", "best"]
#: The modes a person switches between: the paper's configuration, and the field's best.
LIVE_MODES: tuple[LiveMode, ...] = get_args(LiveMode)
#: Rows of the panorama picture sent to the page (the overlay is drawn at full size first).
PANORAMA_PICTURE_HEIGHT = 256
#: Relative error at the top of the error picture's colour scale (|relit - truth| over the
#: truth's mean).
ERROR_FULL_SCALE = 0.5
#: Widest and narrowest zoom: the camera's distance divided by it.
ZOOM_RANGE = (0.25, 8.0)

#: The ground truth of a view under a panorama's radiance (H, 2H, 3), already rotated and scaled
#: by the controls: linear RGB (H, W, 3) and coverage (H, W). Simulated fields have one (the
#: app layer passes the simulator's, :func:`sim.ground_truth.field_truth`), captured ones none.
TruthRenderer = Callable[
    [NDArray[np.float32], PinholeCamera], tuple[NDArray[np.float32], NDArray[np.bool_]]
]


@dataclass(frozen=True)
class LiveControls:
    """What the person set: the lighting, the view and what to show.

    Attributes
    ----------
    mode : "paper" or "best"
    panorama : str, the name of a loaded panorama
    yaw_deg : float, counter-clockwise rotation of the environment seen from above, degrees
    exposure : float, radiance scale (> 0)
    k : int, sampled lights of the paper's mode (and of the best mode, where it samples)
    sampler : str, one of :data:`processing.sampling.SAMPLERS`
    modulation : str or None, the name of a loaded modulation map (sampled lights only)
    azimuth_deg, inclination_deg : float, the view (fields of points), degrees
    zoom : float, the camera's distance divided by this
    truth : bool, render the ground truth and the error beside the frame (simulated fields)
    exact : bool, the best mode summed exactly; off, a best mode of models relights through
        precomputed lighting (:mod:`render.precomputed_lighting`: interactive, a few per cent
        off on glossy objects), and the viewer refines to the exact sum when the person stops
    """

    mode: LiveMode = "best"
    panorama: str = ""
    yaw_deg: float = 0.0
    exposure: float = 1.0
    k: int = 64
    sampler: SamplerName = "tmed"
    modulation: str | None = None
    azimuth_deg: float = 0.0
    inclination_deg: float = 45.0
    zoom: float = 1.0
    truth: bool = False
    exact: bool = False

    def __post_init__(self) -> None:
        if self.mode not in LIVE_MODES:
            raise InputError(f"mode {self.mode!r}: use one of {', '.join(LIVE_MODES)}")
        if self.sampler not in SAMPLERS:
            raise InputError(f"sampler {self.sampler!r}: use one of {', '.join(SAMPLERS)}")
        for name in ("yaw_deg", "exposure", "azimuth_deg", "inclination_deg", "zoom"):
            if not math.isfinite(getattr(self, name)):
                raise InputError(f"{name} must be a finite number, got {getattr(self, name)}")
        if self.exposure <= 0:
            raise InputError(f"exposure must be positive, got {self.exposure}")
        if not 1 <= self.k <= 4096:
            raise InputError(f"k must be between 1 and 4096, got {self.k}")
        if not 0.0 < self.inclination_deg <= 90.0:
            raise InputError(f"inclination must be in (0, 90] degrees, got {self.inclination_deg}")
        if not ZOOM_RANGE[0] <= self.zoom <= ZOOM_RANGE[1]:
            raise InputError(f"zoom must be between {ZOOM_RANGE[0]} and {ZOOM_RANGE[1]}")

    def updated(self, changes: Mapping[str, Any]) -> LiveControls:
        """These controls with ``changes`` (the page's JSON) applied, each value checked."""
        known = {f.name: f for f in fields(self)}
        values: dict[str, Any] = {}
        for name, value in changes.items():
            if name not in known:
                raise InputError(f"unknown control {name!r}; known: {', '.join(known)}")
            values[name] = _control_value(name, value)
        return replace(self, **values)

    def to_json(self) -> dict[str, Any]:
        """The controls as plain JSON (the settings a person saves)."""
        return asdict(self)

    def lighting_key(self) -> tuple[Any, ...]:
        """What the lighting depends on (a change relights).

        ``exact`` is not part of it: it picks another engine, and the panorama as lit and the
        warnings are the same for the exact frame that refines an interactive one.
        """
        return (self.mode, self.panorama, self.yaw_deg, self.exposure, self.k, self.sampler,
                self.modulation)  # fmt: skip


def _control_value(name: str, value: Any) -> Any:
    numbers = {"yaw_deg", "exposure", "azimuth_deg", "inclination_deg", "zoom"}
    try:
        if name in numbers:
            if isinstance(value, bool):
                raise TypeError
            return float(value)
        if name == "k":
            if isinstance(value, bool) or int(value) != value:
                raise TypeError
            return int(value)
        if name in ("truth", "exact"):
            if not isinstance(value, bool):
                raise TypeError
            return value
        if name == "modulation" and value is None:
            return None
        if not isinstance(value, str):
            raise TypeError
        return value
    except (TypeError, ValueError):
        raise InputError(f"control {name}: {value!r} is not a valid value") from None


@dataclass(frozen=True)
class LiveFrame:
    """One frame of the session.

    Attributes
    ----------
    controls : LiveControls, what it was rendered under
    picture : ndarray, shape (H, W, 3), uint8, the relit view, tone-mapped sRGB
    image : RelitImage, the linear relit view (what is saved as EXR)
    panorama_picture : ndarray, shape (h, 2h, 3), uint8, the panorama as lit (yaw, exposure),
        with the sampled lights and their cells where the mode samples
    notes : tuple of str, what the controls could not do here (a modulation map in a mode
        that does not sample, say)
    mode : str, the mode's description
    seconds : dict, time of each stage: "lighting", "view", "render", "display"
    camera, environment, relight_mode, exposure : the view, the lighting (panorama as lit and
        its lights), the mode and the display exposure of the frame
    """

    controls: LiveControls
    picture: NDArray[np.uint8]
    image: RelitImage
    panorama_picture: NDArray[np.uint8]
    notes: tuple[str, ...]
    mode: str
    seconds: dict[str, float]
    camera: PinholeCamera
    environment: EnvironmentLighting
    relight_mode: RelightMode
    exposure: float


@dataclass(frozen=True)
class TruthComparison:
    """A frame beside the ground truth.

    Attributes
    ----------
    picture : ndarray, shape (H, W, 3), uint8, the truth at the frame's display exposure
    error_picture : ndarray, shape (H, W, 3), uint8, the relative error (:func:`error_picture`)
    relative_rmse : float, over the pixels both cover
    seconds : float, time to render the truth and compare
    """

    picture: NDArray[np.uint8]
    error_picture: NDArray[np.uint8]
    relative_rmse: float
    seconds: float


def error_picture(
    rgb: NDArray[np.floating], truth: NDArray[np.floating], coverage: NDArray[np.bool_]
) -> tuple[NDArray[np.uint8], float]:
    """A heat map of the relative error, and the relative RMSE, over covered pixels.

    Parameters
    ----------
    rgb, truth : ndarray, shape (H, W, 3), linear radiance
    coverage : ndarray, shape (H, W), bool, pixels both images cover

    Returns
    -------
    picture : ndarray, shape (H, W, 3), uint8, |rgb - truth| in luminance over the truth's mean
        luminance, 0 dark to :data:`ERROR_FULL_SCALE` and above bright (inferno colour map)
    relative_rmse : float, sqrt(mean |rgb - truth|^2 / mean |truth|^2) over covered pixels (nan
        when nothing is covered)
    """
    height, width = coverage.shape
    if not coverage.any():
        return np.zeros((height, width, 3), np.uint8), math.nan
    a, b = np.asarray(rgb, np.float64), np.asarray(truth, np.float64)
    difference = np.abs(luminance(a) - luminance(b))
    scale = max(float(np.mean(luminance(b)[coverage])), 1e-12)
    level = np.clip(difference / scale / ERROR_FULL_SCALE, 0.0, 1.0)
    grey = np.where(coverage, np.round(level * 255.0), 0).astype(np.uint8)
    picture = cv2.applyColorMap(grey, cv2.COLORMAP_INFERNO)[:, :, ::-1]
    picture[~coverage] = 0
    return np.ascontiguousarray(picture), relative_rmse_values(a, b, coverage)


class LiveSession:
    """A field relit live: controls in, frames out.

    Parameters
    ----------
    field : ReflectanceField
    best : ModeChoice, the field's most accurate mode (:func:`most_accurate_mode`)
    panoramas : mapping of name to Panorama, at least one
    size : (width, height) of views of a field of points (a field of pixels has its own)
    truth : TruthRenderer, optional, the ground truth of a simulated field
    source : Path, optional, what the person opened (an RTI capture is imported into a
        temporary store: its path would say nothing); default the field's store
    """

    def __init__(
        self,
        field: ReflectanceField,
        best: ModeChoice,
        panoramas: Mapping[str, Panorama],
        *,
        size: tuple[int, int] = (512, 512),
        truth: TruthRenderer | None = None,
        source: Path | None = None,
    ) -> None:
        if not panoramas:
            raise InputError("the viewer needs at least one panorama")
        self.field = field
        self.source = source or field.path
        self.best = best
        self.size = size
        self.truth = truth
        self.panoramas: dict[str, Panorama] = dict(panoramas)
        self.modulations: dict[str, NDArray[np.float32]] = {}
        self._relighting = RelightingCache(field, models=best.models, comparison=best.comparison)
        self._lit: LitRelighting | None = None
        self._display_exposure: dict[str, float] = {}
        self._panorama_pictures: dict[tuple[Any, ...], NDArray[np.uint8]] = {}
        self._truths: dict[tuple[Any, ...], tuple[NDArray[np.float32], NDArray[np.bool_]]] = {}
        self._warnings: dict[tuple[Any, ...], tuple[str, ...]] = {}
        self._choices: dict[str, EnvironmentChoice] = {}
        self.frame: LiveFrame | None = None
        self._outside_checked: PinholeCamera | None = None
        start = field.cameras[0]
        self.initial = LiveControls(
            panorama=next(iter(self.panoramas)),
            azimuth_deg=start.azimuth_deg,
            inclination_deg=min(max(start.inclination_deg, 1.0), 90.0),
        )

    @property
    def can_orbit(self) -> bool:
        """Whether the view turns: a field of points; a field of pixels holds one view."""
        return self.field.sample_kind == "points"

    def add_panorama(self, name: str, panorama: Panorama) -> None:
        """Load a panorama under ``name`` (a name already loaded is replaced)."""
        self.panoramas[name] = panorama
        self._display_exposure.pop(name, None)
        self._forget(name)

    def add_modulation(self, name: str, modulation: NDArray[np.floating]) -> None:
        """Load a modulation map (any resolution, grey or RGB, non-negative) under ``name``."""
        values = np.asarray(modulation, dtype=np.float32)
        if values.ndim not in (2, 3) or not np.all(np.isfinite(values)) or np.any(values < 0):
            raise InputError(f"modulation {name!r}: an image of finite values >= 0 is needed")
        if not np.any(values > 0):
            raise InputError(f"modulation {name!r} is zero everywhere: no light could be sampled")
        self.modulations[name] = values
        self._forget(name)

    def _forget(self, name: str) -> None:
        """Drop what was computed with a panorama or map now replaced.

        The engines need no word: the relighting tells panoramas and maps by identity, and a
        replaced one is a new object.
        """
        for cache in (self._panorama_pictures, self._truths, self._warnings):
            for key in [key for key in cache if name in key]:
                del cache[key]
        self._choices.pop(name, None)

    def environment_choice(self, name: str) -> EnvironmentChoice | None:
        """The best mode's choice under panorama ``name`` (None for a field of points).

        Made at the panorama's first frame (seconds: each quick rung is fitted on held-out
        lights; the learned rung, minutes, is left out as by ``--fast``) and kept while the
        panorama turns: the rung that relights its sharp light best stays the best.
        """
        if self.field.sample_kind != "pixels":
            return None
        if name not in self._choices:
            seen = PanoramaControls().as_seen(self.panoramas[name], self.field)
            self._choices[name] = choose_environment_mode(
                self.field, seen, models=self.best.models, fast=True
            )
        return self._choices[name]

    def best_reason(self, name: str) -> str:
        """Why the best mode relights as it does under panorama ``name``.

        Quick: a choice not made yet is said to come with the panorama's first frame.
        """
        if self.field.sample_kind != "pixels":
            return self.best.reason
        choice = self._choices.get(name)
        if choice is None:
            return (
                f"the rung that relights under {name} best is chosen at its first frame, by "
                "held-out lights (seconds)"
            )
        return choice.reason

    def mode(self, controls: LiveControls) -> RelightMode:
        """The relighting mode of the controls."""
        if controls.mode == "paper":
            return replace(
                RelightSettings.paper_configuration(k=controls.k), sampler=controls.sampler
            )
        choice = self.environment_choice(controls.panorama)
        mode = self.best.mode if choice is None else choice.mode
        if mode.sampled_k is not None:
            mode = replace(mode, k=controls.k, sampler=controls.sampler)  # type: ignore[type-var]
        exact_models = isinstance(mode, ModelRelightSettings) and mode.lighting == "grid"
        if exact_models and not controls.exact:
            mode = replace(mode, lighting="precomputed")  # type: ignore[type-var]
        return mode

    def refinable(self, controls: LiveControls) -> bool:
        """Whether the exact sum would render these controls differently (and slower)."""
        return self.mode(controls) != self.mode(replace(controls, exact=True))

    def camera(self, controls: LiveControls) -> PinholeCamera:
        """The view of the controls (a field of pixels: its own camera)."""
        if not self.can_orbit:
            return self.field.cameras[0]
        start = self.field.cameras[0]
        return PinholeCamera(
            controls.azimuth_deg % 360.0,
            controls.inclination_deg,
            start.distance / controls.zoom,
            start.fov_deg,
            self.size[0],
            self.size[1],
        )

    def render(self, controls: LiveControls) -> LiveFrame:
        """Relight under ``controls``, recomputing only what changed since the last frame."""
        if controls.panorama not in self.panoramas:
            raise InputError(
                f"no panorama {controls.panorama!r}; loaded: {', '.join(self.panoramas)}"
            )
        if controls.modulation is not None and controls.modulation not in self.modulations:
            raise InputError(f"no modulation map {controls.modulation!r} is loaded")
        mode = self.mode(controls)
        notes: list[str] = []
        modulation = None
        if controls.modulation is not None:
            if mode.sampled_k is None:
                notes.append(
                    f"the modulation map steers sampled lights; {mode.describe()} lights with "
                    "every part of the panorama, so it is not applied"
                )
            else:
                modulation = self.modulations[controls.modulation]
        camera = self.camera(controls)
        if self.field.points is not None and self.can_orbit and camera != self._outside_checked:
            require_outside(self.field.points, camera)  # a pass over the cloud: once a view
            self._outside_checked = camera
        lighting = PanoramaControls(
            yaw_deg=controls.yaw_deg, exposure=controls.exposure, modulation=modulation
        )
        request = RelightRequest(
            panorama=self.panoramas[controls.panorama], camera=camera, lighting=lighting, mode=mode
        )
        lit = self._relighting.prepare(request)
        seconds = dict(lit.seconds)
        start = time.perf_counter()
        image = lit.engine.render()
        seconds["render"] = time.perf_counter() - start
        start = time.perf_counter()
        environment = lit.environment
        exposure = self._exposure(controls, image)
        picture = display_picture(image.rgb, image.coverage, exposure)
        panorama_picture = self._panorama_picture(controls.lighting_key(), environment)
        seconds["display"] = time.perf_counter() - start
        if controls.truth and self.truth is None:
            notes.append("this field has no ground truth (it was not simulated)")
        self._lit = lit
        self.frame = LiveFrame(
            controls=controls,
            picture=picture,
            image=image,
            panorama_picture=panorama_picture,
            notes=tuple(notes),
            mode=mode.describe(self.best.models if mode.uses_models else None),
            seconds=seconds,
            camera=camera,
            environment=environment,
            relight_mode=mode,
            exposure=exposure,
        )
        return self.frame

    def _last_frame(self) -> LiveFrame:
        if self.frame is None:
            raise InputError("no frame has been rendered yet")
        return self.frame

    def idle_controls(self, controls: LiveControls) -> dict[str, str]:
        """The controls that change nothing in the mode ``controls`` select, each with why.

        A page disables them and says why, rather than re-rendering the same frame.
        """
        mode = self.mode(controls)
        if mode.sampled_k is not None:
            return {}
        described = mode.describe(self.best.models if mode.uses_models else None)
        why = (
            f"every part of the panorama lights ({described}): K, the sampler and a modulation "
            "map steer sampled lights (the paper's configuration)"
        )
        return {"k": why, "sampler": why, "modulation": why}

    def warnings(self) -> tuple[str, ...]:
        """The guards' warnings for the last frame's lighting and view.

        Apart from :meth:`render` (about 0.1 s: they read the panorama and the capture), so a
        viewer shows the frame first. Where a warning's remedy is relighting through the
        models and the best mode does, it names the page's mode rather than a flag.
        """
        frame = self._last_frame()
        key = (*frame.controls.lighting_key(), frame.camera)
        if key not in self._warnings:
            lit = self._lit
            assert lit is not None  # set with the frame
            found = relighting_warnings(self.field, lit.camera, lit.seen, lit.chosen)
            remedy = "--scheme model"
            if self.mode(replace(frame.controls, mode="best")).uses_models:
                remedy = "the viewer's best mode"
            self._warnings = {
                key: tuple(str(warning).replace("--scheme model", remedy) for warning in found)
            }
        return self._warnings[key]

    def compare_truth(self) -> TruthComparison | None:
        """The last frame beside the ground truth (None without a truth renderer)."""
        if self.truth is None:
            return None
        frame = self._last_frame()
        c = frame.controls
        start = time.perf_counter()
        key = (c.panorama, c.yaw_deg, c.exposure, frame.camera)
        if key not in self._truths:
            self._truths = {key: self.truth(frame.environment.panorama.rgb, frame.camera)}
        rgb, covered = self._truths[key]
        picture = display_picture(rgb, covered, frame.exposure)
        error, rmse = error_picture(frame.image.rgb, rgb, covered & frame.image.coverage)
        return TruthComparison(picture, error, rmse, time.perf_counter() - start)

    def _exposure(self, controls: LiveControls, image: RelitImage) -> float:
        """The display exposure: set by the first frame under each panorama, then fixed.

        Fixed so that the exposure control, a yaw or a mode change show as brighter or darker
        pictures rather than being undone by an automatic exposure.
        """
        if controls.panorama not in self._display_exposure:
            covered = image.rgb[image.coverage]
            automatic = auto_exposure(covered) if covered.size else 1.0
            self._display_exposure[controls.panorama] = automatic
        return self._display_exposure[controls.panorama]

    def _panorama_picture(
        self, lighting: tuple[Any, ...], environment: EnvironmentLighting
    ) -> NDArray[np.uint8]:
        if lighting not in self._panorama_pictures:
            rgb = environment.panorama.rgb
            exposure = auto_exposure(rgb)
            lights = environment.lights
            if lights is not None and lights.labels is not None and lights.k <= 4096:
                full = sample_overlay(rgb, lights, exposure=exposure)
            else:
                full = tone_mapped_8bit(rgb, exposure=exposure)
            height = min(PANORAMA_PICTURE_HEIGHT, full.shape[0])
            picture = cv2.resize(full, (2 * height, height), interpolation=cv2.INTER_AREA)
            self._panorama_pictures = {lighting: np.ascontiguousarray(picture)}
        return self._panorama_pictures[lighting]

    def settings(self) -> dict[str, Any]:
        """The current settings as JSON: controls, mode, panorama, field (to save or reload)."""
        frame = self._last_frame()
        controls = frame.controls
        return {
            "field": str(self.field.path),
            "controls": controls.to_json(),
            "mode": frame.mode,
            "panorama": self.panoramas[controls.panorama].source,
            "best_mode_reason": self.best_reason(controls.panorama),
            "camera": asdict(frame.camera),
        }

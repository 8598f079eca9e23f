"""A world the fitted models do not contain: fields and ground truth path-traced by Mitsuba 3.

The simulator's own worlds (:mod:`sim.scenes`) are built from the model family the per-sample
models fit (diffuse plus one GGX lobe, direct light only), so they cannot say how those models
fare on anything else. A Mitsuba world is a triangle mesh with any Mitsuba BSDF (principled with
textured roughness and metallic, coated plastics, anisotropic and coloured metals, layered
coats, non-Lambertian mattes), described in a TOML file (:mod:`sim.world.files`, bundled ones
in ``sim/worlds/``) and rendered by Mitsuba's path tracer with interreflections. From it come

- :func:`render_world_field`: a reflectance field in the store of :mod:`core.field_store`,
  the schema :func:`sim.field.simulate_field` writes, so every tool that reads a field reads it;
- :func:`render_world_environment`: the world under an equirectangular panorama, the ground
  truth relighting is compared with;
- :func:`render_noise`: how noisy those renderings are, measured without a reference.

How a field is made (``docs/world.md`` has the measurements): the scene is loaded once per
camera optics; per camera, a geometry pass (one ray through each pixel centre) tells which
samples the camera sees (:mod:`sim.world.visibility`); per light, the directional emitter is
turned through ``mi.traverse`` and the path tracer renders the image, from which each seen
sample reads its pixel's radiance. A light below a sample's horizon, or blocked, gives whatever
the path tracer gives (interreflected light, usually): this is a physical world, not the model.
Mitsuba runs in the ``scalar_rgb`` variant (``llvm_ad_rgb`` aborts the process on the
development machine, see :mod:`sim.mitsuba_reference`).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.directions import hemisphere_layout
from core.errors import InputError
from core.field_store import FieldStoreWriter, is_field_store
from core.progress import progress_bar
from sim.mitsuba_reference import DEFAULT_VARIANT, load_mitsuba
from sim.world.files import WORLDS, World, load_world
from sim.world.render import SAMPLER, WorldImage, WorldRenderer, render_environment_image
from sim.world.samples import WorldSamples, world_samples
from sim.world.visibility import SampleView, sample_view

__all__ = [
    "DEFAULT_ENVIRONMENT_SPP",
    "DEFAULT_FIELD_SPP",
    "DEFAULT_MAX_DEPTH",
    "FIELD_IMAGE_SIZE",
    "WORLDS",
    "World",
    "WorldNoise",
    "WorldSamples",
    "load_world",
    "render_noise",
    "render_world_environment",
    "render_world_field",
    "world_samples",
]

#: Samples per pixel of a field's images: 0.6-0.7 % noise per sample on the matte and clear-coat
#: worlds at FIELD_IMAGE_SIZE, 2.8-3.7 % on the glossy metals (docs/world.md, every world).
DEFAULT_FIELD_SPP = 256
#: Samples per pixel of the ground truth under a panorama: 0.5-0.6 % noise on the matte and
#: clear-coat worlds under the courtyard, 1.2-1.3 % on the glossy metals (docs/world.md).
DEFAULT_ENVIRONMENT_SPP = 4096
#: Longest path, in segments: 2 is direct light only (70-81 % of the light in the bowls); 8
#: leaves out less than 0.03 % (docs/world.md).
DEFAULT_MAX_DEPTH = 8
#: Image side of a benchmark field's cameras, pixels (about one pixel per sample spacing at
#: 20 000 samples on the torus knot at distance 4, fov 40).
FIELD_IMAGE_SIZE = 128


@dataclass(frozen=True)
class WorldNoise:
    """The noise of a rendering, from two renderings with different seeds.

    Relative noise = RMS over the set of (a - b) / sqrt 2 (the noise of one rendering, if the
    two are independent) divided by the mean of (a + b) / 2; over the three channels.

    Attributes
    ----------
    pixel : float, relative noise over the pixels both renderings cover fully (alpha >= 0.999)
    sample : float, relative noise of the radiance the field stores, over the samples the
        camera sees (what a fitted model sees of the noise)
    pixels, samples : int, how many pixels and samples the figures are over
    spp : int, samples per pixel each rendering took
    seconds : float, wall time of one rendering
    """

    pixel: float
    sample: float
    pixels: int
    samples: int
    spp: int
    seconds: float

    def to_json(self) -> dict[str, float | int]:
        """The figures as plain JSON."""
        return {"pixel": self.pixel, "sample": self.sample, "pixels": self.pixels,
                "samples": self.samples, "spp": self.spp, "seconds": self.seconds}  # fmt: skip


def _world(world: World | str | os.PathLike[str], variant: str) -> World:
    return world if isinstance(world, World) else load_world(world, variant=variant)


def _relative_noise(a: NDArray[np.floating], b: NDArray[np.floating]) -> float:
    """RMS of (a - b) / sqrt 2 over the mean of (a + b) / 2; NaN when the set is empty."""
    if a.size == 0:
        return float("nan")
    first, second = a.astype(np.float64), b.astype(np.float64)
    mean = 0.5 * float((first + second).mean())
    return float(np.sqrt(0.5 * np.mean((first - second) ** 2)) / mean) if mean > 0 else 0.0


def _noise(
    renderer: WorldRenderer, view: SampleView, toward: NDArray[np.float64], seeds: tuple[int, int]
) -> tuple[WorldNoise, WorldImage]:
    """Noise of one (camera, light) from two renderings; also returns the first rendering."""
    start = time.perf_counter()
    first = renderer.render(toward, seeds[0])
    seconds = time.perf_counter() - start
    second = renderer.render(toward, seeds[1])
    full = (first.alpha >= 0.999) & (second.alpha >= 0.999)
    seen = view.visible
    noise = WorldNoise(
        pixel=_relative_noise(first.rgb[full], second.rgb[full]),
        sample=_relative_noise(view.radiance(first)[seen], view.radiance(second)[seen]),
        pixels=int(full.sum()),
        samples=int(seen.sum()),
        spp=renderer.sample_count,
        seconds=seconds,
    )
    return noise, first


def _light_directions(lights: int | NDArray[np.floating], layout: str) -> NDArray[np.float64]:
    if isinstance(lights, int | np.integer):
        return hemisphere_layout(int(lights), layout)
    directions = np.asarray(lights, dtype=np.float64)
    if directions.ndim != 2 or directions.shape[1] != 3 or len(directions) == 0:
        raise InputError(f"lights must be a count or directions (T, 3), got {directions.shape}")
    length = np.linalg.norm(directions, axis=1)
    if not np.all(np.isfinite(directions)) or np.any(np.abs(length - 1.0) > 1e-3):
        raise InputError("light directions must be finite unit vectors (toward each light)")
    return directions / length[:, None]


def render_world_field(
    path: str | os.PathLike[str],
    world: World | str | os.PathLike[str],
    *,
    lights: int | NDArray[np.floating],
    cameras: list[PinholeCamera],
    points: int = 20_000,
    spp: int = DEFAULT_FIELD_SPP,
    max_depth: int = DEFAULT_MAX_DEPTH,
    seed: int = 0,
    layout: str = "grid",
    dtype: str = "float32",
    overwrite: bool = False,
    variant: str = DEFAULT_VARIANT,
) -> Path:
    """Write the path-traced reflectance field of a world to a new store; returns its path.

    Parameters
    ----------
    path : the store's directory (:class:`core.field_store.FieldStoreWriter`)
    world : World, or a world file's path, or a bundled world's name
    lights : int or ndarray, shape (T, 3)
        A count (directions of ``layout`` over the upper hemisphere) or unit vectors toward each
        light, rig frame. Each light is directional with unit irradiance.
    cameras : list of PinholeCamera, S >= 1 (one Mitsuba scene per distinct optics)
    points : int, surface samples P (:func:`world_samples` with ``seed``)
    spp : int, samples per pixel of every image
    max_depth : int, longest path in segments (2: direct light only)
    seed : int, of the samples' placement and of the renderings (each image its own sampler
        seed derived from it, so the noise of different images is independent)
    layout : str, of the lights when given as a count (``core.directions.hemisphere_layout``)
    dtype : {"float32", "float16"}, of the stored radiance
    overwrite : bool, replace a store already at ``path``
    variant : str, Mitsuba variant

    Returns
    -------
    Path of the finished store: ``radiance`` (S, T, P, 3) linear radiance per camera, light
    and sample; ``visibility`` (S, P); ``points`` and ``normals`` (P, 3); provenance with
    ``source = "mitsuba"``, the world (file text and digest), the render settings and the
    noise measured on camera 0 under light 0 (:class:`WorldNoise`, two seeds).

    Raises
    ------
    InputError
        A bad world, count, direction or setting, or an existing store without ``overwrite``.
    MitsubaUnavailableError
        Mitsuba 3 is not installed.
    """
    scene = _world(world, variant)
    if not cameras:
        raise InputError("a field needs at least one camera")
    if is_field_store(path) and not overwrite:
        # The writer refuses this too, but only once the noise check has rendered.
        raise InputError(
            f"{path}: a field store is already there; choose another path, or overwrite it"
        )
    directions = _light_directions(lights, layout)
    samples = world_samples(scene, points, seed)
    count = len(cameras) * len(directions)
    base = seed * (count + 1)  # each field's seeds apart from another seed's

    def image_seed(s: int, t: int) -> int:
        return (base + s * len(directions) + t) % 2**32

    renderers: list[WorldRenderer] = []

    def renderer_for(camera: PinholeCamera) -> WorldRenderer:
        match = next((r for r in renderers if r.accepts(camera)), None)
        if match is None:
            match = WorldRenderer(scene, camera, spp=spp, max_depth=max_depth, variant=variant)
            renderers.append(match)
        match.set_camera(camera)
        return match

    first_renderer = renderer_for(cameras[0])
    first_view = sample_view(samples, cameras[0], first_renderer.geometry())
    noise, first_image = _noise(
        first_renderer, first_view, directions[0], (image_seed(0, 0), (base + count) % 2**32)
    )
    mi = load_mitsuba(variant)
    store = FieldStoreWriter(
        path,
        overwrite=overwrite,
        points=samples.points,
        normals=samples.normals,
        light_directions=directions,
        cameras=cameras,
        dtype=dtype,
        provenance={
            "source": "mitsuba",
            "world": scene.to_json(),
            "points": points,
            "seed": seed,
            "layout": "given" if not isinstance(lights, int | np.integer) else layout,
            "renderer": {
                "mitsuba": str(mi.__version__),
                "variant": variant,
                "integrator": "path",
                "max_depth": max_depth,
                "sampler": SAMPLER,
                "spp": first_renderer.sample_count,
                "film": "hdrfilm, box filter",
                "radiance": "bilinear between the pixels showing the sample's surface, each "
                "divided by its coverage",
            },
            "noise": {"camera": 0, "light": 0, **noise.to_json()},
            "created": datetime.now(UTC).isoformat(timespec="seconds"),
        },
    )
    steps = progress_bar(total=count, desc="world field", unit="image")
    try:
        for s, camera in enumerate(cameras):
            renderer = renderer_for(camera)
            view = first_view if s == 0 else sample_view(samples, camera, renderer.geometry())
            store.write_visibility(s, view.visible)
            for t, direction in enumerate(directions):
                # Slab (0, 0) is the first of the noise check's two renderings, kept.
                image = (
                    first_image
                    if (s, t) == (0, 0)
                    else renderer.render(direction, image_seed(s, t))
                )
                store.write_slab(s, t, view.radiance(image))
                steps.update()
    except BaseException:
        store.abort()
        raise
    finally:
        steps.close()
    return store.finish()


def render_world_environment(
    world: World | str | os.PathLike[str],
    panorama_rgb: NDArray[np.floating],
    camera: PinholeCamera,
    *,
    spp: int = DEFAULT_ENVIRONMENT_SPP,
    max_depth: int = DEFAULT_MAX_DEPTH,
    seed: int = 0,
    upsample: int = 4,
    variant: str = DEFAULT_VARIANT,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """The ground truth of a world under an equirectangular panorama, path-traced.

    The panorama maps to Mitsuba's ``envmap`` exactly as :mod:`sim.mitsuba_reference` maps it
    (:func:`~sim.mitsuba_reference.envmap_texels`, :data:`~sim.mitsuba_reference.ENVMAP_TO_RIG`),
    so the image is on the pixel grid of :func:`sim.ground_truth.render_environment`.

    Parameters
    ----------
    world : World, or a world file's path, or a bundled world's name
    panorama_rgb : ndarray, shape (H, 2H, 3), linear radiance in the project's panorama
        convention (``docs/conventions.md``); reduce a large one first, as Mitsuba holds
        (upsample H + 1) x (upsample 2H) texels
    camera : PinholeCamera
    spp : int, samples per pixel
    max_depth : int, longest path in segments (2: direct light only)
    seed : int, of the sampler
    upsample : int, envmap texels per panorama pixel along each axis (see
        :func:`sim.mitsuba_reference.envmap_texels`)
    variant : str, Mitsuba variant

    Returns
    -------
    rgb : ndarray, shape (camera.height, camera.width, 3), float32, linear radiance, 0 where
        nothing is hit (silhouette pixels hold coverage x radiance)
    alpha : ndarray, shape (camera.height, camera.width), float32, the fraction of each pixel
        the world covers
    """
    image = render_environment_image(
        _world(world, variant), panorama_rgb, camera,
        spp=spp, max_depth=max_depth, seed=seed, upsample=upsample, variant=variant,
    )  # fmt: skip
    return image.rgb, image.alpha


def render_noise(
    world: World | str | os.PathLike[str],
    camera: PinholeCamera,
    light: NDArray[np.floating],
    spp: int = DEFAULT_FIELD_SPP,
    *,
    max_depth: int = DEFAULT_MAX_DEPTH,
    points: int = 20_000,
    seeds: tuple[int, int] = (1, 2),
    variant: str = DEFAULT_VARIANT,
) -> WorldNoise:
    """The noise of one field image and of the field values read from it, reference-free.

    Renders the world twice under one directional light with two sampler seeds; the noise of
    one rendering is the RMS of their difference over sqrt 2 (:class:`WorldNoise`), relative
    to the mean radiance, over the fully covered pixels and over the samples the camera sees.

    Parameters
    ----------
    world : World, or a world file's path, or a bundled world's name
    camera : PinholeCamera
    light : ndarray, shape (3,), unit vector toward the light, rig frame
    spp : int, samples per pixel
    max_depth : int, longest path in segments
    points : int, surface samples for the per-sample figure (seed 0, as a field's)
    seeds : two different sampler seeds
    variant : str, Mitsuba variant

    Returns
    -------
    WorldNoise
    """
    if seeds[0] == seeds[1]:
        raise InputError(f"the two seeds must differ, got {seeds}")
    scene = _world(world, variant)
    toward = _light_directions(np.asarray(light, dtype=np.float64)[None], "given")[0]
    renderer = WorldRenderer(scene, camera, spp=spp, max_depth=max_depth, variant=variant)
    view = sample_view(world_samples(scene, points), camera, renderer.geometry())
    return _noise(renderer, view, toward, seeds)[0]

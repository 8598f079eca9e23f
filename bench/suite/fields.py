"""What the benchmark relights: its environments and its opened fields with their ground truths.

A field is simulated once into the field cache and reused, its per-sample model fit is made
once and saved beside it, and the simulator's ground truth of each environment and view is
cached on disk; :func:`open_field` gathers all of it for the methods measured on the field.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NotRequired, TypedDict, cast

import numpy as np

from bench.sim_truth import Truth, between_view, field_path, truths_of_views
from bench.suite.methods import FieldSpec
from bench.suite.results import EnvironmentRecord, FieldRecord, SpecRecord
from core.camera_model import PinholeCamera
from core.field_store import ReflectanceField
from core.sample_data import PanoramaName, panorama_path
from processing.panorama import Panorama, panorama_from_array, read_panorama
from processing.sample_model_store import default_models_path, models_for_field, read_sample_models
from processing.sample_models import SampleModels
from sim.scenes import SurfaceSamples, build_scene, get_scene
from sim.skies import ldr_photo, procedural_sky
from sim.synthetic_camera import camera_visibility, image_of_points

__all__ = [
    "Environment",
    "FieldRun",
    "ModelsTiming",
    "environment_record",
    "environments",
    "field_record",
    "open_field",
    "spec_record",
    "views_of",
]


@dataclass(frozen=True)
class Environment:
    """A lighting of the benchmark.

    Attributes
    ----------
    name : str
    panorama : Panorama, what the relighting is given
    truth : str, the environment whose ground truth it is scored against (an LDR photo is
        scored against the HDR scene it was taken of)
    ldr : bool
    """

    name: str
    panorama: Panorama
    truth: str
    ldr: bool


def environments(names: Sequence[str], sky_height: int = 256) -> dict[str, Environment]:
    """The named environments.

    Parameters
    ----------
    names : "courtyard", "studio" (the bundled panoramas), "sky" (procedural, with a small,
        very bright sun), each optionally with " LDR" (its 8-bit sRGB photo)
    sky_height : int, rows of the procedural sky

    Returns
    -------
    dict of name to Environment, in the order of ``names``
    """
    hdr: dict[str, Panorama] = {}
    out: dict[str, Environment] = {}
    for name in names:
        base = name.removesuffix(" LDR")
        if base not in hdr:
            if base == "sky":
                hdr[base] = panorama_from_array(procedural_sky(sky_height), source="procedural sky")
            else:
                hdr[base] = read_panorama(panorama_path(cast(PanoramaName, base)))
        panorama = hdr[base]
        ldr = name != base
        if ldr:
            panorama = panorama_from_array(ldr_photo(panorama.rgb), source=f"{base} (LDR photo)")
        out[name] = Environment(name, panorama, base, ldr)
    return out


def environment_record(env: Environment) -> EnvironmentRecord:
    """The results' record of an environment: its truth, LDR or not, the panorama's source.

    Parameters
    ----------
    env : Environment

    Returns
    -------
    EnvironmentRecord
    """
    return {"truth": env.truth, "ldr": env.ldr, "source": env.panorama.source}


def views_of(field: ReflectanceField) -> dict[str, PinholeCamera]:
    """The two views every method is scored at.

    Parameters
    ----------
    field : ReflectanceField

    Returns
    -------
    dict: "captured" (the field's middle camera) and "between" (halfway in azimuth from it to
    its ring neighbour)
    """
    index = len(field.cameras) // 2
    return {"captured": field.cameras[index], "between": between_view(field.cameras, index)}


def _truths(
    cache: Path,
    scene: str,
    samples: SurfaceSamples,
    spec: FieldSpec,
    views: dict[str, PinholeCamera],
    envs: dict[str, Environment],
) -> dict[tuple[str, str], Truth]:
    """Ground truth of each HDR environment and view, cached on disk (radiance per sample)."""
    shadows = not get_scene(scene).convex
    out: dict[tuple[str, str], Truth] = {}
    for name in dict.fromkeys(env.truth for env in envs.values()):
        # An LDR photo asked for without its HDR scene: the truth is still the HDR one.
        hdr = envs[name] if name in envs else environments([name])[name]
        rgb = hdr.panorama.rgb
        # The panorama's sum and size tell a changed sky or file from the cached one.
        digest = f"{float(rgb.sum(dtype=np.float64)):.9e}-{rgb.shape[0]}"
        folder = cache / "truth" / f"{scene}-S{spec[0]}-T{spec[1]}-{spec[2]}-{spec[3]}px"
        path = folder / f"{name}-{digest}.npz"
        if path.exists():
            with np.load(path) as saved:
                for view, camera in views.items():
                    radiance = np.asarray(saved[view])
                    out[(name, view)] = Truth(
                        image_of_points(samples, camera, radiance),
                        radiance,
                        camera_visibility(samples, camera),
                    )
            continue
        truths = truths_of_views(samples, rgb, list(views.values()), shadows)
        path.parent.mkdir(parents=True, exist_ok=True)
        radiances: dict[str, Any] = {v: t.radiance for v, t in zip(views, truths, strict=True)}
        np.savez(path, **radiances)
        out |= {(name, view): t for view, t in zip(views, truths, strict=True)}
    return out


class ModelsTiming(TypedDict):
    """Seconds of a field's per-sample model fit (when known) and of loading it."""

    fit_s: NotRequired[float]
    load_s: float


@dataclass
class FieldRun:
    """One opened field of one scene, with what every method on it shares.

    Attributes
    ----------
    scene : str; spec : FieldSpec
    field : ReflectanceField; models : its per-sample model fit
    models_timing : the fit's and the load's seconds
    views : view name to camera (:func:`views_of`)
    truths : (HDR environment, view name) to the simulator's ground truth
    """

    scene: str
    spec: FieldSpec
    field: ReflectanceField
    models: SampleModels
    models_timing: ModelsTiming
    views: dict[str, PinholeCamera]
    truths: dict[tuple[str, str], Truth]


def _fit_and_load(field: ReflectanceField, path: Path) -> tuple[SampleModels, ModelsTiming]:
    """The field's models, fitted first if no run has, and the fit's and the load's seconds.

    The fit's time is kept beside the fit, since later runs only load it.
    """
    models_path = default_models_path(path)
    fit_record = models_path.with_name(models_path.name + ".fit.json")
    if not models_path.exists():
        start = time.perf_counter()
        models_for_field(field)
        fit_record.write_text(json.dumps({"fit_s": time.perf_counter() - start}) + "\n")
    fit_s = json.loads(fit_record.read_text())["fit_s"] if fit_record.exists() else None
    start = time.perf_counter()
    models = read_sample_models(models_path, field)
    load_s = time.perf_counter() - start
    timing: ModelsTiming = (
        {"load_s": load_s} if fit_s is None else {"fit_s": fit_s, "load_s": load_s}
    )
    return models, timing


def open_field(
    fields_dir: Path, cache: Path, scene: str, spec: FieldSpec, envs: dict[str, Environment]
) -> FieldRun:
    """Simulate (once) and open a field, its models, its views and their ground truths.

    Parameters
    ----------
    fields_dir : Path, the field cache (a directory named ``fields``)
    cache : Path, where ground truths are cached (``cache/truth``)
    scene : str, a simulator scene; spec : FieldSpec
    envs : the environments to have ground truths of

    Returns
    -------
    FieldRun
    """
    cameras, lights, points, size = spec
    start = time.perf_counter()
    path = field_path(fields_dir.parent, scene, cameras, lights, points, size, "float32")
    simulated_s = time.perf_counter() - start
    field = ReflectanceField.open(path)
    models, timing = _fit_and_load(field, path)
    views = views_of(field)
    samples = build_scene(scene, points)
    start = time.perf_counter()
    truths = _truths(cache, scene, samples, spec, views, envs)
    truth_s = time.perf_counter() - start
    print(
        f"field {scene} S={cameras} T={lights} {points} points {size}px: simulated/opened "
        f"{simulated_s:.1f} s, models {timing}, truths {truth_s:.1f} s",
        flush=True,
    )
    return FieldRun(scene, spec, field, models, timing, views, truths)


def spec_record(scene: str, spec: FieldSpec) -> SpecRecord:
    """The results' record of a field: scene, S, T, points and view side.

    Parameters
    ----------
    scene : str; spec : FieldSpec

    Returns
    -------
    SpecRecord
    """
    cameras, lights, points, size = spec
    return {"scene": scene, "S": cameras, "T": lights, "points": points, "image": size}


def field_record(run: FieldRun) -> FieldRecord:
    """The results' record of an opened field, with its model fit's times and its size.

    Parameters
    ----------
    run : FieldRun

    Returns
    -------
    FieldRecord
    """
    return {
        **spec_record(run.scene, run.spec),
        "models_fit_s": run.models_timing.get("fit_s"),
        "models_load_s": run.models_timing["load_s"],
        "field_MB": run.field.camera_slab(0).nbytes * run.spec[0] / 1e6,
    }

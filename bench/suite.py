"""The speed-against-accuracy benchmark: the paper's relighting and each change made to it.

Run: ``python -m bench.suite -o DIR [--quick] [--fields DIR]`` (``rig bench``). Writes
``DIR/results.json`` (every figure, and the machine), the charts and ``DIR/REPORT.md``
(:func:`bench.report.write_report`, generated from the results alone).

What is measured, for each scene of the simulator, reflectance field and relighting method:

- precompute: opening the engine (for per-sample models, loading their saved fit too; the fit
  itself is timed when this run makes it);
- time per new lighting (``set_lighting`` of a rotated panorama + ``render``) and per new view
  (``set_view`` of a turned camera + ``render``), medians after a warm-up frame;
- memory: the arrays the engine holds after a frame, beyond the opened field;
- error against the simulator's ground truth (relative RMSE, PSNR, SSIM) at a captured view
  and at a view halfway between two captured cameras, for every environment.

Studies: the ablation chain on an S = T = 30 field, a sweep of K, a sweep of field density, and
LDR against HDR panoramas; and the speed of the whole product on the simulated rig (capture
overhead, field building, the interactive loop). Fields are simulated into ``--fields`` once and
reused, and so are the ground truths (``DIR/truth``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields, is_dataclass, replace
from pathlib import Path
from typing import Any, cast

import cv2
import numba
import numpy as np
from numpy.typing import NDArray

from bench.advisor import validate_advisor
from bench.capture import bench_capture
from bench.relight import (
    Truth,
    between_view,
    copy_bandwidth,
    field_path,
    image_errors,
    loop_ms,
    truths_of_views,
)
from bench.report import write_report
from bench.stability import run_stability
from core.camera_model import PinholeCamera
from core.colour import linear_to_srgb
from core.errors import InputError
from core.field_store import ReflectanceField
from core.sample_data import PanoramaName, panorama_path
from processing.interpolation import InterpolationMethod
from processing.panorama import Panorama, panorama_from_array, read_panorama
from processing.sample_model_store import (
    default_models_path,
    models_for_field,
    read_sample_models,
)
from processing.sample_models import SampleModels
from processing.sampling import SamplerName
from render.model_relight import ModelRelightSettings
from render.relight_mode import (
    MOST_ACCURATE_MODELS,
    RelightEngine,
    RelightMode,
    most_accurate_mode,
    open_relighter,
)
from render.relighter import Relighter, RelightSettings, RelitImage
from sim.scenes import SurfaceSamples, build_scene, get_scene
from sim.skies import ldr_photo, procedural_sky
from sim.synthetic_camera import camera_visibility, image_of_points

__all__ = [
    "FULL",
    "QUICK",
    "FieldSpec",
    "Method",
    "SuiteConfig",
    "ablation_methods",
    "environments",
    "k_method",
    "main",
    "run_suite",
    "ssim",
]

#: (S cameras, T lights, surface points, image side in pixels) of a simulated field.
FieldSpec = tuple[int, int, int, int]

SCENES = ("diffuse-sphere", "glossy-sphere", "textured-torus")
#: The sampling of the paper and of our sampled schemes at the chain's steps.
CHAIN_K = 64
#: A frame budget for "interactive": 30 frames per second.
FRAME_BUDGET_MS = 1000.0 / 30.0


@dataclass(frozen=True)
class Method:
    """One relighting configuration of a study.

    Attributes
    ----------
    label : str, the name in tables and charts
    mode : RelightSettings or ModelRelightSettings
    role : "chain" (a step of the ablation chain, applied on top of the previous step) or
        "branch" (an alternative to the step before it, not carried on)
    """

    label: str
    mode: RelightMode
    role: str = "chain"


def ablation_methods(quick: bool = False) -> list[Method]:
    """The chain from the paper's configuration, one change per step, and its branches."""
    solid = RelightSettings(scheme="sampled", k=CHAIN_K)
    bary = replace(solid, interpolation="barycentric", view_interpolation="barycentric")
    samplers: tuple[SamplerName, ...] = (
        ("median-cut",) if quick else ("ostromoukhov", "cdf", "median-cut")
    )
    interpolations: tuple[InterpolationMethod, ...] = () if quick else ("nearest", "rbf")
    return [
        Method("paper", RelightSettings.paper_configuration(CHAIN_K)),
        Method("+ solid-angle weighting", solid),
        *(Method(f"  sampler {name}", replace(solid, sampler=name), "branch") for name in samplers),
        Method("+ barycentric lights & views", bary),
        *(
            Method(
                f"  interpolation {name}",
                replace(solid, interpolation=name, view_interpolation=name),
                "branch",
            )
            for name in interpolations
        ),
        Method("+ rearranged eq. 2 (pixels)", replace(bary, scheme="pixels")),
        Method("+ projection", replace(bary, scheme="projection")),
        Method(
            f"+ per-sample models, K={CHAIN_K}",
            ModelRelightSettings(lighting="sampled", k=CHAIN_K),
        ),
        Method("+ per-sample models, grid 64", MOST_ACCURATE_MODELS),
    ]


#: The K sweep's families: the paper, our sampled scheme (chain step 4), models on K lights.
K_FAMILIES = ("paper", "sampled, barycentric", "models, sampled")


def k_method(family: str, k: int) -> Method:
    """The method of a K-sweep family at ``k`` lights."""
    if family == "paper":
        mode: RelightMode = RelightSettings.paper_configuration(k)
    elif family == "sampled, barycentric":
        mode = RelightSettings(
            scheme="sampled", k=k, interpolation="barycentric", view_interpolation="barycentric"
        )
    elif family == "models, sampled":
        mode = ModelRelightSettings(lighting="sampled", k=k)
    else:
        raise InputError(f"unknown K family {family!r}")
    return Method(f"{family} K={k}", mode)


@dataclass(frozen=True)
class SuiteConfig:
    """What one run measures.

    Attributes
    ----------
    name : str, "full", "quick" or a test's own
    scenes : simulator scenes
    environments : environment names (see :func:`environments`)
    chain_field : the field of the ablation chain and the K sweep
    density_fields : the other fields of the density sweep (the chain field is one more point)
    density_methods : labels of chain methods run on every density field
    quick_methods : the shorter chain (fewer branches)
    k_values, k_families : the K sweep
    repeats : timed frames per figure (after a warm-up frame)
    capture : (cameras, lights, image side) of the capture-overhead sweep, or None to skip
    loop : bool, whether to measure the product's interactive loop
    loop_field : (field, dtype) of the interactive loop (glossy sphere), or None for the chain
        field: a large field, so the loop's per-sample work is measured against the memory
        bandwidth it must stream
    sky_height : rows of the procedural sky
    advisor_fields, advisor_scenes, advisor_environments : where ``rig advise`` is validated
        (fields among the chain and density fields; HDR environments among ``environments``)
    advisor_samples : samples the advisor predicts on
    """

    name: str
    scenes: tuple[str, ...]
    environments: tuple[str, ...]
    chain_field: FieldSpec
    density_fields: tuple[FieldSpec, ...]
    density_methods: tuple[str, ...]
    quick_methods: bool
    k_values: tuple[int, ...]
    k_families: tuple[str, ...]
    repeats: int
    capture: tuple[int, int, int] | None
    loop: bool = True
    loop_field: tuple[FieldSpec, str] | None = None
    sky_height: int = 256
    advisor_fields: tuple[FieldSpec, ...] = ()
    advisor_scenes: tuple[str, ...] = SCENES
    advisor_environments: tuple[str, ...] = ("courtyard", "sky")
    advisor_samples: int = 2000


_DENSITY_METHODS = (
    "paper",
    "+ barycentric lights & views",
    "+ rearranged eq. 2 (pixels)",
    "+ projection",
    "+ per-sample models, grid 64",
)

FULL = SuiteConfig(
    name="full",
    scenes=SCENES,
    environments=(
        "courtyard",
        "courtyard LDR",
        "studio",
        "studio LDR",
        "sky",
        "sky LDR",
    ),
    chain_field=(30, 30, 20_000, 128),
    # The dense light set keeps S = 30 and few points: 400 lights x 30 cameras of 20 000
    # points would be 2.9 GB and minutes of simulation for one more point on a chart.
    density_fields=((10, 10, 20_000, 128), (20, 20, 20_000, 128), (30, 400, 4_000, 96)),
    density_methods=_DENSITY_METHODS,
    quick_methods=False,
    k_values=(4, 16, 64, 256, 1024),
    k_families=K_FAMILIES,
    repeats=3,
    capture=(4, 6, 64),
    loop_field=((30, 30, 250_000, 512), "float16"),
    advisor_fields=((10, 10, 20_000, 128), (20, 20, 20_000, 128), (30, 30, 20_000, 128)),
)

QUICK = SuiteConfig(
    name="quick",
    scenes=("glossy-sphere", "textured-torus"),
    environments=("courtyard", "courtyard LDR", "sky"),
    chain_field=(20, 20, 4_000, 64),
    density_fields=((10, 10, 4_000, 64),),
    density_methods=("paper", "+ barycentric lights & views", "+ per-sample models, grid 64"),
    quick_methods=True,
    k_values=(4, 64, 256),
    k_families=("paper", "models, sampled"),
    repeats=2,
    # Fewer images would measure the session's start-up, not the per-image overhead.
    capture=(4, 6, 64),
    advisor_fields=((20, 20, 4_000, 64),),
    advisor_scenes=("glossy-sphere",),
    advisor_environments=("courtyard",),
    advisor_samples=1000,
)


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
    """The named environments: "courtyard", "studio" (the bundled panoramas), "sky" (procedural,
    with a small, very bright sun), each optionally with " LDR" (its 8-bit sRGB photo)."""
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


def ssim(image: RelitImage, truth: Truth) -> float:
    """Mean SSIM over the pixels both images cover, on tone-mapped 8-bit sRGB.

    Both images are scaled so the truth's 99th percentile over the covered pixels is white,
    clipped, sRGB-encoded to [0, 255] (the range OpenCV's SSIM constants assume), and zero
    outside the covered region; the SSIM map (11 x 11 Gaussian windows) is averaged over the
    covered pixels and the three channels.
    """
    mask = image.coverage & truth.image.coverage
    if not mask.any():
        return float("nan")
    white = float(np.percentile(truth.image.rgb[mask], 99.0))
    white = white if white > 0 else 1.0

    def tone(rgb: NDArray[np.float32]) -> NDArray[np.float64]:
        encoded = linear_to_srgb(np.clip(rgb / white, 0.0, 1.0)) * 255.0
        return np.where(mask[:, :, None], encoded, 0.0).astype(np.float64)

    # OpenCV's contrib module has no type stubs.
    quality: Any = getattr(cv2, "quality")  # noqa: B009
    _, ssim_map = quality.QualitySSIM_compute(tone(truth.image.rgb), tone(image.rgb))
    return float(np.mean(np.asarray(ssim_map)[mask]))


def engine_bytes(engine: object) -> int:
    """Bytes of the numpy arrays an engine holds, not counting the opened field's.

    Walks the engine's attributes (objects, dataclasses, dicts, sequences); an array and its
    views count once.
    """
    seen: set[int] = set()
    bases: set[int] = set()
    total = 0
    stack: list[object] = [value for key, value in vars(engine).items() if key != "field"]
    while stack:
        item = stack.pop()
        if id(item) in seen or item is None or isinstance(item, str | int | float | bool):
            continue
        seen.add(id(item))
        if isinstance(item, ReflectanceField):
            continue
        if isinstance(item, np.ndarray):
            base = item
            while isinstance(base.base, np.ndarray):
                base = base.base
            if id(base) not in bases:
                bases.add(id(base))
                total += base.nbytes
        elif isinstance(item, dict):
            stack += list(item.values())
        elif isinstance(item, list | tuple | set | frozenset):
            stack += list(item)
        elif is_dataclass(item):
            stack += [getattr(item, f.name) for f in fields(item)]
        elif hasattr(item, "__dict__"):
            stack += list(vars(item).values())
    return total


def _mode_dict(mode: RelightMode) -> dict[str, Any]:
    return {"engine": "models" if mode.uses_models else "relighter", **vars(mode)}


def _views(field: ReflectanceField) -> dict[str, PinholeCamera]:
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


@dataclass
class _FieldRun:
    """One opened field of one scene, with what every method on it shares."""

    scene: str
    spec: FieldSpec
    field: ReflectanceField
    models: SampleModels
    models_record: dict[str, Any]
    views: dict[str, PinholeCamera]
    truths: dict[tuple[str, str], Truth]


def _open_field(
    fields_dir: Path, cache: Path, scene: str, spec: FieldSpec, envs: dict[str, Environment]
) -> _FieldRun:
    cameras, lights, points, size = spec
    start = time.perf_counter()
    path = field_path(fields_dir.parent, scene, cameras, lights, points, size, "float32")
    simulated_s = time.perf_counter() - start
    field = ReflectanceField.open(path)
    # The fit is timed when this run makes it and remembered beside it, since later runs
    # only load it.
    models_path = default_models_path(path)
    fit_record = models_path.with_name(models_path.name + ".fit.json")
    record: dict[str, Any] = {}
    if not models_path.exists():
        start = time.perf_counter()
        models_for_field(field)
        fit_record.write_text(json.dumps({"fit_s": time.perf_counter() - start}) + "\n")
    if fit_record.exists():
        record["fit_s"] = json.loads(fit_record.read_text())["fit_s"]
    start = time.perf_counter()
    models = read_sample_models(models_path, field)
    record["load_s"] = time.perf_counter() - start
    views = _views(field)
    samples = build_scene(scene, points)
    start = time.perf_counter()
    truths = _truths(cache, scene, samples, spec, views, envs)
    truth_s = time.perf_counter() - start
    print(
        f"field {scene} S={cameras} T={lights} {points} points {size}px: simulated/opened "
        f"{simulated_s:.1f} s, models {record}, truths {truth_s:.1f} s",
        flush=True,
    )
    return _FieldRun(scene, spec, field, models, record, views, truths)


def measure_method(
    run: _FieldRun,
    method: Method,
    envs: dict[str, Environment],
    repeats: int,
) -> dict[str, Any]:
    """Precompute, loop times, memory and errors of one method on one field."""
    start = time.perf_counter()
    engine = open_relighter(run.field, method.mode, run.models)
    precompute = time.perf_counter() - start
    models = method.mode.uses_models
    if models:
        precompute += run.models_record["load_s"]
    timing_panorama = envs[next(iter(envs))].panorama
    loop = loop_ms(engine, timing_panorama, repeats, run.views["captured"])
    scores = []
    for env in envs.values():
        engine.set_lighting(env.panorama)
        for view, camera in run.views.items():
            engine.set_view(camera)
            image = engine.render()
            truth = run.truths[(env.truth, view)]
            scores.append(
                {"environment": env.name, "hdr": env.truth, "ldr": env.ldr, "view": view}
                | image_errors(image, truth)
                | {"ssim": ssim(image, truth), "outside_fraction": image.outside_fraction}
            )
    return _spec_record(run) | {
        "label": method.label.strip(),
        "role": method.role,
        "mode": _mode_dict(method.mode),
        "k": method.mode.sampled_k,
        "precompute_s": precompute,
        "models_fit_s": run.models_record.get("fit_s") if models else None,
        "models_load_s": run.models_record["load_s"] if models else None,
        "new_lighting_ms": loop["loop_new_lighting_ms"],
        "new_view_ms": loop["loop_new_view_ms"],
        "memory_MB": engine_bytes(engine) / 1e6,
        "scores": scores,
    }


def _print_row(study: str, row: dict[str, Any]) -> None:
    between = [s["relative_rmse"] for s in row["scores"] if s["view"] == "between" and not s["ldr"]]
    print(
        f"{study:9s} {row['scene']:15s} S={row['S']:<3d} T={row['T']:<3d} "
        f"{row['label']:34s} new lighting {row['new_lighting_ms']:8.1f} ms  new view "
        f"{row['new_view_ms']:8.1f} ms  {row['memory_MB']:7.1f} MB  "
        f"rel. RMSE (HDR, between) {np.mean(between):7.2%}",
        flush=True,
    )


def _measure(
    run: _FieldRun,
    study: str,
    method: Method,
    envs: dict[str, Environment],
    repeats: int,
    done: dict[tuple[str, FieldSpec, RelightMode], dict[str, Any]],
) -> dict[str, Any]:
    """:func:`measure_method`, or a relabelled copy when the same mode was measured already."""
    key = (run.scene, run.spec, method.mode)
    if key in done:
        row = done[key] | {"label": method.label.strip(), "role": method.role}
    else:
        row = measure_method(run, method, envs, repeats)
        done[key] = row
    row = row | {"study": study}
    _print_row(study, row)
    return row


def machine() -> dict[str, Any]:
    """The machine and software the figures come from."""
    return {
        "cpu_count": os.cpu_count(),
        "load_average": list(os.getloadavg()),
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        "opencv": cv2.__version__,
    }


def bench_product(
    config: SuiteConfig, chain: _FieldRun | None, repeats: int, fields_dir: Path
) -> dict[str, Any]:
    """The whole product's speed in one run: capture, field building, interactive loop."""
    out: dict[str, Any] = {}
    if config.capture is not None:
        cameras, lights, size = config.capture
        capture = bench_capture(cameras, lights, speed=1.0, size=size)
        capture["capture_wall_s"] = capture["wall_s"]["total"]
        # Field building against capture: seconds of processing per second of capture.
        capture["process_over_capture"] = capture["process_s"] / capture["wall_s"]["total"]
        out["capture"] = capture
        print(
            f"capture   {capture['images']} images: controller "
            f"{capture['controller_share_of_motion_and_exposure']:.2%} of motion + exposure; "
            f"field building {capture['process_images_per_s']:.1f} images/s",
            flush=True,
        )
    if config.loop and chain is not None:
        bandwidth = copy_bandwidth()
        if config.loop_field is not None:
            (cameras, lights, points, size), dtype = config.loop_field
            path = field_path(fields_dir.parent, "glossy-sphere", cameras, lights, points, size,
                              dtype)  # fmt: skip
            field = ReflectanceField.open(path)
            models = models_for_field(field, progress=True)
            spec = (cameras, lights, points, size)
            chain = _FieldRun("glossy-sphere", spec, field, models, {}, _views(field), {})
        camera = chain.views["captured"]
        modes: dict[str, RelightMode] = {
            "paper": RelightSettings.paper_configuration(CHAIN_K),
            "default (chosen by leave-one-light-out)": most_accurate_mode(
                chain.field, chain.models
            ).mode,
            "sampled, barycentric": k_method("sampled, barycentric", CHAIN_K).mode,
            "models, sampled K=64": k_method("models, sampled", CHAIN_K).mode,
        }
        loops = []
        courtyard = read_panorama(panorama_path("courtyard"))
        for name, mode in modes.items():
            engine: RelightEngine = open_relighter(chain.field, mode, chain.models)
            loop = loop_ms(engine, courtyard, repeats, camera)
            # Two frames at the last view: the second builds the view's blended field.
            engine.render()
            engine.render()
            compute = []
            for yaw in np.linspace(0.0, 90.0, repeats):
                engine.set_lighting(courtyard, yaw_deg=yaw)
                compute.append(1e3 * engine.render().seconds["relight"])
            row: dict[str, Any] = {"mode": name, "settings": _mode_dict(mode)} | loop
            row["relight_compute_ms"] = float(np.median(compute))
            row["frame_budget_ratio"] = loop["loop_new_lighting_ms"] / FRAME_BUDGET_MS
            if isinstance(engine, Relighter) and engine._view_field is not None:
                # The memory-bandwidth floor: one read of the view's blended field.
                floor = 1e3 * engine._view_field.radiance.nbytes / bandwidth
                row["bandwidth_floor_ms"] = floor
                row["bandwidth_floor_ratio"] = row["relight_compute_ms"] / floor
            loops.append(row)
            print(
                f"loop      {name:40s} new lighting {loop['loop_new_lighting_ms']:.1f} ms "
                f"({row['frame_budget_ratio']:.2f} of a 30 fps frame)",
                flush=True,
            )
        out["loop"] = {
            "scene": chain.scene,
            "S": chain.spec[0],
            "T": chain.spec[1],
            "points": chain.spec[2],
            "image": chain.spec[3],
            "frame_budget_ms": FRAME_BUDGET_MS,
            "copy_bandwidth_GBps": bandwidth / 1e9,
            "modes": loops,
        }
    return out


def run_suite(config: SuiteConfig, out: Path, fields_dir: Path | None = None) -> dict[str, Any]:
    """Run every study of ``config``; returns the results (as written to results.json).

    Parameters
    ----------
    config : SuiteConfig
    out : Path, the output directory (ground truths are cached in ``out/truth``)
    fields_dir : Path, optional, where fields are simulated once and reused (default
        ``out/fields``; a directory named ``fields`` is required by the naming of
        :func:`bench.relight.field_path`)
    """
    started = time.perf_counter()
    fields_dir = fields_dir if fields_dir is not None else out / "fields"
    if fields_dir.name != "fields":
        raise InputError(f"the field cache must be a directory named 'fields', got {fields_dir}")
    envs = environments(config.environments, config.sky_height)
    results: dict[str, Any] = {
        "config": asdict(config),
        "machine": machine(),
        "chain_field": list(config.chain_field),
        "environments": {
            name: {"truth": env.truth, "ldr": env.ldr, "source": env.panorama.source}
            for name, env in envs.items()
        },
        "chain": [m.label.strip() for m in ablation_methods(config.quick_methods)],
        "k_families": list(config.k_families),
        "density_methods": list(config.density_methods),
        "ssim": "mean SSIM map (OpenCV quality, 11x11 Gaussian) over covered pixels of the "
        "tone-mapped images: scaled so the truth's 99th percentile is white, clipped, 8-bit sRGB",
        "memory": "bytes of the numpy arrays the engine holds after a frame, beyond the opened "
        "field (the per-sample models' fits included)",
        "fields": [],
        "rows": [],
        "advisor": [],
    }
    rss_start = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    chain_methods = ablation_methods(config.quick_methods)
    by_label = {m.label.strip(): m for m in chain_methods}
    chain_run: _FieldRun | None = None
    for scene in config.scenes:
        done: dict[tuple[str, FieldSpec, RelightMode], dict[str, Any]] = {}
        run = _open_field(fields_dir, out, scene, config.chain_field, envs)
        if scene == "glossy-sphere" or chain_run is None:
            chain_run = run
        results["fields"].append(_field_record(run))
        for method in chain_methods:
            results["rows"].append(_measure(run, "ablation", method, envs, config.repeats, done))
        for family in config.k_families:
            for k in config.k_values:
                row = _measure(run, "k", k_method(family, k), envs, config.repeats, done)
                results["rows"].append(row | {"family": family})
        opened = {config.chain_field: run}
        for spec in config.density_fields:
            dense = opened[spec] = _open_field(fields_dir, out, scene, spec, envs)
            results["fields"].append(_field_record(dense))
            for label in config.density_methods:
                results["rows"].append(
                    _measure(dense, "density", by_label[label], envs, config.repeats, done)
                )
        if scene in config.advisor_scenes:
            for spec in config.advisor_fields:
                chosen = opened[spec]
                results["advisor"] += validate_advisor(
                    scene, chosen.field, chosen.models, chosen.views, chosen.truths,
                    {name: envs[name].panorama for name in config.advisor_environments},
                    samples=config.advisor_samples,
                )  # fmt: skip
    results["product"] = bench_product(config, chain_run, config.repeats, fields_dir)
    results["stability"] = run_stability(out / "stability", config.quick_methods)
    results["machine"]["load_average_end"] = list(os.getloadavg())
    results["machine"]["peak_rss_MB"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    results["machine"]["rss_growth_MB"] = (
        resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss_start
    ) / 1024
    results["wall_s"] = time.perf_counter() - started
    return results


def _spec_record(run: _FieldRun) -> dict[str, Any]:
    cameras, lights, points, size = run.spec
    return {"scene": run.scene, "S": cameras, "T": lights, "points": points, "image": size}


def _field_record(run: _FieldRun) -> dict[str, Any]:
    return _spec_record(run) | {
        "models_fit_s": run.models_record.get("fit_s"),
        "models_load_s": run.models_record["load_s"],
        "field_MB": run.field.camera_slab(0).nbytes * run.spec[0] / 1e6,
    }


def main(argv: list[str] | None = None) -> int:
    """``python -m bench.suite [--quick] -o DIR [--fields DIR]``; returns the exit status."""
    parser = argparse.ArgumentParser(
        prog="bench.suite", description="Speed against accuracy of relighting, and the product"
    )
    add_arguments(parser)
    return run(parser.parse_args(argv))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The suite's options (shared by ``python -m bench.suite`` and ``rig bench``)."""
    parser.add_argument("-o", "--output", type=Path, required=True, help="output directory")
    parser.add_argument(
        "--quick", action="store_true", help="a few minutes: one small field, fewer methods"
    )
    parser.add_argument(
        "--fields",
        type=Path,
        default=None,
        help="directory named 'fields' where simulated fields are cached (default DIR/fields)",
    )


def run(args: argparse.Namespace) -> int:
    """Run the suite for parsed arguments, write the results and the report."""
    out: Path = args.output
    out.mkdir(parents=True, exist_ok=True)
    config = QUICK if args.quick else FULL
    results = run_suite(config, out, args.fields)
    (out / "results.json").write_text(json.dumps(results, indent=2) + "\n")
    report = write_report(results, out)
    print(f"wrote {out / 'results.json'} and {report} in {results['wall_s']:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

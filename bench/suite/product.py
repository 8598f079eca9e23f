"""The speed of the whole product in one run: capture, field building and the interactive loop.

The capture sweep runs on the simulated rig through the real drivers
(:func:`bench.capture.bench_capture`); the loop times a new lighting and a new view of the
paper's configuration, the mode ``rig relight`` chooses by default, its interactive variant
(the models' grid sum split into precomputed terms, :mod:`render.precomputed_lighting`) and two
of our own, each against a 30 fps frame and, for the interpolating engines, against the memory
bandwidth floor of reading the view's blended field once; and each mode's error against its
own exact reference (the same predictors with the panorama summed exactly,
``mode.exact_lighting``), the price of its lighting approximation.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import cast

import numpy as np

from bench.capture import bench_capture
from bench.sim_truth import field_path
from bench.suite.fields import FieldRun, spec_record, views_of
from bench.suite.methods import CHAIN_K, FieldSpec, SuiteConfig, k_method, mode_record
from bench.suite.results import (
    CaptureRecord,
    InteractiveRecord,
    LoopModeRecord,
    LoopRecord,
    ProductRecord,
)
from bench.timing import copy_bandwidth, loop_ms
from core.camera_model import PinholeCamera
from core.field_store import ReflectanceField
from core.sample_data import panorama_path
from processing.panorama import Panorama, read_panorama
from processing.sample_model_store import models_for_field
from processing.sample_models import SampleModels
from render.engines.interpolated import Relighter, RelightSettings
from render.engines.models import ModelRelightSettings
from render.engines.modes import RelightEngine, RelightMode, most_accurate_mode, open_relighter

__all__ = [
    "FRAME_BUDGET_MS",
    "bench_loop",
    "bench_product",
    "capture_record",
    "interactive_record",
    "interactive_variant",
]

#: A frame budget for "interactive": 30 frames per second.
FRAME_BUDGET_MS = 1000.0 / 30.0
#: Rows of the exact reference's panorama grid (the default model mode's own).
REFERENCE_GRID = 64
#: The yaw of the frame compared with the reference, degrees.
REFERENCE_YAW = 30.0
#: The scene of the large loop field.
_LOOP_SCENE = "glossy-sphere"


def capture_record(cameras: int, lights: int, size: int) -> CaptureRecord:
    """A capture sweep on the simulated rig at full speed, and its field building; printed.

    Parameters
    ----------
    cameras, lights : int, the sweep; size : int, image side in pixels

    Returns
    -------
    CaptureRecord: :func:`bench.capture.bench_capture`'s figures, the capture's wall time
    and the seconds of field building per second of capture
    """
    capture = bench_capture(cameras, lights, speed=1.0, size=size)
    # bench.capture returns its record as a plain dict; CaptureRecord is its layout.
    record = cast(
        CaptureRecord,
        {
            **capture,
            "capture_wall_s": capture["wall_s"]["total"],
            "process_over_capture": capture["process_s"] / capture["wall_s"]["total"],
        },
    )
    print(
        f"capture   {record['images']} images: controller "
        f"{record['controller_share_of_motion_and_exposure']:.2%} of motion + exposure; "
        f"field building {record['process_images_per_s']:.1f} images/s",
        flush=True,
    )
    return record


def _loop_mode(
    name: str,
    mode: RelightMode,
    field: ReflectanceField,
    models: SampleModels,
    courtyard: Panorama,
    camera: PinholeCamera,
    repeats: int,
    bandwidth: float,
) -> LoopModeRecord:
    """The loop of one mode at ``camera``, under rotations of ``courtyard``."""
    engine: RelightEngine = open_relighter(field, mode, models)
    loop = loop_ms(engine, courtyard, repeats, camera)
    # Two frames at the last view: the second builds the view's blended field.
    engine.render()
    engine.render()
    compute = []
    for yaw in np.linspace(0.0, 90.0, repeats):
        engine.set_lighting(courtyard, yaw_deg=yaw)
        compute.append(1e3 * engine.render().seconds["relight"])
    row: LoopModeRecord = {
        "mode": name,
        "settings": mode_record(mode),
        "loop_new_lighting_ms": loop["loop_new_lighting_ms"],
        "loop_new_view_ms": loop["loop_new_view_ms"],
        "relight_compute_ms": float(np.median(compute)),
        "frame_budget_ratio": loop["loop_new_lighting_ms"] / FRAME_BUDGET_MS,
        "error_vs_reference": _error_vs_reference(engine, mode, field, models, courtyard, camera),
    }
    if isinstance(engine, Relighter) and engine._view_field is not None:
        # The memory-bandwidth floor: one read of the view's blended field.
        floor = 1e3 * engine._view_field.radiance.nbytes / bandwidth
        row["bandwidth_floor_ms"] = floor
        row["bandwidth_floor_ratio"] = row["relight_compute_ms"] / floor
    print(
        f"loop      {name:40s} new lighting {loop['loop_new_lighting_ms']:.1f} ms "
        f"({row['frame_budget_ratio']:.2f} of a 30 fps frame)",
        flush=True,
    )
    return row


def _error_vs_reference(
    engine: RelightEngine,
    mode: RelightMode,
    field: ReflectanceField,
    models: SampleModels,
    courtyard: Panorama,
    camera: PinholeCamera,
) -> float:
    """Relative RMSE of the mode's frame against its exact reference's, over covered pixels."""
    reference_mode = mode.exact_lighting(REFERENCE_GRID)
    if reference_mode == mode:
        return 0.0
    reference = open_relighter(field, reference_mode, models)
    frames = []
    for relighter in (engine, reference):
        relighter.set_lighting(courtyard, yaw_deg=REFERENCE_YAW)
        relighter.set_view(camera)
        frames.append(relighter.render())
    image, truth = frames
    covered = image.coverage & truth.coverage
    energy = float(np.mean(truth.rgb[covered] ** 2))
    difference = float(np.mean((image.rgb[covered] - truth.rgb[covered]) ** 2))
    return float(np.sqrt(difference / energy)) if energy > 0 else float("nan")


def interactive_variant(mode: RelightMode) -> ModelRelightSettings:
    """The models' interactive mode: ``mode``'s model with precomputed lighting.

    The default mode's own model when it relights through models, else the field's chosen one.
    """
    if isinstance(mode, ModelRelightSettings):
        return replace(mode, lighting="precomputed")
    return ModelRelightSettings(model="auto", lighting="precomputed")


def interactive_record(loop: LoopRecord) -> dict[str, InteractiveRecord]:
    """The loop's modes keyed by name: the figures the interactive goals are read from."""
    return {
        m["mode"]: {
            "new_lighting_ms": m["loop_new_lighting_ms"],
            "new_view_ms": m["loop_new_view_ms"],
            "error_vs_reference": m["error_vs_reference"],
            "points": loop["points"],
            "settings": m["settings"],
        }
        for m in loop["modes"]
    }


def bench_loop(
    scene: str,
    spec: FieldSpec,
    field: ReflectanceField,
    models: SampleModels,
    repeats: int,
    bandwidth: float,
) -> LoopRecord:
    """The interactive loop of the product's modes on one field; printed.

    Parameters
    ----------
    scene : str; spec : FieldSpec; field : ReflectanceField, of them
    models : the field's per-sample model fit
    repeats : int, timed frames per time
    bandwidth : float, bytes per second of a large copy (:func:`bench.timing.copy_bandwidth`)

    Returns
    -------
    LoopRecord
    """
    default = most_accurate_mode(field, models).mode
    modes: dict[str, RelightMode] = {
        "paper": RelightSettings.paper_configuration(CHAIN_K),
        "default": default,
        "models, precomputed": interactive_variant(default),
        "sampled, barycentric": k_method("sampled, barycentric", CHAIN_K).mode,
        "models, sampled K=64": k_method("models, sampled", CHAIN_K).mode,
    }
    camera = views_of(field)["captured"]
    courtyard = read_panorama(panorama_path("courtyard"))
    return {
        **spec_record(scene, spec),
        "frame_budget_ms": FRAME_BUDGET_MS,
        "copy_bandwidth_GBps": bandwidth / 1e9,
        "modes": [
            _loop_mode(name, mode, field, models, courtyard, camera, repeats, bandwidth)
            for name, mode in modes.items()
        ],
    }


def bench_product(config: SuiteConfig, chain: FieldRun | None, fields_dir: Path) -> ProductRecord:
    """The whole product's speed in one run: capture, field building, interactive loop.

    Parameters
    ----------
    config : SuiteConfig, its ``capture``, ``loop``, ``loop_field`` and ``repeats``
    chain : FieldRun, the ablation chain's field (the loop's, unless ``config.loop_field``);
        None skips the loop
    fields_dir : Path, the field cache (a directory named ``fields``)

    Returns
    -------
    ProductRecord, with the parts the configuration asks for
    """
    out: ProductRecord = {}
    if config.capture is not None:
        out["capture"] = capture_record(*config.capture)
    if config.loop and chain is not None:
        bandwidth = copy_bandwidth()
        if config.loop_field is None:
            scene, spec, field, models = chain.scene, chain.spec, chain.field, chain.models
        else:
            spec, dtype = config.loop_field
            scene = _LOOP_SCENE
            field = ReflectanceField.open(field_path(fields_dir.parent, scene, *spec, dtype))
            models = models_for_field(field)
        out["loop"] = bench_loop(scene, spec, field, models, config.repeats, bandwidth)
    return out

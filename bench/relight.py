"""Benchmark of relighting: speed of the interactive loop and accuracy against the simulator.

Run: ``python -m bench.relight -o bench-out [--quick]``. Prints tables and writes
``bench-out/relight.json`` and ``bench-out/relight.png`` (error against time per frame).
Fields are simulated into ``bench-out/fields/`` once and reused (:mod:`bench.sim_truth`, with
the ground truths and the errors against them). Timings are medians after numba compilation
on this machine's cores (:mod:`bench.timing`); compare them as ratios within one run.
"""

from __future__ import annotations

import argparse
import json
import resource
import time
from functools import partial
from itertools import product
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from numpy.typing import NDArray

from bench.sim_truth import Truth, between_view, field_path, image_errors, truth_of
from bench.timing import copy_bandwidth, loop_ms, median_ms
from core.camera_model import PinholeCamera
from core.field_store import ReflectanceField
from core.sample_data import PANORAMA_NAMES, PanoramaName, panorama_path
from processing.panorama import Panorama, panorama_from_array, read_panorama
from processing.sample_model_store import models_for_field
from processing.sample_models import SampleModels, choose_model, interpolation_loo
from render.engines.interpolated import Relighter, RelightSettings
from render.engines.models import ModelRelighter, ModelRelightSettings
from render.engines.modes import MOST_ACCURATE_MODELS, RelightEngine, RelightMode, open_relighter
from render.engines.paper_sums import (
    blend_cameras,
    blend_field,
    relight,
    relight_pixels_literal,
    relight_view,
)
from render.light_weights import pixel_light_weights
from render.splat import splat
from sim.scenes import build_scene, get_scene


def _read_slab(field: ReflectanceField, camera: int) -> NDArray[np.float32]:
    return np.asarray(field.radiance[camera], dtype=np.float32)


def bench_speed(out: Path, points: int, repeats: int, panorama: Panorama) -> dict[str, Any]:
    """The interactive loop on a 512 x 512 view of an S = T = 30 field."""
    result: dict[str, Any] = {"points": points, "S": 30, "T": 30, "image": "512x512"}
    storage = {}
    for dtype in ("float16", "float32"):
        start = time.perf_counter()
        path = field_path(out, "glossy-sphere", 30, 30, points, 512, dtype)
        build = time.perf_counter() - start
        size = sum(f.stat().st_size for f in path.rglob("*") if f.is_file())
        field = ReflectanceField.open(path, cached_slabs=1)
        load = median_ms(partial(_read_slab, field, 3), 3)
        storage[dtype] = {"bytes": size, "slab_load_ms": load, "build_s_if_new": build}
    result["storage"] = storage
    field = ReflectanceField.open(
        field_path(out, "glossy-sphere", 30, 30, points, 512, "float16"), 30
    )
    bandwidth = copy_bandwidth()
    result["copy_bandwidth_GBps"] = bandwidth / 1e9
    camera = PinholeCamera(20.0, 50.0)
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    schemes = [
        _bench_scheme(field, settings, panorama, camera, bandwidth, repeats)
        for settings in (
            RelightSettings.paper_configuration(k=64),
            RelightSettings(scheme="sampled", k=64, interpolation="barycentric"),
            RelightSettings(scheme="projection"),
            RelightSettings(scheme="pixels", interpolation="barycentric"),
        )
    ]
    result["schemes"] = schemes
    start = time.perf_counter()
    models = models_for_field(field)
    result["model_fit_or_load_s"] = time.perf_counter() - start
    result["model_schemes"] = [
        _bench_model_scheme(field, models, settings, panorama, camera, repeats)
        for settings in (
            ModelRelightSettings(lighting="sampled", k=64),
            ModelRelightSettings(lighting="sampled", k=256),
            ModelRelightSettings(lighting="grid", grid_height=32),
            MOST_ACCURATE_MODELS,
        )
    ]
    result["peak_rss_MB"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    result["rss_growth_MB"] = (
        resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss_before
    ) / 1024
    result["slab_MB"] = field.camera_slab(0).nbytes / 1e6
    result["equation_2_vs_3"] = _bench_equations(out, panorama)
    return result


def _bench_scheme(
    field: ReflectanceField,
    settings: RelightSettings,
    panorama: Panorama,
    camera: PinholeCamera,
    bandwidth: float,
    repeats: int,
) -> dict[str, Any]:
    relighter = Relighter(field, settings)
    lighting_ms = median_ms(lambda: relighter.set_lighting(panorama, yaw_deg=7.0), repeats)
    relighter.set_view(camera)
    relighter.render()
    relighter.render()  # the second frame at this view builds the view's blended field
    view_field, lighting, view = relighter._view_field, relighter._lighting, relighter._view
    assert view_field is not None and lighting is not None and view is not None
    blend, plan = view[0], view[1].plan
    assert plan is not None
    relight_ms = median_ms(lambda: relight_view(view_field, lighting), repeats)
    radiance = relight_view(view_field, lighting)
    splat_ms = median_ms(lambda: splat(plan, radiance), repeats)
    floor_ms = 1e3 * view_field.radiance.nbytes / bandwidth
    return {
        "scheme": settings.scheme,
        "interpolation": settings.interpolation,
        "paper": settings.paper,
        "k": settings.k if settings.scheme == "sampled" else None,
        "lighting_ms": lighting_ms,
        "relight_new_lighting_ms": relight_ms,
        "bandwidth_floor_ms": floor_ms,
        "floor_ratio": relight_ms / floor_ms,
        "blend_field_ms": median_ms(lambda: blend_field(field, blend), 3),
        "view_setup_ms": median_ms(lambda: relighter.set_view(camera), 3),
        "splat_ms": splat_ms,
        **loop_ms(relighter, panorama, repeats),
        "needed_samples": len(view_field.samples),
        "cameras_blended": len(blend.cameras),
    }


def _bench_model_scheme(
    field: ReflectanceField,
    models: SampleModels,
    settings: ModelRelightSettings,
    panorama: Panorama,
    camera: PinholeCamera,
    repeats: int,
) -> dict[str, Any]:
    """The interactive loop through per-sample models (no blended field: the models are it)."""
    relighter = ModelRelighter(field, settings, models)
    lighting_ms = median_ms(lambda: relighter.set_lighting(panorama, yaw_deg=7.0), repeats)
    relighter.set_view(camera)
    relight_ms = median_ms(lambda: relighter.render().seconds["relight"], repeats)
    image = relighter.render()
    return {
        "scheme": "model",
        "model": relighter.choice.chosen,
        "lighting": settings.lighting,
        "lights": settings.k if settings.lighting == "sampled" else 2 * settings.grid_height**2,
        "lighting_ms": lighting_ms,
        "render_ms": relight_ms,
        "relight_ms": image.seconds["relight"] * 1e3,
        "splat_ms": image.seconds["splat"] * 1e3,
        "view_setup_ms": median_ms(lambda: relighter.set_view(camera), 3),
        **loop_ms(relighter, panorama, repeats),
    }


def _bench_equations(out: Path, panorama: Panorama) -> dict[str, Any]:
    """Literal eq. 2 against its rearranged form and eq. 3, at equal sizes, in one run."""
    field = ReflectanceField.open(field_path(out, "glossy-sphere", 30, 30, 50_000, 256, "float32"))
    camera = PinholeCamera(20.0, 50.0, width=128, height=128)
    blend = blend_cameras(field, camera, "barycentric")
    rgb = panorama.rgb
    literal_ms = median_ms(
        lambda: relight_pixels_literal(field, rgb, blend, "barycentric", grid_height=64), 1
    )

    def rearranged() -> None:
        weights = pixel_light_weights(
            rgb, field.light_directions, field.normals, "barycentric", grid_height=64
        )
        relight(field, weights, blend)

    rearranged_ms = median_ms(rearranged, 3)
    relighter = Relighter(field, RelightSettings(scheme="sampled", k=64))
    relighter.set_view(camera)
    sampled_ms = median_ms(lambda: (relighter.set_lighting(panorama), relighter.render()), 3)
    return {
        "points": 50_000,
        "panorama_directions": 64 * 128,
        "literal_eq2_ms": literal_ms,
        "rearranged_eq2_ms": rearranged_ms,
        "eq3_k64_ms": sampled_ms,
        "literal_over_rearranged": literal_ms / rearranged_ms,
        "literal_over_eq3": literal_ms / sampled_ms,
    }


ACCURACY_METHODS: dict[str, RelightMode] = {
    "paper (TMED on luminance, K=64, cosine 3x3, eq. 3)": RelightSettings.paper_configuration(64),
    "sampled K=256, barycentric": RelightSettings(
        scheme="sampled", k=256, interpolation="barycentric", view_interpolation="barycentric"
    ),
    "pixels (eq. 2), barycentric": RelightSettings(
        scheme="pixels", interpolation="barycentric", view_interpolation="barycentric"
    ),
    "projection": RelightSettings(scheme="projection", view_interpolation="barycentric"),
    "models (LOO choice), grid 64": MOST_ACCURATE_MODELS,
    "models (LOO choice), TMED K=256": ModelRelightSettings(lighting="sampled", k=256),
}

#: (S, T, points, image size): dense fields use fewer points (S = T = 400 at 3 000 points is
#: 160 000 slabs, 5.8 GB in float32).
ACCURACY_FIELDS = [
    (10, 10, 20_000, 128),
    (20, 20, 20_000, 128),
    (30, 30, 20_000, 128),
    (100, 100, 4_000, 96),
    (30, 400, 4_000, 96),
    (400, 400, 3_000, 96),
]


def _score(
    engine: RelightEngine, panorama: Panorama, camera: PinholeCamera, truth: Truth
) -> dict[str, Any]:
    engine.set_lighting(panorama)
    engine.set_view(camera)
    start = time.perf_counter()
    image = engine.render()
    seconds = time.perf_counter() - start
    return image_errors(image, truth) | {
        "render_ms": seconds * 1e3,
        "outside_fraction": image.outside_fraction,
    }


def environments(name: PanoramaName) -> dict[str, Panorama]:
    """The bundled panorama ``name`` as ``"full"`` and as ``"upper"`` (lower half black)."""
    full = read_panorama(panorama_path(name))
    upper = full.rgb.copy()
    upper[full.rgb.shape[0] // 2 :] = 0.0  # an object on a black stand
    return {"full": full, "upper": panorama_from_array(upper, source=name)}


def _field_loo(field: ReflectanceField, models: SampleModels) -> dict[str, Any]:
    """Leave-one-light-out errors of the field's models and of interpolation."""
    choice = choose_model(models)
    return {
        "chosen_model": choice.chosen,
        "loo": {row.name: row.loo_relative_rmse for row in choice.table}
        | {"interpolation: barycentric": interpolation_loo(field, "barycentric").relative_rmse},
    }


def bench_accuracy(out: Path, quick: bool) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Relative RMSE and PSNR against the simulator's ground truth over covered pixels.

    Returns the rows (one per scene, panorama, field, view and method) and the per-field
    leave-one-light-out table.
    """
    rows: list[dict[str, Any]] = []
    fields: list[dict[str, Any]] = []
    for scene in ("diffuse-sphere", "glossy-sphere", "textured-torus"):
        shadows = not get_scene(scene).convex
        for cameras, lights, points, size in ACCURACY_FIELDS[2:3] if quick else ACCURACY_FIELDS:
            samples = build_scene(scene, points)
            path = field_path(out, scene, cameras, lights, points, size, "float32")
            field = ReflectanceField.open(path)
            start = time.perf_counter()
            models = models_for_field(field)
            loo = _field_loo(field, models) | {"fit_or_load_s": time.perf_counter() - start}
            fields.append({"scene": scene, "S": cameras, "T": lights, "points": points} | loo)
            print(f"{scene} S={cameras} T={lights}: LOO {loo['loo']}")
            engines = {
                method: open_relighter(field, mode, models)
                for method, mode in ACCURACY_METHODS.items()
            }
            index = len(field.cameras) // 2
            views = {
                "captured": field.cameras[index],
                "between": between_view(field.cameras, index),
            }
            for name in PANORAMA_NAMES:
                for (env_name, panorama), (view_name, camera) in product(
                    environments(name).items(), views.items()
                ):
                    truth = truth_of(samples, panorama.rgb, camera, shadows)
                    for method, engine in engines.items():
                        row = {
                            "scene": scene,
                            "panorama": name,
                            "environment": env_name,
                            "S": cameras,
                            "T": lights,
                            "points": points,
                            "view": view_name,
                            "method": method,
                        } | _score(engine, panorama, camera, truth)
                        rows.append(row)
                        print(
                            f"{scene:15s} {name:14s} {env_name:5s} S={cameras:<3d} "
                            f"T={lights:<3d} {view_name:8s} {row['relative_rmse']:7.2%} "
                            f"{row['sample_relative_rmse']:7.2%}  {method}"
                        )
    return rows, fields


def format_accuracy(rows: list[dict[str, Any]], view: str = "between") -> str:
    """Markdown tables of relative RMSE at ``view``: one per field size, image (sample) %."""
    lights = [("courtyard.exr", "full"), ("courtyard.exr", "upper"), ("studio.exr", "full"),
              ("studio.exr", "upper")]  # fmt: skip
    header = " | ".join(f"{p.removesuffix('.exr')} {e}" for p, e in lights)
    out: list[str] = []
    sizes = sorted({(r["S"], r["T"], r["points"]) for r in rows}, key=lambda k: (k[1], k[0]))
    for cameras, count, points in sizes:
        out += [f"S = {cameras}, T = {count}, {points} points, {view} view: relative RMSE, "
                "image (samples)", "", f"| scene | method | {header} |",
                "|---|---|" + "---|" * len(lights)]  # fmt: skip
        chosen = [r for r in rows if (r["S"], r["T"], r["points"]) == (cameras, count, points)]
        for scene in dict.fromkeys(r["scene"] for r in chosen):
            for method in dict.fromkeys(r["method"] for r in chosen):
                cells = []
                for panorama, environment in lights:
                    match = [
                        r for r in chosen
                        if (r["scene"], r["method"], r["panorama"], r["environment"], r["view"])
                        == (scene, method, panorama, environment, view)
                    ]  # fmt: skip
                    cells.append(
                        f"{match[0]['relative_rmse']:.2%} ({match[0]['sample_relative_rmse']:.2%})"
                        if match
                        else "-"
                    )
                out.append(f"| {scene} | {method} | " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)


def format_loo(fields: list[dict[str, Any]]) -> str:
    """A Markdown table of each field's leave-one-light-out errors."""
    names = list(dict.fromkeys(name for f in fields for name in f["loo"]))
    out = [
        f"| scene | S | T | chosen | {' | '.join(names)} |",
        "|---|---|---|---|" + "---|" * len(names),
    ]
    for f in fields:
        cells = [f"{f['loo'][n]:.2%}" if n in f["loo"] else "-" for n in names]
        out.append(
            f"| {f['scene']} | {f['S']} | {f['T']} | {f['chosen_model']} | "
            + " | ".join(cells)
            + " |"
        )
    return "\n".join(out) + "\n"


def _chart(results: dict[str, Any], path: Path) -> None:
    figure, axis = plt.subplots(figsize=(7, 4.5))
    rows = [
        r
        for r in results["accuracy"]
        if r["S"] == 30 and r["T"] == 30 and r["environment"] == "upper"
    ]
    for method in ACCURACY_METHODS:
        chosen = [r for r in rows if r["method"] == method]
        axis.scatter(
            [r["render_ms"] for r in chosen],
            [100 * r["relative_rmse"] for r in chosen],
            label=method,
            s=18,
        )
    axis.set_xscale("log")
    axis.set_xlabel("relight + splat time per frame, ms (128 x 128, 20k points)")
    axis.set_ylabel("relative RMSE against ground truth, %")
    axis.set_title("Relighting: error against time (S = T = 30, upper-hemisphere light)")
    axis.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def main(argv: list[str] | None = None) -> int:
    """``python -m bench.relight [-o DIR] [--quick] [--only speed|accuracy]``; the exit status.

    Updates ``DIR/relight.json`` (the half not run is kept from an earlier run) and, with
    accuracy results, writes ``DIR/relight-accuracy.md`` and ``DIR/relight.png``.
    """
    parser = argparse.ArgumentParser(description="Relighting benchmark")
    parser.add_argument("-o", "--output", type=Path, default=Path("bench-out"))
    parser.add_argument("--quick", action="store_true", help="fewer points and fields")
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--only", choices=("speed", "accuracy"), help="run one half")
    args = parser.parse_args(argv)
    args.output.mkdir(parents=True, exist_ok=True)
    panorama = read_panorama(panorama_path("courtyard"))
    points = 50_000 if args.quick else 250_000
    target = args.output / "relight.json"
    results: dict[str, Any] = json.loads(target.read_text()) if target.exists() else {}
    if args.only != "accuracy":
        results["speed"] = bench_speed(args.output, points, args.repeats, panorama)
        print(json.dumps(results["speed"], indent=2))
    if args.only != "speed":
        results["accuracy"], results["leave_one_light_out"] = bench_accuracy(
            args.output, args.quick
        )
    target.write_text(json.dumps(results, indent=2) + "\n")
    if "accuracy" in results:
        tables = (
            format_accuracy(results["accuracy"])
            + "\n"
            + format_accuracy(results["accuracy"], "captured")
        )
        loo = format_loo(results.get("leave_one_light_out", []))
        (args.output / "relight-accuracy.md").write_text(tables + "\n" + loo)
        print(tables + "\n" + loo)
    if "accuracy" in results:
        _chart(results, args.output / "relight.png")
    print(f"wrote {target}")
    return 0


if __name__ == "__main__":
    from core.progress import drawing_bars

    with drawing_bars():  # the library's bars on stderr, as ``rig`` draws them
        status = main()
    raise SystemExit(status)

"""The models' precomputed lighting against the exact grid sum, per material: error and time.

``python -m bench.interactive -o DIR [--points 20000] [--grid 16] [--size 256]
[--bright 0,32,128]`` simulates each scene (``--grid`` lights x cameras), fits its models, and
relights a view between captured cameras under each bundled panorama at two yaws with the
models' exact 64 x 128 grid sum (``rig relight``'s default for a glossy field) and with the
precomputed lighting (:mod:`render.precomputed_lighting`) keeping 0, 32 or 128 of the brightest
blocks exact. It reports the relative RMSE of the precomputed image against the exact one
(over covered pixels, and over the samples shown), the time of a new lighting (a yaw: the
lighting and the frame) and of the exact frame. Writes ``interactive.json`` and
``interactive.md``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from core.camera_model import PinholeCamera
from core.field_store import ReflectanceField
from core.sample_data import PANORAMA_NAMES, panorama_path
from processing.image_quality import relative_rmse_values
from processing.panorama import read_panorama
from processing.sample_model_store import models_for_field
from render.engines.interpolated import RelitImage
from render.engines.models import ModelRelightSettings
from sim.field import field_cameras, simulate_field

__all__ = ["main", "relative_rmse"]

SCENES = ("diffuse-sphere", "glossy-sphere", "textured-torus")
YAWS = (0.0, 100.0)


def relative_rmse(image: RelitImage, reference: RelitImage) -> tuple[float, float]:
    """(over covered pixels, over the samples shown) of ``image`` against ``reference``."""
    covered = image.coverage & reference.coverage
    shown = image.needed & reference.needed
    return (
        relative_rmse_values(image.rgb, reference.rgb, covered),
        relative_rmse_values(image.radiance, reference.radiance, shown),
    )


def _scene_rows(
    field: ReflectanceField, scene: str, size: int, bright_counts: list[int]
) -> list[dict[str, Any]]:
    models = models_for_field(field)
    camera = PinholeCamera(20.0, 40.0, width=size, height=size)
    rows: list[dict[str, Any]] = []
    for env in PANORAMA_NAMES:
        panorama = read_panorama(panorama_path(env))
        exact = ModelRelightSettings(lighting="grid", grid_height=64).open(field, models)
        exact.set_view(camera)
        references, exact_ms = {}, []
        for yaw in YAWS:
            start = time.perf_counter()
            exact.set_lighting(panorama, yaw_deg=yaw)
            references[yaw] = exact.render()
            exact_ms.append(1000.0 * (time.perf_counter() - start))
        for bright in bright_counts:
            settings = ModelRelightSettings(lighting="precomputed", bright_lights=bright)
            fast = settings.open(field, models)
            fast.set_view(camera)
            start = time.perf_counter()
            fast.set_lighting(panorama)  # pre-filtering and the transfer, once
            fast.render()
            first_ms = 1000.0 * (time.perf_counter() - start)
            for yaw in YAWS:
                start = time.perf_counter()
                fast.set_lighting(panorama, yaw_deg=yaw)
                image = fast.render()
                new_lighting_ms = 1000.0 * (time.perf_counter() - start)
                pixels, samples = relative_rmse(image, references[yaw])
                rows.append({
                    "scene": scene, "environment": env, "yaw_deg": yaw, "bright": bright,
                    "error_image": pixels, "error_samples": samples,
                    "new_lighting_ms": new_lighting_ms,
                    "exact_frame_ms": float(np.median(exact_ms)),
                    "first_frame_ms": first_ms, "samples_shown": int(image.needed.sum()),
                })  # fmt: skip
                print(
                    f"{scene:15s} {env:9s} yaw {yaw:5.1f} bright {bright:3d}: error "
                    f"{pixels:.2%} (samples {samples:.2%}), new lighting "
                    f"{new_lighting_ms:.1f} ms, exact {np.median(exact_ms):.0f} ms",
                    flush=True,
                )
    return rows


def _markdown(rows: list[dict[str, Any]], points: int, grid: int, size: int) -> str:
    lines = [
        f"# Precomputed lighting against the exact grid sum ({points} points, {grid} lights x "
        f"{grid} cameras, {size} x {size} view)",
        "",
        "| scene | panorama | yaw | bright blocks exact | error (image) | error (samples) | "
        "new lighting ms | exact frame ms |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['scene']} | {r['environment']} | {r['yaw_deg']:g} | {r['bright']} | "
            f"{r['error_image']:.2%} | {r['error_samples']:.2%} | {r['new_lighting_ms']:.1f} | "
            f"{r['exact_frame_ms']:.0f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", type=Path, required=True, help="output directory")
    parser.add_argument("--points", type=int, default=20_000, help="points (default 20000)")
    parser.add_argument("--grid", type=int, default=16, help="lights = cameras (default 16)")
    parser.add_argument("--size", type=int, default=256, help="view side in pixels (256)")
    parser.add_argument("--bright", default="0,32,128", help="bright blocks kept exact")
    parser.add_argument("--scenes", default=",".join(SCENES), help="scenes to measure")
    args = parser.parse_args(argv)
    args.output.mkdir(parents=True, exist_ok=True)
    bright_counts = [int(v) for v in args.bright.split(",")]
    rows: list[dict[str, Any]] = []
    for scene in args.scenes.split(","):
        store = args.output / f"{scene}.zarr"
        if not store.exists():
            cameras = field_cameras(args.grid, width=96, height=96)
            simulate_field(store, scene, lights=args.grid, cameras=cameras, points=args.points)
        rows += _scene_rows(ReflectanceField.open(store), scene, args.size, bright_counts)
    result = {"points": args.points, "grid": args.grid, "size": args.size, "rows": rows}
    (args.output / "interactive.json").write_text(json.dumps(result, indent=2) + "\n")
    markdown = _markdown(rows, args.points, args.grid, args.size)
    (args.output / "interactive.md").write_text(markdown)
    print(markdown)
    return 0


if __name__ == "__main__":
    from core.progress import drawing_bars

    with drawing_bars():  # the library's bars on stderr, as ``rig`` draws them
        status = main()
    raise SystemExit(status)

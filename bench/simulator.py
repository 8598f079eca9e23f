"""Benchmark of the simulator: one-light images and ground truth under a panorama.

Run: ``python -m bench.simulator -o bench-out``. Prints a table and writes
``bench-out/simulator.json``. Medians after numba compilation, on this machine's cores.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from core.camera_model import PinholeCamera
from core.directions import direction_from_angles_deg
from core.sample_data import panorama_path
from processing.panorama import read_panorama
from sim.ground_truth import render_environment
from sim.scenes import build_scene
from sim.synthetic_camera import DirectionalLight, render_under_light


def _median_ms(run: Callable[[], object], repeats: int) -> float:
    run()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return float(np.median(times)) * 1e3


def main(argv: list[str] | None = None) -> int:
    """``python -m bench.simulator [-o DIR] [--repeats N]``; returns the exit status.

    Prints the table and writes ``DIR/simulator.json``.
    """
    parser = argparse.ArgumentParser(description="Simulator benchmark")
    parser.add_argument("-o", "--output", type=Path, default=Path("bench-out"))
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    camera = PinholeCamera(30.0, 60.0, 4.0, 40.0, 512, 512)
    x, y, z = direction_from_angles_deg(100.0, 50.0)
    light = DirectionalLight((float(x), float(y), float(z)))
    rows: list[dict[str, Any]] = []
    for scene in ("glossy-sphere", "textured-torus"):
        samples = build_scene(scene, 250_000)
        for shadows in (True, False):
            ms = _median_ms(
                partial(render_under_light, samples, camera, light, shadows=shadows), args.repeats
            )
            rows.append(
                {
                    "what": "one light, 512x512",
                    "scene": scene,
                    "points": 250_000,
                    "shadows": shadows,
                    "ms": ms,
                }
            )
    panorama = read_panorama(panorama_path("courtyard")).rgb
    small = PinholeCamera(30.0, 60.0, 4.0, 40.0, 256, 256)
    for scene, shadows in (("glossy-sphere", False), ("textured-torus", True)):
        samples = build_scene(scene, 50_000)
        for grid in (16, 32):
            ms = _median_ms(
                partial(
                    render_environment, samples, panorama, small, grid_height=grid, shadows=shadows
                ),
                max(1, args.repeats // 2),
            )
            rows.append(
                {
                    "what": f"ground truth, grid {grid}, 256x256",
                    "scene": scene,
                    "points": 50_000,
                    "shadows": shadows,
                    "ms": ms,
                }
            )
    for r in rows:
        print(
            f"{r['what']:32s} {r['scene']:15s} P={r['points']:7d}"
            f" shadows={r['shadows']!s:5s} {r['ms']:9.1f} ms"
        )
    args.output.mkdir(parents=True, exist_ok=True)
    (args.output / "simulator.json").write_text(json.dumps(rows, indent=2) + "\n")
    print(f"wrote {args.output / 'simulator.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

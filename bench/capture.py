"""Benchmark of a capture session's overhead on the simulated rig.

Run: ``python -m bench.capture -o bench-out [--cameras 4] [--lights 6] [--speed 1]``. Runs a
sweep through the real drivers against the emulators and splits the wall time: the motion the
plan's model predicts (the emulators move as the config says, so this is the physical motion),
the simulated camera's rendering (a real camera spends its exposure instead), and the rest,
the controller's own time (driver round trips and polling, safety checks, files, journal);
then builds the field from the dataset as ``rig process`` does
(:func:`processing.process_dataset.process_dataset`) for its throughput. Writes
``bench-out/capture.json`` and ``bench-out/capture.png``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from capture.dataset import Dataset
from capture.grid_plan import grid_plan
from capture.session import CaptureSession
from processing.process_dataset import process_dataset
from sim.capture_sources import simulated_capture_sources
from sim.simulated_rig import SimulatedRig, simulated_capture_config


def bench_capture(cameras: int, lights: int, speed: float, size: int) -> dict[str, Any]:
    """One sweep on the simulated rig; the time split and the controller's share."""
    config = simulated_capture_config("glossy-sphere", size=size, points=2000, speed=speed)
    plan = grid_plan(cameras, lights, exposures_ms=(40.0,), layout="fibonacci")
    estimate = plan.estimate(config)
    scratch = Path(tempfile.mkdtemp(prefix="bench-capture-"))
    try:
        dataset = Dataset.create(
            scratch / "dataset",
            rig_config=config.to_dict(),
            plan=plan.to_dict(),
            planned=plan.planned_keys(config),
        )
        with SimulatedRig(config) as simulated, simulated.rig() as rig:
            result = CaptureSession(rig, dataset, plan).run()
        # Field building on the same dataset (what `rig process` does), for the throughput.
        started = time.perf_counter()
        sources = simulated_capture_sources(dataset.rig_config)
        process_dataset(scratch / "dataset", scratch / "f.zarr", sources)
        process_s = time.perf_counter() - started
    finally:
        shutil.rmtree(scratch)
    seconds = result.seconds
    motion = estimate.motion_s
    exposure = estimate.exposure_s
    controller = seconds["total"] - motion - seconds["capture"]
    return {
        "cameras": cameras,
        "lights": lights,
        "images": result.taken,
        "speed_factor": speed,
        "image_size": size,
        "exit_status": result.exit_status,
        "wall_s": seconds,
        "modelled_motion_s": motion,
        "exposure_s": exposure,
        "camera_simulation_s": seconds["capture"],
        "controller_s": controller,
        "controller_share_of_motion_and_exposure": controller / (motion + exposure),
        "controller_ms_per_image": 1e3 * controller / max(result.taken, 1),
        "process_s": process_s,
        "process_images_per_s": result.taken / process_s,
    }


def _chart(result: dict[str, Any], path: Path) -> None:
    parts = {
        "motion (model)": result["modelled_motion_s"],
        "camera (simulation)": result["camera_simulation_s"],
        "controller": result["controller_s"],
    }
    figure, axis = plt.subplots(figsize=(7, 2.2))
    left = 0.0
    for name, value in parts.items():
        axis.barh([0], [value], left=left, label=f"{name}: {value:.2f} s")
        left += value
    axis.set_yticks([])
    axis.set_xlabel("seconds")
    share = result["controller_share_of_motion_and_exposure"]
    axis.set_title(
        f"Capture of {result['images']} images on the simulated rig: controller {share:.1%} of "
        "motion + exposure"
    )
    axis.legend(fontsize=7, loc="lower right")
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def main(argv: list[str] | None = None) -> int:
    """``python -m bench.capture [-o DIR] [--cameras S] [--lights T]``; returns the exit status.

    Also ``--speed`` (axis speed factor) and ``--size`` (image side, pixels). Writes
    ``DIR/capture.json`` and ``DIR/capture.png`` and prints the result.
    """
    parser = argparse.ArgumentParser(description="Capture overhead benchmark")
    parser.add_argument("-o", "--output", type=Path, default=Path("bench-out"))
    parser.add_argument("--cameras", type=int, default=4)
    parser.add_argument("--lights", type=int, default=6)
    parser.add_argument("--speed", type=float, default=1.0, help="axis speed factor")
    parser.add_argument("--size", type=int, default=64, help="image side, pixels")
    args = parser.parse_args(argv)
    args.output.mkdir(parents=True, exist_ok=True)
    result = bench_capture(args.cameras, args.lights, args.speed, args.size)
    (args.output / "capture.json").write_text(json.dumps(result, indent=2) + "\n")
    _chart(result, args.output / "capture.png")
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

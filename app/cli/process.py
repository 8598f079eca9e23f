"""The ``rig process`` command: a capture dataset to a reflectance field store.

A thin layer over :func:`processing.process_dataset.process_dataset`; a simulated capture's
scene and sensor come from :func:`sim.capture_sources.simulated_capture_sources`.
"""

from __future__ import annotations

import argparse
import dataclasses
import resource
import sys
from pathlib import Path
from typing import Any

from app.cli.args import (
    add_dask_options,
    cluster_for,
    count,
    image_size,
    output_directory,
    positive,
)
from core.errors import InputError

__all__ = ["add_process"]


def add_process(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig process DATASET -o FIELD`` on the ``rig`` sub-command set."""
    # Spelled out call by call, like every command's parser (duplicates pairs them by shape):
    # the options read here as --help prints them; those shared are app.cli.args' add_*.
    p = commands.add_parser(
        "process",
        help="build a reflectance field store from a capture dataset",
        description="Decode every image of a capture (RAW, 16-bit linear, 8-bit sRGB, EXR), "
        "subtract the dark frames, merge exposure brackets, project the object's points into "
        "every camera pose, sample the images where the depth test shows the points, and write "
        "a Zarr field store. A simulated capture needs no more flags: its manifest's rig config "
        "names the scene and the camera.",
    )
    p.add_argument("dataset", type=Path, help="capture dataset directory")
    p.add_argument(
        "-o", "--output", type=output_directory, required=True, help="field store directory"
    )
    source = p.add_mutually_exclusive_group()
    source.add_argument("--points", type=Path, help="the object's point cloud (.ply or .npz)")
    source.add_argument("--scene", help="synthetic scene (default: a simulated capture's)")
    p.add_argument("--scene-points", type=count, help="points of --scene (default: the config's)")
    p.add_argument("--spacing", type=positive, help="point spacing (default: from the cloud)")
    p.add_argument("--camera-distance", type=positive, help="camera distance from the object")
    p.add_argument("--fov", type=positive, help="horizontal field of view, degrees")
    p.add_argument("--size", type=image_size, help="image WIDTHxHEIGHT (default: the images')")
    p.add_argument(
        "--radiance-scale",
        type=positive,
        help="decoded value per unit radiance per ms (default: the simulated sensor's, else 1)",
    )
    p.add_argument("--light-intensity", type=positive, default=1.0, help="uncalibrated lights")
    p.add_argument(
        "--ignore-calibration",
        action="store_true",
        help="use the measured poses, not the manifest's calibration",
    )
    p.add_argument("--allow-missing", action="store_true", help="leave missing images at zero")
    p.add_argument("--dtype", choices=("float32", "float16"), default="float32")
    p.add_argument("--demosaic", default="linear", help="RAW demosaicing (default linear)")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a field store already at -o (and the fit saved beside it)",
    )
    add_dask_options(p)
    p.set_defaults(handler=_run_process)


def _sources(args: argparse.Namespace, dataset: Any) -> Any:
    """The object's points and the camera's scale, from --points, --scene or the simulation."""
    from processing.process_dataset import point_cloud_sources
    from sim.capture_sources import simulated_capture_sources

    if args.points is not None:
        return point_cloud_sources(
            args.points, spacing=args.spacing, radiance_scale=args.radiance_scale
        )
    try:
        sources = simulated_capture_sources(
            dataset.rig_config, scene=args.scene, points=args.scene_points
        )
    except InputError:
        if args.scene is not None:
            raise  # the scene named is unknown: its own message says so
        raise InputError(
            f"{args.dataset}: not a simulated capture; give the object's points with --points "
            f"PLY|NPZ (or a synthetic --scene)"
        ) from None
    if args.spacing is not None:
        sources = dataclasses.replace(sources, spacing=args.spacing)
    if args.radiance_scale is not None:
        sources = dataclasses.replace(sources, radiance_scale=args.radiance_scale)
    return sources


def _run_process(args: argparse.Namespace) -> int:
    from capture.dataset import Dataset

    dataset = Dataset.open(args.dataset)
    with cluster_for(args) as client:
        report = _process(args, dataset, client)
    s, t, p = report.shape
    kib = 1024.0 if sys.platform == "darwin" else 1.0  # ru_maxrss: bytes on macOS, else KiB
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / kib / 1024.0
    print(
        f"{args.dataset}: {s} cameras x {t} lights x {p} points from {report.exposures} "
        f"exposures ({report.dark_frames} dark frames) in {report.seconds:.1f} s, visible "
        f"{report.visible_fraction:.1%}, saturated {report.saturated_fraction:.2%}, peak RSS "
        f"{peak_mb:.0f} MB -> {args.output}"
    )
    if report.removed_partials:
        names = [path.name for path in report.removed_partials]
        shown = ", ".join(names[:3]) + (", ..." if len(names) > 3 else "")
        print(
            f"note: removed {len(names)} partial stores of {args.output.name} left by runs that "
            f"were killed ({shown})"
        )
    if report.left_out:
        shown = ", ".join(report.left_out[:3]) + (", ..." if len(report.left_out) > 3 else "")
        print(f"note: {len(report.left_out)} planned images left out ({shown}), interpolated")
    if report.absent_cameras:
        print(
            f"warning: the field lacks cameras {report.absent_cameras} of the plan (no image "
            "of theirs was taken)"
        )
    if report.without_dark:
        print(f"warning: {report.without_dark} exposures had no dark frame (not subtracted)")
    if report.missing:
        print(
            f"note: {len(report.missing)} (camera, light) pairs without an image (skipped by the "
            "plan, e.g. the light where the camera stands) interpolated from the camera's "
            "other lights"
        )
    if max(report.camera_spread_deg, report.light_spread_deg) > 0.5:
        print(
            f"warning: measured poses of one index spread {report.camera_spread_deg:.2f} deg "
            f"(cameras), {report.light_spread_deg:.2f} deg (lights)"
        )
    return 0


def _process(args: argparse.Namespace, dataset: Any, client: Any) -> Any:
    from processing.process_dataset import process_dataset

    return process_dataset(
        dataset,
        args.output,
        _sources(args, dataset),
        camera_distance=args.camera_distance,
        fov_deg=args.fov,
        size=args.size,
        ignore_calibration=args.ignore_calibration,
        light_intensity=args.light_intensity,
        allow_missing=args.allow_missing,
        dtype=args.dtype,
        demosaic=args.demosaic,
        overwrite=args.overwrite,
        client=client,
    )

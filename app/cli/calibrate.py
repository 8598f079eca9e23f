"""The ``rig calibrate`` command: solve a dataset's calibration captures into its manifest.

A thin layer over :func:`processing.calibrate_dataset.calibrate_dataset` (see
``docs/calibration.md``): it builds the nominal camera model and the targets from the flags and
the dataset's rig config snapshot, prints what it found, and stores the calibration.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from app.cli.args import positive, squares
from core.errors import InputError

__all__ = ["add_calibrate"]


def add_calibrate(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig calibrate DATASET`` on the ``rig`` sub-command set."""
    # Spelled out call by call, like every command's parser (duplicates pairs them by shape):
    # the options read here as --help prints them; those shared are app.cli.args' add_*.
    p = commands.add_parser(
        "calibrate",
        help="solve a dataset's calibration captures (ChArUco, mirror sphere, white target)",
        description="Read the dataset's calibration images: a ChArUco board at the object's "
        "place per camera pose (camera poses; intrinsics too with enough views), a mirror "
        "sphere per light (light directions), a white target per light (intensities). Print "
        "each camera's disagreement with the rig kinematics and each light's with its commanded "
        "pose, and store the calibration in the manifest (rig process then uses it).",
    )
    p.add_argument("dataset", type=Path, help="capture dataset directory")
    p.add_argument("--camera-distance", type=positive, help="nominal camera distance (config's)")
    p.add_argument("--fov", type=positive, help="nominal horizontal field of view, deg (config's)")
    p.add_argument(
        "--intrinsics",
        choices=("auto", "board", "nominal"),
        default="auto",
        help="from the ChArUco views (auto: with 6 or more), or the nominal camera's",
    )
    p.add_argument("--board", type=squares, default=(5, 5), help="ChArUco squares XxY (5x5)")
    p.add_argument("--square-length", type=positive, default=0.45, help="scene units (0.45)")
    p.add_argument("--marker-length", type=positive, default=0.33, help="scene units (0.33)")
    p.add_argument("--dictionary", default="DICT_4X4_50", help="ArUco dictionary (DICT_4X4_50)")
    p.add_argument("--sphere-radius", type=positive, default=1.0, help="mirror sphere radius (1)")
    p.add_argument("--white-albedo", type=positive, default=0.8, help="white target albedo (0.8)")
    p.add_argument("--white-half-size", type=positive, default=1.5, help="its half side (1.5)")
    p.add_argument(
        "--light-distance",
        type=positive,
        help="point lights at this distance (default: a simulated config's, else distant)",
    )
    p.add_argument("--dry-run", action="store_true", help="print, do not store")
    p.set_defaults(handler=_run_calibrate)


def _nominal(args: argparse.Namespace, dataset: Any, camera: dict[str, Any]) -> Any:
    """The rig's camera model from the flags, else the config snapshot's camera section."""
    from core.camera_model import RigCamera
    from processing.decode import decode_image

    distance = args.camera_distance if args.camera_distance is not None else camera.get("distance")
    fov = args.fov if args.fov is not None else camera.get("fov_deg")
    if distance is None or fov is None:
        raise InputError(
            f"{args.dataset}: the rig config has no camera distance and field of view; give "
            "--camera-distance and --fov"
        )
    if camera.get("width") and camera.get("height"):
        width, height = int(camera["width"]), int(camera["height"])
    else:
        first = next((r for r in dataset.records if r.kind == "calibration"), None)
        if first is None:
            raise InputError(f"{args.dataset}: the dataset has no calibration images")
        height, width = decode_image(dataset.image_path(first)).linear.shape[:2]
    return RigCamera(float(distance), float(fov), width, height)


def _run_calibrate(args: argparse.Namespace) -> int:
    from capture.dataset import Dataset
    from processing.calibrate_dataset import calibrate_dataset
    from processing.charuco import ChArUcoTarget
    from processing.light_falloff import WhiteReference
    from processing.light_probe import MirrorSphere

    squares_x, squares_y = args.board
    dataset = Dataset.open(args.dataset)
    camera: dict[str, Any] = dict(dataset.rig_config.get("camera") or {})
    light_distance = args.light_distance
    if light_distance is None and camera.get("backend") == "simulated":
        light_distance = camera.get("light_distance")
    report = calibrate_dataset(
        dataset,
        nominal_camera=_nominal(args, dataset, camera),
        board=ChArUcoTarget(
            squares_x, squares_y, args.square_length, args.marker_length, args.dictionary
        ),
        sphere=MirrorSphere(args.sphere_radius),
        white=WhiteReference(albedo=args.white_albedo, half_size=args.white_half_size),
        light_distance=light_distance,
        intrinsics=args.intrinsics,
    )
    for line in report.lines():
        print(line)
    if not args.dry_run:
        dataset.set_calibration(report.calibration.to_dict())
        dataset.save()
        print(f"calibration stored in {dataset.manifest_path}")
    return 1 if report.problems else 0

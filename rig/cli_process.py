"""The ``rig process`` command: a capture dataset to a reflectance field store.

Application layer (it may import ``sim``: a simulated capture's scene gives the object's points,
and its sensor the radiometric scale), over :func:`processing.field_builder.build_field`.
"""

from __future__ import annotations

import argparse
import resource
import sys
from pathlib import Path
from typing import Any

from rig.errors import InputError

__all__ = ["add_process"]


def add_process(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig process DATASET -o FIELD`` on the ``rig`` sub-command set."""
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
    p.add_argument("-o", "--output", type=Path, required=True, help="field store directory")
    source = p.add_mutually_exclusive_group()
    source.add_argument("--points", type=Path, help="the object's point cloud (.ply or .npz)")
    source.add_argument("--scene", help="synthetic scene (default: a simulated capture's)")
    p.add_argument("--scene-points", type=int, help="points of --scene (default: the config's)")
    p.add_argument("--spacing", type=float, help="point spacing (default: from the cloud)")
    p.add_argument("--camera-distance", type=float, help="camera distance from the object")
    p.add_argument("--fov", type=float, help="horizontal field of view, degrees")
    p.add_argument("--size", type=_size, help="image WIDTHxHEIGHT (default: the images')")
    p.add_argument(
        "--radiance-scale",
        type=float,
        help="decoded value per unit radiance per ms (default: the simulated sensor's, else 1)",
    )
    p.add_argument("--light-intensity", type=float, default=1.0, help="uncalibrated lights")
    p.add_argument(
        "--ignore-calibration",
        action="store_true",
        help="use the measured poses, not the manifest's calibration",
    )
    p.add_argument("--allow-missing", action="store_true", help="leave missing images at zero")
    p.add_argument("--dtype", choices=("float32", "float16"), default="float32")
    p.add_argument("--demosaic", default="linear", help="RAW demosaicing (default linear)")
    p.set_defaults(handler=_run_process)


def _size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got {text!r}") from None
    return width, height


def _cloud(args: argparse.Namespace, camera: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
    """The object's points and what they are, from --points, --scene or the simulated config."""
    from processing.field_builder import PointCloud, read_point_cloud

    if args.points is not None:
        cloud = read_point_cloud(args.points)
        if args.spacing is not None:
            cloud = PointCloud(cloud.points, cloud.normals, args.spacing)
        return cloud, {"points_file": str(args.points)}
    scene = args.scene or (camera.get("scene") if camera.get("backend") == "simulated" else None)
    if scene is None:
        raise InputError(
            f"{args.dataset}: not a simulated capture; give the object's points with --points "
            f"PLY|NPZ (or a synthetic --scene)"
        )
    from sim.scenes import build_scene

    count = args.scene_points or int(camera.get("points", 20_000))
    samples = build_scene(scene, count)
    spacing = args.spacing if args.spacing is not None else samples.spacing
    return PointCloud.from_arrays(samples.points, samples.normals, spacing), {
        "scene": scene,
        "scene_points": count,
    }


def _rig_camera(args: argparse.Namespace, dataset: Any, camera: dict[str, Any]) -> Any:
    """The camera model from the flags, else the config snapshot, else the first image's size."""
    from processing.decode import decode_image
    from processing.field_builder import RigCamera

    distance = args.camera_distance if args.camera_distance is not None else camera.get("distance")
    fov = args.fov if args.fov is not None else camera.get("fov_deg")
    if args.size is not None:
        width, height = args.size
    elif camera.get("width") and camera.get("height"):
        width, height = int(camera["width"]), int(camera["height"])
    else:
        first = next((r for r in dataset.records if r.kind == "light"), None)
        if first is None:
            return None
        height, width = decode_image(dataset.image_path(first)).shape
    if distance is None or fov is None:
        return None
    return RigCamera(float(distance), float(fov), width, height)


def _run_process(args: argparse.Namespace) -> int:
    from capture.dataset import Dataset
    from processing.field_builder import build_field

    dataset = Dataset.open(args.dataset)
    camera: dict[str, Any] = dict(dataset.rig_config.get("camera") or {})
    simulated = camera.get("backend") == "simulated"
    cloud, source = _cloud(args, camera)
    calibration = None if args.ignore_calibration else (dataset.calibration or None)
    rig_camera = _rig_camera(args, dataset, camera)
    if rig_camera is None and not (calibration and "cameras" in calibration):
        raise InputError(
            f"{args.dataset}: no camera model; give --camera-distance and --fov (and --size), or "
            f"calibrate the cameras"
        )
    scale = args.radiance_scale
    if scale is None and simulated:
        from sim.sensor import Sensor

        sensor = Sensor()  # the simulated camera's sensor (rig.config has no sensor keys)
        scale = sensor.sensitivity / (1000.0 * sensor.full_well)
    light_model = None
    if simulated and camera.get("light_distance") is not None:
        distance = float(camera["light_distance"])
        light_model = {"type": "point", "distance": distance, "irradiance_at_origin": 1.0}
    report = build_field(
        dataset,
        args.output,
        cloud,
        camera=rig_camera,
        calibration=calibration,
        radiance_scale=1.0 if scale is None else scale,
        light_intensity=args.light_intensity,
        allow_missing=args.allow_missing,
        dtype=args.dtype,
        demosaic=args.demosaic,
        light_model=light_model,
        provenance={"tool": "rig process", **source},
        progress=True,
    )
    s, t, p = report.shape
    kib = 1024.0 if sys.platform == "darwin" else 1.0  # ru_maxrss: bytes on macOS, else KiB
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / kib / 1024.0
    print(
        f"{args.dataset}: {s} cameras x {t} lights x {p} points from {report.exposures} "
        f"exposures ({report.dark_frames} dark frames) in {report.seconds:.1f} s, visible "
        f"{report.visible_fraction:.1%}, saturated {report.saturated_fraction:.2%}, peak RSS "
        f"{peak_mb:.0f} MB -> {args.output}"
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

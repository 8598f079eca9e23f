"""Calibrate a capture dataset from its calibration images (``rig calibrate``).

A dataset whose plan lists calibration captures (:class:`capture.plan.CalibrationCapture`,
image kind ``"calibration"``) holds, by capture name:

- ``charuco``: the ChArUco board flat at the object's place, seen from a camera pose. Each
  gives that camera pose's extrinsics (:func:`processing.charuco.board_extrinsics`); with at
  least ``min_intrinsics_views`` of them the camera's intrinsics too
  (:func:`processing.charuco.calibrate_intrinsics`), else the rig's nominal camera model.
- ``mirror-sphere``: the chrome ball at the object's place under one light, seen from a
  calibrated camera pose: that light's direction
  (:func:`processing.light_probe.light_directions_from_mirror_sphere`).
- ``white-target``: the white target under one light: its intensity (relative, mean 1) and,
  for point lights, its falloff exponent
  (:func:`processing.light_falloff.light_intensity_and_falloff`).

:func:`calibrate_dataset` solves them all and returns a :class:`CalibrationReport` whose
``calibration`` is what the dataset's manifest stores
(:meth:`capture.dataset.Dataset.set_calibration` of
:meth:`processing.calibration.Calibration.to_dict`), with each camera's disagreement with
the rig's kinematics (the nominal camera at the measured pose) and each light's angle from its
commanded pose. Camera poses or lights whose images fail are kept at the nominal value and named
in ``problems``. See ``docs/calibration.md``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Container, Iterator, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from capture.dataset import Dataset
from capture.manifest import ImageRecord
from capture.plan import SweepPlan
from core.calibrated_camera import CalibratedCamera, CameraPose, Intrinsics, PoseDisagreement
from core.camera_model import RigCamera
from core.directions import direction_from_angles_deg
from core.errors import DatasetError, RigError
from processing.calibration import Calibration, LightCalibration
from processing.charuco import ChArUcoTarget, board_extrinsics, calibrate_intrinsics
from processing.decode import decode_image
from processing.light_falloff import WhiteReference, light_intensity_and_falloff
from processing.light_probe import MirrorSphere, light_directions_from_mirror_sphere

__all__ = [
    "DEFAULT_BOARD",
    "DEFAULT_SPHERE",
    "CalibrationReport",
    "calibrate_dataset",
]

F64 = NDArray[np.float64]
#: The rig's printed ChArUco board (and the simulator's, ``sim.simulated_camera.BOARD``): 5 x 5
#: squares of 0.45 with 0.33 markers of a 4 x 4 dictionary, found in images of 160 pixels.
DEFAULT_BOARD = ChArUcoTarget(5, 5, 0.45, 0.33, "DICT_4X4_50")
#: The rig's chrome ball (and the simulator's): radius 1 at the object's place.
DEFAULT_SPHERE = MirrorSphere(1.0)
#: Intrinsics from the board views when there are at least this many (else nominal).
MIN_INTRINSICS_VIEWS = 6


@dataclass(frozen=True)
class CalibrationReport:
    """What :func:`calibrate_dataset` found.

    Attributes
    ----------
    calibration : Calibration, for the manifest (cameras by camera index, lights by light index)
    intrinsics_source : "board" (from the ChArUco views) or "nominal" (the rig's camera model)
    cameras : dict of camera index to PoseDisagreement with the rig kinematics (calibrated ones)
    light_errors_deg : dict of light index to the angle between the measured direction and the
        commanded light pose (calibrated ones)
    intensities : dict of light index to relative intensity (mean 1 over the measured lights)
    problems : list of str, images that gave nothing (the pose or light kept at nominal)
    """

    calibration: Calibration
    intrinsics_source: str
    cameras: dict[int, PoseDisagreement] = field(default_factory=dict)
    light_errors_deg: dict[int, float] = field(default_factory=dict)
    intensities: dict[int, float] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)

    def lines(self) -> list[str]:
        """A summary for people, one line per camera and light."""
        intrinsics = self.calibration.intrinsics
        out = []
        if intrinsics is not None:
            out.append(
                f"intrinsics ({self.intrinsics_source}): fx {intrinsics.fx:.2f} fy "
                f"{intrinsics.fy:.2f} px, principal point ({intrinsics.cx:.2f}, "
                f"{intrinsics.cy:.2f}), RMS {intrinsics.rms_px:.3f} px, {intrinsics.views} views"
            )
        for index, d in sorted(self.cameras.items()):
            pose = self.calibration.cameras[index]
            out.append(
                f"camera {index}: direction {d.direction_error_deg:.3f} deg, distance "
                f"{d.distance_error:+.4f}, orientation {d.orientation_error_deg:.3f} deg from the "
                f"rig kinematics (RMS {pose.rms_px:.3f} px, {pose.corners} corners)"
            )
        for index, angle in sorted(self.light_errors_deg.items()):
            intensity = self.intensities.get(index)
            extra = "" if intensity is None else f", relative intensity {intensity:.4f}"
            out.append(f"light {index}: direction {angle:.3f} deg from the commanded pose{extra}")
        out += [f"problem: {p}" for p in self.problems]
        return out


def _angles_direction(pose: dict[str, float], role: str) -> F64:
    """Unit vector toward the camera or light (``role``) of a pose dict, object's frame."""
    turn = pose.get("turntable_deg", 0.0)
    return direction_from_angles_deg(
        pose[f"{role}_azimuth_deg"] - turn, pose[f"{role}_inclination_deg"]
    )


def _vec(values: Any) -> tuple[float, float, float]:
    v = np.asarray(values, dtype=np.float64).reshape(3)
    return (float(v[0]), float(v[1]), float(v[2]))


def _angle_deg(a: F64, b: F64) -> float:
    return math.degrees(math.atan2(float(np.linalg.norm(np.cross(a, b))), float(a @ b)))


def _by_capture(
    dataset: Dataset, plan: SweepPlan, name: str
) -> dict[int, tuple[int, int | None, list[ImageRecord]]]:
    """Calibration index to (camera index, plan light index, records by exposure) of ``name``."""
    found: dict[int, tuple[int, int | None, list[ImageRecord]]] = {}
    for record in sorted(dataset.records, key=lambda r: (r.light_index or 0, r.exposure_index)):
        if record.kind != "calibration" or record.light_index is None:
            continue
        if record.light_index >= len(plan.calibration):
            raise DatasetError(f"{record.file}: calibration index {record.light_index} not planned")
        capture = plan.calibration[record.light_index]
        if capture.name == name:
            entry = found.setdefault(
                record.light_index, (capture.camera_index, capture.light_index, [])
            )
            entry[2].append(record)
    return found


def _image(dataset: Dataset, records: Sequence[ImageRecord]) -> tuple[NDArray[Any], ImageRecord]:
    """The bracket's best image as linear float RGB, and its record.

    The best is the longest exposure with under 0.5 % saturated pixels (else the shortest).
    """
    ordered = sorted(records, key=lambda r: r.exposure_ms)
    for record in reversed(ordered[1:]):
        decoded = decode_image(dataset.image_path(record))
        if decoded.saturated.any(axis=2).mean() < 0.005:
            return decoded.linear, record
    return decode_image(dataset.image_path(ordered[0])).linear, ordered[0]


def _light_images(
    dataset: Dataset,
    captures: dict[int, tuple[int, int | None, list[ImageRecord]]],
    intrinsics: Intrinsics,
    poses: Sequence[CameraPose],
    solved: Container[int],
) -> Iterator[tuple[int, NDArray[Any], ImageRecord, CalibratedCamera]]:
    """Each plan light's calibration image: light index, best image, its record, its camera.

    A capture under no plan light, or of a light already in ``solved``, is passed over;
    ``solved`` is looked up as each capture comes, so it may grow while this runs.
    """
    for camera_index, light_index, records in captures.values():
        if light_index is None or light_index in solved:
            continue
        image, record = _image(dataset, records)
        yield light_index, image, record, CalibratedCamera(intrinsics, poses[camera_index])


def _attempt(problems: list[str], what: str, solve: Callable[[], Any]) -> Any:
    try:
        return solve()
    except RigError as error:
        problems.append(f"{what}: {error}")
        return None


def calibrate_dataset(
    dataset: Dataset,
    *,
    nominal_camera: RigCamera,
    board: ChArUcoTarget = DEFAULT_BOARD,
    sphere: MirrorSphere = DEFAULT_SPHERE,
    white: WhiteReference | None = None,
    light_distance: float | None = None,
    intrinsics: Literal["auto", "board", "nominal"] = "auto",
    min_intrinsics_views: int = MIN_INTRINSICS_VIEWS,
) -> CalibrationReport:
    """Solve a dataset's calibration captures (see the module docstring).

    Parameters
    ----------
    dataset : Dataset, with calibration images (its plan's ``calibration`` names them)
    nominal_camera : RigCamera, the rig's camera model (distance, field of view, image size)
    board, sphere, white : the targets as placed (default: the rig's, the simulator's)
    light_distance : float, optional, point lights at this distance (None: distant lights)
    intrinsics : {"auto", "board", "nominal"}
        From the ChArUco views ("auto": when there are ``min_intrinsics_views`` or more), or
        the nominal camera's.
    min_intrinsics_views : int

    Returns
    -------
    CalibrationReport

    Raises
    ------
    DatasetError
        The dataset has no calibration images.
    """
    plan = SweepPlan.from_dict(dataset.plan)
    problems: list[str] = []
    charuco = _by_capture(dataset, plan, "charuco")
    spheres = _by_capture(dataset, plan, "mirror-sphere")
    whites = _by_capture(dataset, plan, "white-target")
    if not (charuco or spheres or whites):
        raise DatasetError(
            f"{dataset.path}: no calibration images (charuco, mirror-sphere, white-target); "
            "capture with calibration captures in the plan (rig capture --sim --calibrate)"
        )
    nominal: dict[int, Any] = {}
    views: dict[int, tuple[NDArray[Any], str]] = {}
    for camera_index, _, records in charuco.values():
        if camera_index in views:
            continue
        image, record = _image(dataset, records)
        views[camera_index] = (image, record.file)
        where = record.measured_pose
        turn = where.get("turntable_deg", 0.0)
        nominal[camera_index] = nominal_camera.at(
            where["camera_azimuth_deg"] - turn, where["camera_inclination_deg"]
        )

    source = "nominal"
    solved: Intrinsics | None = None
    if intrinsics == "board" or (intrinsics == "auto" and len(views) >= min_intrinsics_views):
        images = [v[0] for v in views.values()]
        names = [v[1] for v in views.values()]
        solved = _attempt(
            problems,
            "intrinsics",
            partial(calibrate_intrinsics, images, board, names=names, zero_tangential=True),
        )
        source = "board" if solved is not None else source
    if solved is None:
        solved = Intrinsics.from_pinhole(nominal_camera.at(0.0, 45.0))

    # Camera poses, by camera index; the nominal ones where no board view solved.
    poses: list[CameraPose] = []
    errors: dict[int, PoseDisagreement] = {}
    for c, (azimuth, inclination) in enumerate(plan.cameras):
        pinhole = nominal.get(c) or nominal_camera.at(azimuth, inclination)
        pose = None
        if c in views:
            image, name = views[c]
            pose = _attempt(
                problems,
                f"camera {c}",
                partial(board_extrinsics, image, solved, board, nominal=pinhole, name=name),
            )
        if pose is None:
            poses.append(CameraPose.from_pinhole(pinhole))
            continue
        poses.append(pose)
        errors[c] = pose.disagreement

    lights, light_errors, measured = _lights(
        dataset, plan, spheres, solved, poses, sphere, light_distance, problems
    )
    intensities = _intensities(
        dataset, whites, solved, poses, lights, white, light_distance, problems
    )
    calibrated_lights = tuple(
        LightCalibration(
            direction=light.direction,
            position=None
            if light_distance is None or t not in measured
            else _vec(light_distance * np.asarray(light.direction)),
            intensity=intensities.get(t, (None, None))[0],
            falloff_exponent=intensities.get(t, (None, None))[1],
        )
        for t, light in enumerate(lights)
    )
    calibration = Calibration(solved, tuple(poses), calibrated_lights if measured else ())
    return CalibrationReport(
        calibration=calibration,
        intrinsics_source=source,
        cameras=errors,
        light_errors_deg=light_errors,
        intensities={t: v[0] for t, v in intensities.items() if v[0] is not None},
        problems=problems,
    )


def _lights(
    dataset: Dataset,
    plan: SweepPlan,
    spheres: dict[int, tuple[int, int | None, list[ImageRecord]]],
    intrinsics: Intrinsics,
    poses: Sequence[CameraPose],
    sphere: MirrorSphere,
    light_distance: float | None,
    problems: list[str],
) -> tuple[list[LightCalibration], dict[int, float], set[int]]:
    """Every plan light: measured from its mirror-sphere image, else the commanded direction."""
    lights = [
        LightCalibration(direction=_vec(direction_from_angles_deg(a, i))) for a, i in plan.lights
    ]
    errors: dict[int, float] = {}
    measured: set[int] = set()
    for light_index, image, record, camera in _light_images(
        dataset, spheres, intrinsics, poses, measured
    ):
        directions = _attempt(
            problems,
            f"light {light_index}",
            partial(
                light_directions_from_mirror_sphere,
                [image],
                camera,
                sphere,
                light_distance=light_distance,
                names=[record.file],
            ),
        )
        if directions is None:
            continue
        direction = np.asarray(directions[0], dtype=np.float64)
        commanded = _angles_direction(record.commanded_pose, "light")
        errors[light_index] = _angle_deg(direction, commanded)
        lights[light_index] = LightCalibration(direction=_vec(direction))
        measured.add(light_index)
    return lights, errors, measured


def _intensities(
    dataset: Dataset,
    whites: dict[int, tuple[int, int | None, list[ImageRecord]]],
    intrinsics: Intrinsics,
    poses: Sequence[CameraPose],
    lights: Sequence[LightCalibration],
    white: WhiteReference | None,
    light_distance: float | None,
    problems: list[str],
) -> dict[int, tuple[float | None, float | None]]:
    """Light index to (relative intensity, falloff exponent) from the white-target images."""
    irradiance: dict[int, tuple[float, float | None]] = {}
    for light_index, image, record, camera in _light_images(
        dataset, whites, intrinsics, poses, irradiance
    ):
        result = _attempt(
            problems,
            f"light {light_index} intensity",
            partial(
                light_intensity_and_falloff,
                [image],
                camera,
                [lights[light_index].direction],
                distances=light_distance,
                target=white,
                names=[record.file],
            ),
        )
        if result is None:
            continue
        exponent = float(result.falloff_exponent[0])
        irradiance[light_index] = (
            float(result.irradiance[0]) / record.exposure_ms,
            exponent if math.isfinite(exponent) else None,
        )
    if not irradiance:
        return {}
    mean = float(np.mean([e for e, _ in irradiance.values()]))
    return {t: (e / mean, p) for t, (e, p) in irradiance.items()}

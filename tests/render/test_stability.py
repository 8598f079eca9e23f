"""Each failure case of bench.stability, small: the warning fires where the measured error
against the simulator's ground truth is large and stays quiet where it is small."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from bench.stability import energy_matched_ldr, in_memory, measure, sensor_field
from capture.dataset import Dataset, ImageKey
from core.camera_model import PinholeCamera, RigCamera
from core.errors import DatasetError
from core.field_store import ReflectanceField
from processing.field_layout import field_layout
from processing.panorama import read_panorama
from processing.sample_models import SampleModels, fit_sample_models
from sim.field import field_cameras, simulate_field
from sim.skies import procedural_sky

POINTS, SIZE = 2000, 64
#: Points of the 200-light field (800 slabs).
DENSE_POINTS = 1200


def _field(
    root: Path, scene: str, cameras: int, lights: int, points: int = POINTS
) -> ReflectanceField:
    path = root / f"{scene}-{cameras}-{lights}.zarr"
    simulate_field(path, scene, lights=lights, cameras=field_cameras(cameras, width=SIZE,
                   height=SIZE), points=points)  # fmt: skip
    return ReflectanceField.open(path)


@pytest.fixture(scope="module")
def root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("stability")


@pytest.fixture(scope="module")
def glossy(root: Path) -> tuple[ReflectanceField, SampleModels]:
    field = _field(root, "glossy-sphere", 12, 30)
    return field, fit_sample_models(field)


@pytest.fixture(scope="module")
def matte(root: Path) -> tuple[ReflectanceField, SampleModels]:
    field = _field(root, "diffuse-sphere", 12, 30)
    return field, fit_sample_models(field)


@pytest.fixture(scope="module")
def sun() -> NDArray[np.float32]:
    return procedural_sky(64, sun_share=0.9, sun_inclination_deg=40.0)


@pytest.fixture(scope="module")
def courtyard(courtyard_path: Path) -> NDArray[np.float32]:
    return read_panorama(courtyard_path).rgb


def _row(rows: list[dict[str, Any]], method: str) -> dict[str, Any]:
    return next(r for r in rows if r["method"] == method)


def _middle(field: ReflectanceField) -> PinholeCamera:
    return field.cameras[len(field.cameras) // 2]


def test_a_sun_over_few_lights_is_flagged(
    root: Path, matte: tuple[ReflectanceField, SampleModels], sun: NDArray[np.float32]
) -> None:
    sparse = _field(root, "diffuse-sphere", 12, 10)
    failing = _row(measure(sparse, "diffuse-sphere", sun, _middle(sparse), points=POINTS),
                   "best interpolation")  # fmt: skip
    field, models = matte
    benign = _row(
        measure(field, "diffuse-sphere", sun, _middle(field), models=models, points=POINTS),
        "best interpolation",
    )
    assert failing["relative_rmse"] > 0.08 and "sun-sparse-lights" in failing["warnings"]
    assert benign["relative_rmse"] < 0.05 and "sun-sparse-lights" not in benign["warnings"]


def test_a_suns_highlight_ghosts_on_a_sparse_field(
    root: Path, glossy: tuple[ReflectanceField, SampleModels], sun: NDArray[np.float32]
) -> None:
    field, models = glossy
    rows = measure(field, "glossy-sphere", sun, _middle(field), models=models, points=POINTS)
    failing = _row(rows, "best interpolation")
    assert failing["relative_rmse"] > 0.1 and "sun-ghosting" in failing["warnings"]
    fitted = _row(rows, "models")  # the fitted lobe follows the sun: no warning
    assert fitted["relative_rmse"] < 0.02 and fitted["warnings"] == []
    # Dense in lights, few cameras and points (the lights are what this case is about).
    dense = _field(root, "glossy-sphere", 4, 200, points=DENSE_POINTS)
    fit = fit_sample_models(dense)
    view = _middle(dense)
    rows = measure(dense, "glossy-sphere", sun, view, models=fit, points=DENSE_POINTS)
    benign, paper = _row(rows, "best interpolation"), _row(rows, "paper")
    assert benign["relative_rmse"] < 0.06 and "sun-ghosting" not in benign["warnings"]
    # The paper's 3-nearest cosine interpolation ghosts the sun at any density.
    assert paper["relative_rmse"] > 0.2 and "sun-ghosting" in paper["warnings"]
    off = replace(view, azimuth_deg=view.azimuth_deg + 6.0)
    between = _row(measure(dense, "glossy-sphere", sun, off, models=fit, points=DENSE_POINTS),
                   "best interpolation")  # fmt: skip
    assert between["relative_rmse"] > 0.12 and "sun-ghosting" in between["warnings"]


def test_views_from_below_the_cameras_are_flagged(
    glossy: tuple[ReflectanceField, SampleModels], courtyard: NDArray[np.float32]
) -> None:
    field, models = glossy
    below = PinholeCamera(20.0, 120.0, 4.0, 40.0, SIZE, SIZE)
    rows = measure(field, "glossy-sphere", courtyard, below, models=models, points=POINTS)
    failing, fitted = _row(rows, "best interpolation"), _row(rows, "models")
    assert failing["relative_rmse"] > 0.3 and "view-outside" in failing["warnings"]
    assert fitted["relative_rmse"] < 0.1 and fitted["warnings"] == []


def test_grazing_views_are_flagged(
    glossy: tuple[ReflectanceField, SampleModels], sun: NDArray[np.float32]
) -> None:
    field, models = glossy
    no_sun = procedural_sky(64, sun_share=0.0)
    errors = {}
    for inclination in (85.0, 50.0):
        view = PinholeCamera(20.0, inclination, 4.0, 40.0, SIZE, SIZE)
        row = _row(measure(field, "glossy-sphere", no_sun, view, models=models, points=POINTS),
                   "best interpolation")  # fmt: skip
        errors[inclination] = row["relative_rmse"]
        assert ("grazing-view" in row["warnings"]) == (inclination == 85.0)
    assert errors[85.0] > 0.12 and errors[50.0] < 0.1


def test_an_ldr_panorama_is_flagged(
    matte: tuple[ReflectanceField, SampleModels], sun: NDArray[np.float32]
) -> None:
    field, models = matte
    view = _middle(field)
    ldr = measure(field, "diffuse-sphere", energy_matched_ldr(sun), view, truth_rgb=sun,
                  models=models, points=POINTS)  # fmt: skip
    hdr = measure(field, "diffuse-sphere", sun, view, models=models, points=POINTS)
    for row in ldr:  # the sun is gone whatever the method
        assert row["relative_rmse"] > 0.3 and "clipped-panorama" in row["warnings"]
    fitted = _row(hdr, "models")
    assert fitted["relative_rmse"] < 0.01 and fitted["warnings"] == []


def test_a_saturated_capture_is_flagged(
    glossy: tuple[ReflectanceField, SampleModels], courtyard: NDArray[np.float32]
) -> None:
    field, _ = glossy
    for level, fires in ((3.0, True), (0.8, False)):
        rows = measure(sensor_field(field, level), "glossy-sphere", courtyard, _middle(field),
                       points=POINTS)  # fmt: skip
        fitted = _row(rows, "models")
        assert ("saturated-capture" in fitted["warnings"]) == fires
        if fires:
            assert fitted["relative_rmse"] > 0.1
        else:
            assert fitted["relative_rmse"] < 0.05


def test_a_noisy_capture_is_flagged(
    matte: tuple[ReflectanceField, SampleModels], sun: NDArray[np.float32]
) -> None:
    field, _ = matte
    for level, fires in ((0.002, True), (0.8, False)):
        rows = measure(sensor_field(field, level), "diffuse-sphere", sun, _middle(field),
                       points=POINTS)  # fmt: skip
        linear, fitted = _row(rows, "best interpolation"), _row(rows, "models")
        assert ("noisy-capture" in linear["warnings"]) == fires
        assert (linear["relative_rmse"] > 0.08) == fires
        assert (linear["relative_rmse"] < 0.05) != fires
        # The models average the noise away: nothing to warn about.
        assert fitted["relative_rmse"] < 0.03 and "noisy-capture" not in fitted["warnings"]


def test_an_empty_camera_is_flagged(
    glossy: tuple[ReflectanceField, SampleModels], courtyard: NDArray[np.float32]
) -> None:
    field, models = glossy
    radiance = field.load().astype(np.float32)
    radiance[5] = 0.0  # the slabs of camera 5 never written
    damaged = measure(in_memory(field, radiance), "glossy-sphere", courtyard, field.cameras[5],
                      points=POINTS)  # fmt: skip
    complete = measure(field, "glossy-sphere", courtyard, field.cameras[5], models=models,
                       points=POINTS)  # fmt: skip
    for method, worst in (("best interpolation", 0.5), ("models", 0.2)):
        row = _row(damaged, method)
        assert row["relative_rmse"] > worst and "empty-camera" in row["warnings"]
    fitted = _row(complete, "models")
    assert fitted["relative_rmse"] < 0.02 and fitted["warnings"] == []


def test_a_missing_camera_pose_is_refused_by_name(tmp_path: Path) -> None:
    dataset = Dataset.create(tmp_path / "d", rig_config={"camera": {}}, plan={"kind": "test"})
    pose = {"camera_azimuth_deg": 0.0, "camera_inclination_deg": 45.0,
            "light_azimuth_deg": 90.0, "light_inclination_deg": 30.0}  # fmt: skip
    for index, measured in enumerate((pose, {"light_azimuth_deg": 90.0})):
        dataset.write_image(f"light_c{index}.png", b"x", key=ImageKey("light", index, 0, 0),
                            exposure_ms=10.0, commanded_pose=pose,
                            measured_pose=measured)  # fmt: skip
    with pytest.raises(DatasetError, match=r"light_c1\.png: the measured pose has no camera_az"):
        field_layout(dataset, camera=RigCamera(4.0, 40.0, 64, 64))

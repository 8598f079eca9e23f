from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from capture.dataset import Dataset, ImageKey
from capture.lp_export import export_lp
from core.camera_model import PinholeCamera, rig_to_camera
from core.directions import direction_from_angles_deg
from core.errors import DatasetError, InputError
from core.lp_format import read_lp

CAMERAS = [(0.0, 0.0), (30.0, 60.0), (250.0, 90.0)]  # (azimuth, inclination) degrees
LIGHTS = [(0.0, 10.0), (45.0, 40.0), (170.0, 75.0), (300.0, 89.0), (90.0, 0.0)]


def _pose(camera: tuple[float, float], light: tuple[float, float]) -> dict[str, float]:
    return {
        "camera_azimuth_deg": camera[0],
        "camera_inclination_deg": camera[1],
        "light_azimuth_deg": light[0],
        "light_inclination_deg": light[1],
        "turntable_deg": 15.0,
    }


def _dataset(path: Path, exposures: int = 1) -> Dataset:
    dataset = Dataset.create(path, rig_config={}, plan={})
    for c, camera in enumerate(CAMERAS):
        dark = ImageKey("dark", c, None, 0)
        pose = _pose(camera, (0.0, 0.0))
        dataset.write_image(
            f"{dark.stem()}.dng",
            b"d",
            key=dark,
            exposure_ms=1,
            commanded_pose=pose,
            measured_pose=pose,
        )
        # Lights in reverse order: the export orders lines by light index.
        for t, light in reversed(list(enumerate(LIGHTS))):
            for e in range(exposures):
                key = ImageKey("light", c, t, e)
                measured = _pose((camera[0] + 0.1, camera[1]), (light[0], light[1] + 0.2))
                dataset.write_image(
                    f"{key.stem()}.dng",
                    key.stem().encode(),
                    key=key,
                    exposure_ms=10.0 * 4**e,
                    commanded_pose=_pose(camera, light),
                    measured_pose=measured,
                )
    return dataset


def test_export_agrees_with_the_rti_reader(tmp_path: Path) -> None:
    dataset = _dataset(tmp_path / "ds")
    out = tmp_path / "lp"
    written = export_lp(dataset, out)
    assert [path.name for path in written] == ["camera_000.lp", "camera_001.lp", "camera_002.lp"]
    for c, path in enumerate(written):
        read = read_lp(path)
        records = [dataset.get(ImageKey("light", c, t, 0)) for t in range(len(LIGHTS))]
        assert all(record is not None for record in records)
        # Names are relative to the .lp file's folder and lead to the dataset's images.
        assert [(out / name).resolve() for name in read.files] == [
            dataset.image_path(record).resolve() for record in records if record is not None
        ]
        measured = [r.measured_pose for r in records if r is not None]
        expected = np.stack(
            [
                rig_to_camera(
                    direction_from_angles_deg(p["light_azimuth_deg"], p["light_inclination_deg"]),
                    PinholeCamera(p["camera_azimuth_deg"], p["camera_inclination_deg"]),
                )
                for p in measured
            ]
        )
        np.testing.assert_allclose(read.directions, expected, atol=1e-12)


def test_commanded_pose_and_exposure_brackets(tmp_path: Path) -> None:
    dataset = _dataset(tmp_path / "ds", exposures=2)
    written = export_lp(dataset, tmp_path / "lp", pose="commanded")
    assert [path.name for path in written][:2] == [
        "camera_000_exposure_00.lp",
        "camera_000_exposure_01.lp",
    ]
    assert len(written) == 2 * len(CAMERAS)
    read = read_lp(written[3])  # camera 1, exposure 1
    assert read.files[0].endswith("light_c001_l000_e1.dng")
    camera = PinholeCamera(*CAMERAS[1])
    expected = rig_to_camera(direction_from_angles_deg(*np.transpose(LIGHTS)), camera)
    np.testing.assert_allclose(read.directions, expected, atol=1e-12)


def test_bad_poses_and_empty_datasets(tmp_path: Path) -> None:
    dataset = Dataset.create(tmp_path / "ds", rig_config={}, plan={})
    with pytest.raises(InputError, match="no light images"):
        export_lp(dataset, tmp_path / "lp")
    key = ImageKey("light", 0, 0, 0)
    dataset.write_image(
        "a.png",
        b"a",
        key=key,
        exposure_ms=1,
        commanded_pose={"camera_azimuth_deg": 0.0},
        measured_pose=_pose((0.0, 200.0), (0.0, 0.0)),
    )
    with pytest.raises(DatasetError, match=r"images/a.png.*inclination in \[0, 180\]"):
        export_lp(dataset, tmp_path / "lp")
    with pytest.raises(DatasetError, match="commanded pose has no camera_inclination_deg"):
        export_lp(dataset, tmp_path / "lp", pose="commanded")
    with pytest.raises(InputError, match="'measured' or 'commanded'"):
        export_lp(dataset, tmp_path / "lp", pose="planned")  # type: ignore[arg-type]
    assert not (tmp_path / "lp").exists() or not any((tmp_path / "lp").iterdir())

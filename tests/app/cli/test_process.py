"""``rig process``: a simulated capture needs no flags; other captures say what they lack."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

from app.cli.process import add_process
from capture.dataset import Dataset, ImageKey
from core.errors import DatasetError, InputError
from core.field_store import ReflectanceField
from core.image_io import write_linear16_tiff
from sim.scenes import build_scene
from tests.processing.test_field_builder import SIZE, _build, make_capture


def run(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="rig")
    add_process(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    status: int = args.handler(args)
    return status


def test_a_simulated_capture_needs_no_flags(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capture = make_capture(tmp_path, points=2_000)
    assert run(["process", str(capture.path), "-o", str(tmp_path / "cli.zarr")]) == 0
    out = capsys.readouterr().out
    assert "4 cameras x 6 lights x 2000 points from 24 exposures (4 dark frames)" in out
    assert "peak RSS" in out
    _build(capture, tmp_path / "direct.zarr")
    cli, direct = (
        ReflectanceField.open(tmp_path / "cli.zarr"),
        ReflectanceField.open(tmp_path / "direct.zarr"),
    )
    np.testing.assert_array_equal(cli.load(), direct.load())
    np.testing.assert_array_equal(cli.visibility, direct.visibility)
    assert cli.provenance["scene"] == "glossy-sphere" and cli.provenance["tool"] == "rig process"

    # The same capture with the points from a file and the scale given explicitly.
    samples = build_scene("glossy-sphere", 2_000)
    np.savez(
        tmp_path / "cloud.npz",
        points=samples.points,
        normals=samples.normals,
        spacing=samples.spacing,
    )
    argv = ["process", str(capture.path), "-o", str(tmp_path / "npz.zarr")]
    argv += ["--points", str(tmp_path / "cloud.npz"), "--radiance-scale", "1.0"]
    assert run(argv) == 0
    scaled = ReflectanceField.open(tmp_path / "npz.zarr").load()
    np.testing.assert_allclose(scaled, direct.load() * capture.radiance_scale, rtol=1e-5, atol=1e-9)


def _real_capture(tmp_path: Path) -> Path:
    """A dataset from a (pretend) UVC camera: one black 16-bit image, no scene to rebuild."""
    dataset = Dataset.create(
        tmp_path / "real", rig_config={"camera": {"backend": "opencv"}}, plan={}
    )
    pose = {
        "camera_azimuth_deg": 0.0,
        "camera_inclination_deg": 60.0,
        "light_azimuth_deg": 90.0,
        "light_inclination_deg": 45.0,
    }
    pixels = np.zeros((SIZE, SIZE, 3), np.uint16)
    dataset.write_image(
        "light_c0_l0.tif",
        lambda path: write_linear16_tiff(path, pixels),
        key=ImageKey("light", 0, 0, 0),
        exposure_ms=10.0,
        commanded_pose=pose,
        measured_pose=pose,
    )
    dataset.save()
    return dataset.path


def test_other_captures_say_what_they_lack(tmp_path: Path) -> None:
    path = _real_capture(tmp_path)
    out = str(tmp_path / "field.zarr")
    with pytest.raises(InputError, match="not a simulated capture; give the object's points"):
        run(["process", str(path), "-o", out])
    samples = build_scene("diffuse-sphere", 500)
    np.savez(tmp_path / "cloud.npz", points=samples.points, normals=samples.normals)
    cloud = ["--points", str(tmp_path / "cloud.npz")]
    with pytest.raises(InputError, match="no camera model; give --camera-distance and --fov"):
        run(["process", str(path), "-o", out, *cloud])
    # With the camera given, the size comes from the images; a black image is all zeros.
    camera = ["--camera-distance", "4", "--fov", "40"]
    assert run(["process", str(path), "-o", out, *cloud, *camera]) == 0
    field = ReflectanceField.open(out)
    assert field.shape == (1, 1, 500) and field.cameras[0].width == SIZE
    assert field.visibility.any() and not field.load().any()


def test_process_refuses_what_verify_refuses(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from processing.process_dataset import verify_for_processing

    capture = make_capture(tmp_path, points=500)
    dataset = Dataset.open(capture.path)
    victim = next(r for r in dataset.records if r.kind == "light")
    path = dataset.image_path(victim)
    path.write_bytes(path.read_bytes()[:-10] + b"0123456789")  # same size, other bytes
    with pytest.raises(DatasetError, match=rf"image files are corrupt \({victim.file}"):
        verify_for_processing(Dataset.open(capture.path), allow_missing=True)
    with pytest.raises(DatasetError, match="corrupt"):
        run(["process", str(capture.path), "-o", str(tmp_path / "f.zarr")])
    assert not (tmp_path / "f.zarr").exists()


def test_a_deleted_image_is_left_out_only_when_allowed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capture = make_capture(tmp_path, points=500)
    dataset = Dataset.open(capture.path)
    victim = next(r for r in dataset.records if r.kind == "light")
    dataset.image_path(victim).unlink()
    with pytest.raises(DatasetError, match=rf"1 planned images are missing.*{victim.file}"):
        run(["process", str(capture.path), "-o", str(tmp_path / "f.zarr")])
    argv = ["process", str(capture.path), "-o", str(tmp_path / "f.zarr"), "--allow-missing"]
    assert run(argv) == 0
    assert f"1 planned images left out ({victim.file})" in capsys.readouterr().out

from __future__ import annotations

import hashlib
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from PIL import Image

from core.camera_model import PinholeCamera, camera_to_rig, rig_to_camera
from core.colour import srgb_to_linear
from core.errors import DatasetError, InputError
from core.field_store import ReflectanceField
from core.image_io import read_linear, write_exr, write_linear16_tiff
from core.lp_format import read_intensity_sidecar, read_lp
from core.sample_data import rti_capture_path
from processing.rti import export_lp, import_rti, open_field_or_rti, rti_camera

LOEWENKOPF_LP = rti_capture_path()
LOEWENKOPF = LOEWENKOPF_LP.parent


@pytest.fixture(scope="module")
def loewenkopf(tmp_path_factory: pytest.TempPathFactory) -> ReflectanceField:
    store = tmp_path_factory.mktemp("rti") / "loewenkopf.zarr"
    return import_rti(LOEWENKOPF_LP, store)


def _write_png(path: Path, image: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), image)


def _small_capture(folder: Path, sizes: list[tuple[int, int]], grey: bool = False) -> Path:
    """PNG images of the given (height, width) under folder/img/ and an .lp file listing them."""
    rng = np.random.default_rng(7)
    lines = [str(len(sizes))]
    for index, (height, width) in enumerate(sizes):
        shape = (height, width) if grey else (height, width, 3)
        _write_png(folder / "img" / f"{index}.png", rng.integers(0, 256, shape, dtype=np.uint8))
        lines.append(f"img/{index}.png {0.1 * index} -0.2 1.0")
    lp = folder / "small.lp"
    lp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return lp


# --- frames --------------------------------------------------------------------------------

_CAMERAS = st.builds(
    PinholeCamera,
    azimuth_deg=st.floats(0.0, 360.0, exclude_max=True),
    # Within ~0.01 degrees of the poles (not at them) camera.axes() is orthonormal only to
    # ~1e-16 / sin(inclination), up to 2e-9: the up vector is normalised from a tiny one.
    inclination_deg=st.one_of(st.sampled_from([0.0, 180.0]), st.floats(0.01, 179.99)),
    distance=st.floats(1.0, 20.0),
    fov_deg=st.floats(5.0, 120.0),
    width=st.integers(16, 256),
    height=st.integers(16, 256),
)


def test_the_rti_camera_looks_straight_down_with_light_z_as_rig_z() -> None:
    camera = rti_camera(64, 43)
    assert (camera.width, camera.height) == (64, 43)
    np.testing.assert_allclose(camera_to_rig([0.0, 0.0, 1.0], camera), [0.0, 0.0, 1.0], atol=0)
    np.testing.assert_allclose(camera.direction, [0.0, 0.0, 1.0], atol=1e-15)
    # Image right is rig +y and image up is rig -x (the limit from azimuth 0 looking down).
    np.testing.assert_allclose(
        camera_to_rig(np.eye(3), camera), [[0, 1, 0], [-1, 0, 0], [0, 0, 1]], atol=1e-15
    )


@settings(max_examples=40)
@given(camera=_CAMERAS, vectors=arrays(np.float64, (5, 3), elements=st.floats(-1, 1)))
def test_camera_and_rig_frames_are_inverse_rotations(
    camera: PinholeCamera, vectors: np.ndarray
) -> None:
    rig = camera_to_rig(vectors, camera)
    np.testing.assert_allclose(rig_to_camera(rig, camera), vectors, atol=1e-12)
    # Lengths kept (absolutely: squares of values near 1e-162 underflow to subnormals).
    np.testing.assert_allclose(
        np.linalg.norm(rig, axis=1), np.linalg.norm(vectors, axis=1), rtol=1e-7, atol=1e-12
    )
    np.testing.assert_allclose(camera_to_rig([0, 0, 1], camera), camera.direction, atol=1e-12)
    assert camera_to_rig(vectors[0], camera).shape == (3,)


@settings(max_examples=40)
@given(
    camera=_CAMERAS,
    x=st.floats(0.05, 1.0),
    y=st.floats(0.05, 1.0),
    z=st.floats(0.1, 1.0),
)
def test_image_right_and_up_in_the_camera_frame_are_right_and_up_in_the_picture(
    camera: PinholeCamera, x: float, y: float, z: float
) -> None:
    scale = 0.01 * camera.distance  # a point near the object, well inside the view
    for direction, side in (([x, 0.0, z], "right"), ([0.0, y, z], "up")):
        point = scale * camera_to_rig(direction, camera)
        col, row, depth = camera.project(point[None])
        assert depth[0] > 0
        if side == "right":
            assert col[0] > camera.width / 2
            assert row[0] == pytest.approx(camera.height / 2, abs=1e-6)
        else:
            assert row[0] < camera.height / 2
            assert col[0] == pytest.approx(camera.width / 2, abs=1e-6)


def test_frame_functions_refuse_non_vectors() -> None:
    with pytest.raises(InputError, match=r"shape \(\.\.\., 3\)"):
        camera_to_rig([1.0, 2.0], rti_camera(8, 8))
    with pytest.raises(InputError, match=r"shape \(\.\.\., 3\)"):
        rig_to_camera(np.zeros((4, 2)), rti_camera(8, 8))


# --- import and export ---------------------------------------------------------------------


def test_the_real_capture_imports_as_a_pixel_field(loewenkopf: ReflectanceField) -> None:
    field = ReflectanceField.open(loewenkopf.path)
    assert field.image_shape == (43, 64)
    assert field.shape == (1, 240, 43 * 64)
    # 8-bit JPEGs: float16 by default (every level keeps a value of its own)
    assert field.sample_kind == "pixels" and field.dtype == np.float16
    assert field.points is None and field.normals is None
    assert field.visibility.shape == (1, 43 * 64) and field.visibility.all()
    np.testing.assert_allclose(np.linalg.norm(field.light_directions, axis=1), 1.0, atol=1e-12)
    assert (field.light_directions[:, 2] > 0).all()
    lights = read_lp(LOEWENKOPF_LP)
    np.testing.assert_allclose(field.light_directions[:, 2], lights.directions[:, 2], atol=1e-15)
    camera = field.cameras[0]
    assert camera == rti_camera(64, 43)
    np.testing.assert_allclose(field.camera_directions, [[0.0, 0.0, 1.0]], atol=1e-15)
    assert field.light_model["type"] == "directional"
    assert field.provenance["images"] == 240
    assert field.provenance["lp"] == str(LOEWENKOPF_LP.resolve())
    assert field.provenance["camera_intrinsics"]["nominal"] is True
    slab = field.camera_slab(0)
    for t in (0, 117, 239):
        image = read_linear(LOEWENKOPF / lights.files[t])
        np.testing.assert_array_equal(slab[t].reshape(43, 64, 3), image.astype(np.float16))
    assert not list(loewenkopf.path.parent.glob(".*partial*"))


def test_real_normals_are_integrable_only_in_the_stated_image_frame(
    loewenkopf: ReflectanceField,
) -> None:
    """Lambertian photometric stereo on the imported field: the normals' slopes, mapped to the
    image with the camera's axes, form a gradient field (small curl); with the image's x or y
    axis flipped they do not. This checks the .lp frame, camera_to_rig and the pixel order."""
    height, width = 43, 64
    luminance = loewenkopf.camera_slab(0).astype(np.float64).mean(axis=2)  # (T, P)
    scaled, *_ = np.linalg.lstsq(loewenkopf.light_directions, luminance, rcond=None)
    camera_normals = rig_to_camera(scaled.T, loewenkopf.cameras[0]).reshape(height, width, 3)
    assert camera_normals[..., 2].mean() > 0  # the relief faces the camera

    def curl(flip_x: float, flip_y: float) -> float:
        nx, ny, nz = np.moveaxis(camera_normals, -1, 0)
        dz_dcol = -flip_x * nx / nz
        dz_drow = flip_y * ny / nz  # rows grow downward, against camera y
        rotation = np.diff(dz_dcol, axis=0)[:, :-1] - np.diff(dz_drow, axis=1)[:-1, :]
        return float(np.median(np.abs(rotation)))

    stated = curl(1.0, 1.0)
    assert stated < 0.8 * curl(-1.0, 1.0)
    assert stated < 0.8 * curl(1.0, -1.0)


def test_export_lp_gives_back_the_real_file(loewenkopf: ReflectanceField, tmp_path: Path) -> None:
    original = read_lp(LOEWENKOPF_LP)
    written = export_lp(loewenkopf, 0, tmp_path / "out" / "dirs.lp", original.files)
    read = read_lp(tmp_path / "out" / "dirs.lp")
    assert read.files == written.files == original.files
    np.testing.assert_allclose(read.directions, original.directions, rtol=0, atol=1e-15)
    export_lp(loewenkopf.path, 0, tmp_path / "again.lp", original.files)
    assert (tmp_path / "again.lp").read_bytes() == (tmp_path / "out" / "dirs.lp").read_bytes()
    with pytest.raises(InputError, match=r"camera index 1 outside 0\.\.0"):
        export_lp(loewenkopf, 1, tmp_path / "x.lp", original.files)
    with pytest.raises(InputError, match="2 image names for the 240 lights"):
        export_lp(loewenkopf, 0, tmp_path / "x.lp", ["a", "b"])


def test_a_missing_image_is_refused_with_its_line(tmp_path: Path) -> None:
    lp = _small_capture(tmp_path, [(4, 6)] * 3)
    (tmp_path / "img" / "1.png").unlink()
    with pytest.raises(DatasetError, match=r"small\.lp, line 3: image 'img/1\.png' not found"):
        import_rti(lp, tmp_path / "f.zarr")
    assert not (tmp_path / "f.zarr").exists()


def test_mixed_image_sizes_are_refused_and_leave_no_store(tmp_path: Path) -> None:
    lp = _small_capture(tmp_path, [(4, 6), (4, 6), (6, 4), (4, 6)])
    with pytest.raises(
        DatasetError, match=r"line 4: image 'img/2\.png' is 4x6 pixels, the first .* is 6x4"
    ):
        import_rti(lp, tmp_path / "f.zarr")
    assert not (tmp_path / "f.zarr").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["img", "small.lp"]


def test_a_corrupt_image_is_refused_with_its_line(tmp_path: Path) -> None:
    lp = _small_capture(tmp_path, [(4, 6)] * 2)
    (tmp_path / "img" / "1.png").write_bytes(b"not a png")
    with pytest.raises(DatasetError, match=r"line 3: .*1\.png.*cannot decode"):
        import_rti(lp, tmp_path / "f.zarr")


def test_grey_images_become_rgb_and_an_old_store_is_replaced(tmp_path: Path) -> None:
    lp = _small_capture(tmp_path, [(4, 6)] * 3, grey=True)
    store = tmp_path / "f.zarr"
    import_rti(_small_capture(tmp_path / "other", [(2, 2)]), store)
    field = import_rti(lp, store, dtype="float16")
    assert field.shape == (1, 3, 24) and field.image_shape == (4, 6)
    assert field.dtype == np.float16
    slab = field.camera_slab(0).astype(np.float32)
    np.testing.assert_array_equal(slab[..., 0], slab[..., 1])
    np.testing.assert_array_equal(slab[..., 0], slab[..., 2])
    expected = read_linear(tmp_path / "img" / "2.png")
    assert expected.shape == (4, 6)  # read_linear gives grey as (H, W)
    np.testing.assert_allclose(slab[2, :, 0].reshape(4, 6), expected, rtol=1e-3, atol=1e-4)
    camera = field.cameras[0]
    expected_lights = camera_to_rig(read_lp(lp).directions, camera)
    np.testing.assert_allclose(field.light_directions, expected_lights, atol=1e-15)


def test_import_refuses_bad_arguments(tmp_path: Path) -> None:
    lp = _small_capture(tmp_path, [(4, 6)] * 2)
    with pytest.raises(InputError, match="float16 or float32"):
        import_rti(lp, tmp_path / "f.zarr", dtype="float64")
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "notes.txt").write_text("mine", encoding="utf-8")
    with pytest.raises(InputError, match="exists and is not a field store"):
        import_rti(lp, tmp_path / "taken")
    assert (tmp_path / "taken" / "notes.txt").read_text(encoding="utf-8") == "mine"


# --- transfer, masks, intensities, formats ---------------------------------------------------


def _capture(
    folder: Path,
    images: list[np.ndarray],
    *,
    suffix: str = ".png",
    extra: list[str] | None = None,
    name: str = "cap",
) -> Path:
    """``images`` (RGB order; uint8, uint16 or float32) written under folder/img/ by OpenCV (EXR
    by core.image_io), and ``name``.lp listing them, with ``extra`` appended to each line."""
    lines = [str(len(images))]
    for index, image in enumerate(images):
        path = folder / "img" / f"{index}{suffix}"
        path.parent.mkdir(parents=True, exist_ok=True)
        if suffix == ".exr":
            write_exr(path, image)
        else:
            assert cv2.imwrite(str(path), image[:, :, ::-1] if image.ndim == 3 else image)
        tail = f" {extra[index]}" if extra else ""
        lines.append(f"img/{index}{suffix} {0.1 * index} 0.2 1.0{tail}")
    lp = folder / f"{name}.lp"
    lp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return lp


def _flat(
    value: float | int, dtype: type[np.generic], shape: tuple[int, int] = (4, 6)
) -> np.ndarray:
    return np.full((*shape, 3), value, dtype=dtype)


def _images(field: ReflectanceField) -> np.ndarray:
    """The field's radiance as images (T, H, W, 3), float64."""
    height, width = field.image_shape or (0, 0)
    return field.camera_slab(0).astype(np.float64).reshape(-1, height, width, 3)


def test_a_16_bit_png_is_linear_by_default_and_srgb_when_asked(tmp_path: Path) -> None:
    lp = _capture(tmp_path, [_flat(13107, np.uint16), _flat(65535, np.uint16)])  # 0.2 and 1.0
    field = import_rti(lp, tmp_path / "auto.zarr")
    images = _images(field)
    np.testing.assert_allclose(images[0], 0.2, rtol=0, atol=1 / 65535)
    np.testing.assert_allclose(images[1], 1.0, rtol=0, atol=1 / 65535)
    record = field.provenance["transfer"]
    assert record["requested"] == "auto" and record["applied"] == "linear"
    assert record["bit_depth"] == "16-bit"
    assert "16-bit images decoded as linear" in field.provenance["assumed"]
    srgb = import_rti(lp, tmp_path / "srgb.zarr", transfer="srgb")
    np.testing.assert_allclose(_images(srgb)[0], 0.0331048, rtol=1e-5)  # what 0.2 becomes
    assert srgb.provenance["transfer"]["applied"] == "srgb"
    assert "transfer 'srgb' as asked" in srgb.provenance["assumed"]


def test_a_16_bit_tiff_is_linear_by_default(tmp_path: Path) -> None:
    (tmp_path / "img").mkdir()
    write_linear16_tiff(tmp_path / "img" / "a.tif", _flat(13107, np.uint16))
    (tmp_path / "t.lp").write_text("1\nimg/a.tif 0 0 1\n", encoding="utf-8")
    field = import_rti(tmp_path / "t.lp", tmp_path / "f.zarr")
    np.testing.assert_allclose(_images(field), 0.2, rtol=0, atol=1 / 65535)


@pytest.mark.parametrize("transfer", ["srgb", "linear"])
def test_8_bit_levels_are_stored_as_float16_by_default_and_lose_nothing(
    tmp_path: Path, transfer: str
) -> None:
    from core.colour import linear_to_srgb

    levels = np.arange(256, dtype=np.uint8).reshape(16, 16)
    picture = np.stack([levels, levels.T, 255 - levels], axis=2)
    lp = _capture(tmp_path, [picture, picture[::-1]])
    field = import_rti(lp, tmp_path / "f.zarr", transfer=transfer)  # type: ignore[arg-type]
    assert field.dtype == np.float16
    assert "stored as float16 (8-bit levels" in field.provenance["assumed"]
    stored = _images(field)
    # Each level is the float16 of its float32 value, and all 256 are told apart: decoding
    # them back gives every level as it was.
    wide = import_rti(lp, tmp_path / "g.zarr", transfer=transfer, dtype="float32")  # type: ignore[arg-type]
    assert wide.dtype == np.float32
    np.testing.assert_array_equal(stored, _images(wide).astype(np.float16))
    encoded = linear_to_srgb(stored.astype(np.float32)) if transfer == "srgb" else stored
    back = np.round(np.asarray(encoded) * 255.0)
    np.testing.assert_array_equal(back, np.stack([picture, picture[::-1]]).astype(np.float64))
    assert len(np.unique(stored[0, :, :, 0])) == 256


def test_16_bit_images_and_divided_images_stay_float32(tmp_path: Path) -> None:
    sixteen = _capture(tmp_path / "a", [_flat(13107, np.uint16)] * 3)
    assert import_rti(sixteen, tmp_path / "a.zarr").dtype == np.float32
    divided = _capture(tmp_path / "b", [_flat(100, np.uint8)] * 3, extra=["2", "0.5", "1"])
    field = import_rti(divided, tmp_path / "b.zarr")
    assert field.dtype == np.float32 and "stored as float32" in field.provenance["assumed"]
    asked = import_rti(divided, tmp_path / "c.zarr", dtype="float16")
    assert asked.dtype == np.float16


def test_an_image_that_fails_to_decode_ahead_is_named_and_leaves_no_store(
    tmp_path: Path,
) -> None:
    # Later images decode on a thread while earlier ones are written: the failure still names
    # the image's line, and the store is not made.
    images = [_flat(10 * t, np.uint8) for t in range(6)]
    lp = _capture(tmp_path, images)
    (tmp_path / "img" / "4.png").write_bytes(b"not a png")
    with pytest.raises(DatasetError, match=r"cap\.lp, line 6: .*4\.png"):
        import_rti(lp, tmp_path / "f.zarr")
    assert not (tmp_path / "f.zarr").exists()
    assert not list(tmp_path.glob(".f.zarr.*"))


@pytest.mark.parametrize("suffix", [".png", ".jpg"])
def test_8_bit_images_are_srgb_by_default_and_linear_when_asked(
    tmp_path: Path, suffix: str
) -> None:
    lp = _capture(tmp_path, [_flat(128, np.uint8)] * 2, suffix=suffix)
    field = import_rti(lp, tmp_path / "f.zarr", dtype="float32")
    # 128/255 encoded is 0.2158605 linear (a JPEG of a flat patch keeps the value exactly).
    np.testing.assert_allclose(_images(field), 0.2158605, rtol=1e-6)
    assert field.provenance["transfer"] == {
        "requested": "auto",
        "applied": "srgb",
        "bit_depth": "8-bit",
        "first_image": f"img/0{suffix}",
        "rule": "auto: 8-bit is sRGB, 16-bit and float are linear",
    }
    linear = import_rti(lp, tmp_path / "g.zarr", transfer="linear")
    np.testing.assert_array_equal(_images(linear), np.float16(128 / 255))  # auto: float16


def test_the_real_capture_records_what_it_assumed(loewenkopf: ReflectanceField) -> None:
    assert loewenkopf.provenance["transfer"]["applied"] == "srgb"
    assert loewenkopf.provenance["transfer"]["bit_depth"] == "8-bit"
    assert loewenkopf.provenance["mask"] is None and loewenkopf.provenance["intensities"] is None
    assert loewenkopf.provenance["assumed"] == (
        "rti dirs.lp: 240 8-bit images decoded as sRGB (auto: 8-bit is sRGB, 16-bit and float "
        "are linear; transfer 'srgb' or 'linear' overrides); mask: none, every pixel counts; "
        "intensities: none, the lights are taken as equal; below the horizon: blocked by the "
        "base (environment light from below is dropped); stored as float16 (8-bit levels: "
        "float16 keeps each one distinct, nothing is lost)"
    )
    assert loewenkopf.below_horizon == "blocked"


def test_float_images_are_taken_as_stored_whatever_the_transfer(tmp_path: Path) -> None:
    lp = _capture(tmp_path, [_flat(0.2, np.float32), _flat(3.5, np.float32)], suffix=".exr")
    field = import_rti(lp, tmp_path / "f.zarr", transfer="srgb")
    np.testing.assert_allclose(_images(field)[:, 0, 0], [[0.2] * 3, [3.5] * 3], rtol=1e-7)
    record = field.provenance["transfer"]
    assert record["bit_depth"] == "float" and record["applied"] == "linear"
    assert "transfer 'srgb' does not apply to floats" in field.provenance["assumed"]


def test_mixed_bit_depths_are_refused_naming_the_first_that_differs(tmp_path: Path) -> None:
    images = [_flat(10, np.uint8), _flat(10, np.uint8), _flat(10, np.uint16), _flat(10, np.uint8)]
    lp = _capture(tmp_path, images)
    with pytest.raises(
        DatasetError,
        match=r"cap\.lp, line 4: image 'img/2\.png' is 16-bit, the first \('img/0\.png'\) is "
        r"8-bit",
    ):
        import_rti(lp, tmp_path / "f.zarr")
    assert not (tmp_path / "f.zarr").exists()
    assert not list(tmp_path.glob(".*partial*"))


def test_the_import_prints_what_it_assumed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lp = _capture(tmp_path, [_flat(13107, np.uint16)] * 2)
    field = import_rti(lp, tmp_path / "f.zarr", print_assumed=True)
    err = capsys.readouterr().err
    assert err.splitlines()[0] == field.provenance["assumed"]
    assert field.provenance["assumed"].startswith("rti cap.lp: 2 16-bit images decoded as linear")
    import_rti(lp, tmp_path / "f.zarr")
    assert capsys.readouterr().err == ""


def test_a_bad_transfer_is_refused(tmp_path: Path) -> None:
    lp = _capture(tmp_path, [_flat(1, np.uint8)])
    with pytest.raises(
        InputError, match=r"transfer must be 'auto', 'srgb' or 'linear', got 'gamma'"
    ):
        import_rti(lp, tmp_path / "f.zarr", transfer="gamma")  # type: ignore[arg-type]


def _mask_picture(shape: tuple[int, int] = (4, 6)) -> np.ndarray:
    mask = np.zeros(shape, np.uint8)
    mask[1:3, 2:5] = 255
    mask[0, 0] = 1  # any non-zero value counts
    return mask


def test_a_mask_file_sets_the_visibility(tmp_path: Path) -> None:
    lp = _capture(tmp_path, [_flat(100, np.uint8)] * 3)
    mask = _mask_picture()
    assert cv2.imwrite(str(tmp_path / "object.png"), mask)
    field = import_rti(lp, tmp_path / "f.zarr", mask=tmp_path / "object.png")
    np.testing.assert_array_equal(field.visibility[0], mask.reshape(-1) > 0)
    record = field.provenance["mask"]
    assert record["file"] == str((tmp_path / "object.png").resolve())
    assert record["sha256"] == hashlib.sha256((tmp_path / "object.png").read_bytes()).hexdigest()
    assert record["found"] == "mask argument" and record["pixels"] == 7
    assert (
        "mask: " in field.provenance["assumed"] and "7 of 24 pixels" in field.provenance["assumed"]
    )
    # A colour mask counts a pixel when any channel is non-zero.
    colour = np.zeros((4, 6, 3), np.uint8)
    colour[2, 3, 1] = 9
    assert cv2.imwrite(str(tmp_path / "colour.png"), colour)
    field = import_rti(lp, tmp_path / "f.zarr", mask=tmp_path / "colour.png")
    assert np.flatnonzero(field.visibility[0]).tolist() == [2 * 6 + 3]


def test_a_mask_sidecar_is_found_and_an_explicit_mask_wins(tmp_path: Path) -> None:
    lp = _capture(tmp_path, [_flat(100, np.uint8)] * 2)
    generic = np.zeros((4, 6), np.uint8)
    generic[0] = 1
    assert cv2.imwrite(str(tmp_path / "mask.png"), generic)
    field = import_rti(lp, tmp_path / "f.zarr")
    np.testing.assert_array_equal(field.visibility[0], generic.reshape(-1) > 0)
    assert field.provenance["mask"]["found"] == "mask sidecar"
    assert field.provenance["mask"]["file"] == str((tmp_path / "mask.png").resolve())
    specific = _mask_picture()
    assert cv2.imwrite(str(tmp_path / "cap.mask.png"), specific)  # <lp stem>.mask.png first
    field = import_rti(lp, tmp_path / "f.zarr")
    np.testing.assert_array_equal(field.visibility[0], specific.reshape(-1) > 0)
    explicit = np.ones((4, 6), np.uint8)
    assert cv2.imwrite(str(tmp_path / "all.png"), explicit)
    field = import_rti(lp, tmp_path / "f.zarr", mask=tmp_path / "all.png")
    assert field.visibility.all() and field.provenance["mask"]["found"] == "mask argument"
    with open_field_or_rti(lp) as opened:  # the sidecar, through the opener too
        np.testing.assert_array_equal(opened.visibility[0], specific.reshape(-1) > 0)
    with open_field_or_rti(tmp_path, mask=tmp_path / "all.png", transfer="linear") as opened:
        assert opened.visibility.all()
        assert opened.provenance["transfer"]["applied"] == "linear"
        np.testing.assert_array_equal(_images(opened), np.float16(100 / 255))


def test_bad_masks_are_refused_and_leave_no_store(tmp_path: Path) -> None:
    lp = _capture(tmp_path, [_flat(100, np.uint8)] * 2)
    assert cv2.imwrite(str(tmp_path / "small.png"), _mask_picture((3, 6)))
    with pytest.raises(
        DatasetError,
        match=r"mask argument .*small\.png: 6x3 pixels, the images are 6x4 \(width x height\)",
    ):
        import_rti(lp, tmp_path / "f.zarr", mask=tmp_path / "small.png")
    assert cv2.imwrite(str(tmp_path / "cap.mask.png"), np.zeros((4, 6), np.uint8))
    with pytest.raises(DatasetError, match=r"mask sidecar .*cap\.mask\.png: every pixel is zero"):
        import_rti(lp, tmp_path / "f.zarr")
    (tmp_path / "cap.mask.png").write_bytes(b"")
    with pytest.raises(DatasetError, match=r"mask sidecar: .*cap\.mask\.png: the file is empty"):
        import_rti(lp, tmp_path / "f.zarr")
    with pytest.raises(DatasetError, match=r"mask argument: .*none\.png: no such file"):
        import_rti(lp, tmp_path / "f.zarr", mask=tmp_path / "none.png")
    assert not (tmp_path / "f.zarr").exists()


def test_a_store_refuses_import_options(loewenkopf: ReflectanceField, tmp_path: Path) -> None:
    with pytest.raises(InputError, match="applies to an RTI capture"):
        with open_field_or_rti(loewenkopf.path, mask=tmp_path / "m.png"):
            pass
    with open_field_or_rti(loewenkopf.path) as opened:
        assert opened.shape == loewenkopf.shape


def test_fifth_column_intensities_divide_the_images(tmp_path: Path) -> None:
    values = [13107, 26214, 39321]  # 0.2, 0.4, 0.6 linear
    lp = _capture(tmp_path, [_flat(v, np.uint16) for v in values], extra=["2", "0.5", "1"])
    field = import_rti(lp, tmp_path / "f.zarr")
    np.testing.assert_allclose(
        _images(field)[:, 0, 0, 0], [0.2 / 2, 0.4 / 0.5, 0.6 / 1], rtol=0, atol=1 / 65535
    )
    record = field.provenance["intensities"]
    assert record["source"] == "cap.lp fifth column" and record["values"] == [2.0, 0.5, 1.0]
    assert "intensities: cap.lp fifth column (0.5 to 2)" in field.provenance["assumed"]
    assert "divided" in field.light_model["note"]


def test_mixed_columns_are_refused_at_import_with_the_line(tmp_path: Path) -> None:
    lp = _capture(tmp_path, [_flat(1, np.uint8)] * 3, extra=["2", "", "1"])
    with pytest.raises(DatasetError, match=r"cap\.lp, line 3: 4 columns, but line 2 has 5"):
        import_rti(lp, tmp_path / "f.zarr")


def test_sidecar_intensities_divide_the_images(tmp_path: Path) -> None:
    lp = _capture(tmp_path, [_flat(0.8, np.float32)] * 3, suffix=".exr")
    (tmp_path / "cap.intensities").write_text(
        "# light intensities\r\nimg/2.exr 4\r\n\r\nimg/0.exr 2\r\nimg/1.exr\t0.25\r\n",
        encoding="utf-8",
    )
    field = import_rti(lp, tmp_path / "f.zarr")
    np.testing.assert_allclose(_images(field)[:, 0, 0, 0], [0.4, 3.2, 0.2], rtol=1e-7)
    record = field.provenance["intensities"]
    assert record["source"] == str((tmp_path / "cap.intensities").resolve())
    assert (
        record["sha256"] == hashlib.sha256((tmp_path / "cap.intensities").read_bytes()).hexdigest()
    )
    assert record["values"] == [2.0, 0.25, 4.0]
    lights = read_lp(lp)
    np.testing.assert_array_equal(
        read_intensity_sidecar(tmp_path / "cap.intensities", lights), [2.0, 0.25, 4.0]
    )
    (tmp_path / "cap.intensities").rename(tmp_path / "intensities.txt")  # the generic name
    field = import_rti(lp, tmp_path / "f.zarr")
    np.testing.assert_allclose(_images(field)[:, 0, 0, 0], [0.4, 3.2, 0.2], rtol=1e-7)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        (
            "img/0.png 1\nimg/1.png 1\n",
            r"lists 2 intensities for the 3 images of cap\.lp; "
            r"'img/2\.png' \(cap\.lp line 4\) has none",
        ),
        ("img/0.png 1\n", r"lists 1 intensities .* 'img/1\.png' .* has none, nor 1 more"),
        ("img/0.png 1\nimg/9.png 1\n", r"line 2: 'img/9\.png' is not an image of cap\.lp"),
        (
            "img/0.png 1\n\nimg/0.png 2\n",
            r"line 3: 'img/0\.png' already has an intensity on line 1",
        ),
        ("img/0.png\n", r"line 1: expected 'filename intensity'"),
        ("img/0.png 0\n", r"line 1: intensity '0' must be a positive finite number"),
        ("img/0.png one\n", r"line 1: intensity 'one' is not a number"),
    ],
)
def test_bad_intensity_sidecars_are_refused(tmp_path: Path, text: str, match: str) -> None:
    lp = _capture(tmp_path, [_flat(1, np.uint8)] * 3)
    (tmp_path / "cap.intensities").write_text(text, encoding="utf-8")
    with pytest.raises(DatasetError, match=match) as caught:
        import_rti(lp, tmp_path / "f.zarr")
    assert "cap.intensities" in str(caught.value)
    assert not (tmp_path / "f.zarr").exists()


def test_a_fifth_column_and_a_sidecar_together_are_refused(tmp_path: Path) -> None:
    lp = _capture(tmp_path, [_flat(1, np.uint8)] * 2, extra=["1", "2"])
    (tmp_path / "intensities.txt").write_text("img/0.png 1\nimg/1.png 2\n", encoding="utf-8")
    with pytest.raises(DatasetError, match=r"cap\.lp: gives intensities in a fifth column and "):
        import_rti(lp, tmp_path / "f.zarr")


def test_tga_and_bmp_captures_import(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    pictures = [rng.integers(0, 256, (4, 6, 3), dtype=np.uint8) for _ in range(2)]
    (tmp_path / "img").mkdir()
    # OpenCV has no TGA writer: Pillow writes it (RLE); OpenCV writes the BMP.
    Image.fromarray(pictures[0]).save(tmp_path / "img" / "a.tga", compression="tga_rle")
    assert cv2.imwrite(str(tmp_path / "img" / "b.bmp"), pictures[1][:, :, ::-1])
    (tmp_path / "t.lp").write_text("2\nimg/a.tga 0 0 1\nimg/b.bmp 0.5 0 1\n", encoding="utf-8")
    field = import_rti(tmp_path / "t.lp", tmp_path / "f.zarr", dtype="float32")
    expected = srgb_to_linear(np.array(pictures, dtype=np.float32) / 255.0)
    np.testing.assert_array_equal(_images(field), expected)  # the table is the curve, bit for bit
    assert field.provenance["transfer"]["bit_depth"] == "8-bit"


def test_an_empty_tga_is_refused_by_name_and_line(tmp_path: Path) -> None:
    (tmp_path / "img").mkdir()
    Image.fromarray(np.zeros((4, 6, 3), np.uint8)).save(tmp_path / "img" / "a.tga")
    (tmp_path / "img" / "b.tga").write_bytes(b"")
    (tmp_path / "t.lp").write_text("2\nimg/a.tga 0 0 1\nimg/b.tga 0.5 0 1\n", encoding="utf-8")
    with pytest.raises(DatasetError, match=r"t\.lp, line 3: .*b\.tga: the file is empty"):
        import_rti(tmp_path / "t.lp", tmp_path / "f.zarr")
    assert not (tmp_path / "f.zarr").exists()

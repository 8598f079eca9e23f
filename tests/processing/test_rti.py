from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from core.camera_model import PinholeCamera, camera_to_rig, rig_to_camera
from core.errors import DatasetError, InputError
from core.field_store import ReflectanceField
from core.image_io import read_linear
from core.sample_data import rti_capture_path
from processing.rti import (
    LightPositions,
    export_lp,
    import_rti,
    read_lp,
    rti_camera,
    write_lp,
)

LOEWENKOPF_LP = rti_capture_path()
LOEWENKOPF = LOEWENKOPF_LP.parent


@pytest.fixture(scope="module")
def loewenkopf(tmp_path_factory: pytest.TempPathFactory) -> ReflectanceField:
    store = tmp_path_factory.mktemp("rti") / "loewenkopf.zarr"
    return import_rti(LOEWENKOPF_LP, store, progress=False)


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


# --- .lp reading and writing ----------------------------------------------------------------


def test_the_real_lp_file_has_240_unit_directions_over_the_upper_hemisphere() -> None:
    lights = read_lp(LOEWENKOPF_LP)
    assert len(lights) == 240 and lights.directions.shape == (240, 3)
    assert lights.files[0] == "jpg/Loewenkopf_klein_0001.jpg"
    assert lights.lines == tuple(range(2, 242))
    np.testing.assert_allclose(np.linalg.norm(lights.directions, axis=1), 1.0, atol=1e-12)
    z = lights.directions[:, 2]
    # README: "z runs from 0.02 to 0.99"; the largest is 0.99244 (rounded there).
    assert 0.02 <= z.min() < 0.025 and 0.99 < z.max() < 0.995
    # The first entry as written, to float32 rounding (the file's vectors are float32).
    np.testing.assert_allclose(
        lights.directions[0], [-0.0019356994, -0.14720464, 0.98910415], atol=1e-7
    )


def test_windows_endings_tabs_blank_lines_and_non_unit_vectors_are_accepted(
    tmp_path: Path,
) -> None:
    lp = tmp_path / "a.lp"
    lp.write_bytes(
        b"\xef\xbb\xbf2\r\njpg/a.jpg\t0.0\t0.0\t2.0\r\n\r\n  my photo.jpg   3 0 4  \r\n\r\n\r\n"
    )
    lights = read_lp(lp)
    assert lights.files == ["jpg/a.jpg", "my photo.jpg"]
    assert lights.lines == (2, 4)
    np.testing.assert_allclose(lights.directions, [[0, 0, 1], [0.6, 0, 0.8]], atol=1e-15)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("", r"line 1: empty file"),
        ("\n\n  \n", r"line 1: empty file"),
        ("two\na.jpg 0 0 1\n", r"line 1: expected the image count .*'two'"),
        ("0\n", r"line 1: expected the image count"),
        ("-1\n", r"line 1: expected the image count"),
        ("2\na.jpg 0 0 1\n", r"line 1: announces 2 images but only 1 entries follow .*line 2"),
        ("1\na.jpg 0 0 1\nb.jpg 0 0 1\n", r"line 3: more entries than the 1 announced on line 1"),
        ("1\na.jpg 0 0 1\n\nb.jpg 0 0 1\n", r"line 4: more entries than the 1"),
        ("2\na.jpg 0 0 1\nb.jpg 0 0\n", r"line 3: expected 'filename x y z'"),
        ("2\na.jpg 0 0 1\nb.jpg 0 0 0\n", r"line 3: the direction .* has zero length"),
        ("1\na.jpg 0,5 0 1\n", r"line 2: '0,5' is not a number"),
        ("1\na.jpg x 0 1\n", r"line 2: 'x' is not a number"),
        ("1\na.jpg nan 0 1\n", r"line 2: the direction .* is not finite"),
        ("1\na.jpg 0 inf 1\n", r"line 2: the direction .* is not finite"),
    ],
)
def test_malformed_lp_files_are_refused_with_the_line(
    tmp_path: Path, text: str, match: str
) -> None:
    lp = tmp_path / "bad.lp"
    lp.write_text(text, encoding="utf-8")
    with pytest.raises(DatasetError, match=match) as caught:
        read_lp(lp)
    assert str(lp) in str(caught.value)


def test_missing_or_binary_lp_files_are_refused(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match=r"no such \.lp file"):
        read_lp(tmp_path / "none.lp")
    (tmp_path / "binary.lp").write_bytes(b"\xff\xfe\x00\x81")
    with pytest.raises(DatasetError, match="cannot read"):
        read_lp(tmp_path / "binary.lp")


_NAMES = st.text(
    alphabet=st.characters(exclude_categories=("Cs",), exclude_characters="\r\n"),
    min_size=1,
    max_size=12,
).filter(lambda name: name == name.strip())
_VECTORS = arrays(
    np.float64, 3, elements=st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
).filter(lambda v: float(np.linalg.norm(v)) > 1e-6)


@settings(max_examples=60, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(entries=st.lists(st.tuples(_NAMES, _VECTORS), min_size=1, max_size=8))
def test_write_then_read_round_trips(tmp_path: Path, entries: list[tuple[str, np.ndarray]]) -> None:
    names = [name for name, _ in entries]
    vectors = np.array([vector for _, vector in entries])
    written = write_lp(tmp_path / "sub" / "round.lp", names, vectors)
    read = read_lp(tmp_path / "sub" / "round.lp")
    assert read.files == names == written.files
    assert read.lines == written.lines
    unit = vectors / np.linalg.norm(vectors, axis=1, keepdims=True)
    np.testing.assert_allclose(read.directions, unit, rtol=0, atol=1e-15)
    np.testing.assert_allclose(written.directions, unit, rtol=0, atol=1e-15)


def test_write_lp_format_and_digits(tmp_path: Path) -> None:
    direction = np.array([0.1, -0.2, 0.3])
    direction /= np.linalg.norm(direction)
    written = write_lp(tmp_path / "f.lp", ["jpg/a.jpg"], [direction])
    text = (tmp_path / "f.lp").read_text(encoding="utf-8")
    first, second, end = text.split("\n")
    assert first == "1" and end == ""
    name, *numbers = second.split(" ")
    assert name == "jpg/a.jpg"
    assert [float(n) for n in numbers] == written.directions[0].tolist()  # every digit
    np.testing.assert_allclose(written.directions[0], direction, rtol=0, atol=1e-15)
    assert not list(tmp_path.glob(".*partial*"))


@pytest.mark.parametrize(
    ("files", "directions", "match"),
    [
        ([], np.zeros((0, 3)), r"at least one image"),
        (["a.jpg"], [[0, 0, 1], [0, 0, 1]], r"shape \(1, 3\)"),
        (["a.jpg", "b.jpg"], [[0, 0, 1], [0, 0, 0]], r"line 3: direction .* zero or not finite"),
        (["a.jpg"], [[np.nan, 0, 1]], r"line 2: direction .* zero or not finite"),
        (["a.jpg", ""], [[0, 0, 1], [0, 0, 1]], r"line 3: image name '' is empty"),
        ([" a.jpg"], [[0, 0, 1]], r"line 2: .*edge whitespace"),
        (["a\nb.jpg"], [[0, 0, 1]], r"line 2: .*line break"),
    ],
)
def test_write_lp_refuses_bad_arguments(
    tmp_path: Path, files: list[str], directions: object, match: str
) -> None:
    with pytest.raises(InputError, match=match):
        write_lp(tmp_path / "bad.lp", files, directions)  # type: ignore[arg-type]
    assert not (tmp_path / "bad.lp").exists()


def test_light_positions_check_their_shapes() -> None:
    with pytest.raises(InputError, match=r"shape \(2, 3\)"):
        LightPositions(files=["a", "b"], directions=np.zeros((3, 3)))


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
    np.testing.assert_allclose(np.linalg.norm(rig, axis=1), np.linalg.norm(vectors, axis=1))
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
    assert field.sample_kind == "pixels" and field.dtype == np.float32
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
        np.testing.assert_array_equal(slab[t].reshape(43, 64, 3), image)
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
        import_rti(lp, tmp_path / "f.zarr", progress=False)
    assert not (tmp_path / "f.zarr").exists()


def test_mixed_image_sizes_are_refused_and_leave_no_store(tmp_path: Path) -> None:
    lp = _small_capture(tmp_path, [(4, 6), (4, 6), (6, 4), (4, 6)])
    with pytest.raises(
        DatasetError, match=r"line 4: image 'img/2\.png' is 4x6 pixels, the first .* is 6x4"
    ):
        import_rti(lp, tmp_path / "f.zarr", progress=False)
    assert not (tmp_path / "f.zarr").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["img", "small.lp"]


def test_a_corrupt_image_is_refused_with_its_line(tmp_path: Path) -> None:
    lp = _small_capture(tmp_path, [(4, 6)] * 2)
    (tmp_path / "img" / "1.png").write_bytes(b"not a png")
    with pytest.raises(DatasetError, match=r"line 3: .*1\.png.*cannot decode"):
        import_rti(lp, tmp_path / "f.zarr", progress=False)


def test_grey_images_become_rgb_and_an_old_store_is_replaced(tmp_path: Path) -> None:
    lp = _small_capture(tmp_path, [(4, 6)] * 3, grey=True)
    store = tmp_path / "f.zarr"
    import_rti(_small_capture(tmp_path / "other", [(2, 2)]), store, progress=False)
    field = import_rti(lp, store, dtype="float16", progress=True)
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
        import_rti(lp, tmp_path / "f.zarr", dtype="float64", progress=False)
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "notes.txt").write_text("mine", encoding="utf-8")
    with pytest.raises(InputError, match="exists and is not a field store"):
        import_rti(lp, tmp_path / "taken", progress=False)
    assert (tmp_path / "taken" / "notes.txt").read_text(encoding="utf-8") == "mine"

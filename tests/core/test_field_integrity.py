"""A damaged field store is an error naming the store and the chunk, never data (issue 15)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import zarr

from app.cli import main
from core.camera_model import PinholeCamera
from core.errors import DatasetError
from core.field_store import FieldStoreWriter, ReflectanceField
from core.store.integrity import check_store
from sim.field import field_cameras, simulate_field


@pytest.fixture(scope="module")
def intact(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("field") / "f.zarr"
    cameras = field_cameras(3, width=32, height=32)
    simulate_field(path, "glossy-sphere", lights=4, cameras=cameras, points=800)
    return path


@pytest.fixture
def store(intact: Path, tmp_path: Path) -> Path:
    copy = tmp_path / "f.zarr"
    shutil.copytree(intact, copy)
    return copy


def _chunk(store: Path, camera: int, light: int) -> Path:
    return store / "radiance" / "c" / str(camera) / str(light) / "0" / "0"


def test_an_intact_store_verifies(intact: Path, capsys: pytest.CaptureFixture[str]) -> None:
    check = check_store(intact)
    assert check.ok and check.digest == "matches" and check.chunks == 12
    assert main(["verify", str(intact), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "3 cameras x 4 lights x 800 samples, 12 radiance slabs read" in out
    assert out.splitlines()[0].endswith("radiance digest matches: intact")


def test_a_deleted_chunk_is_an_error_not_zeros(
    store: Path, courtyard_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _chunk(store, 1, 2).unlink()
    with pytest.raises(DatasetError) as error:
        ReflectanceField.open(store)
    message = str(error.value)
    assert "1 of the 12 chunks of 'radiance' are missing" in message
    assert "camera 1 light 2 sample block 0 (radiance/c/1/2/0/0)" in message
    assert main(["verify", str(store), "--quiet"]) == 1
    out = capsys.readouterr().out
    assert "DAMAGED" in out and "camera 1 light 2" in out
    argv = ["relight", str(store), "--env", str(courtyard_path), "--view", "30,50", "--size",
            "32x32", "-o", str(store.parent / "x.png")]  # fmt: skip
    assert main(argv) == 2
    assert "chunks of 'radiance' are missing" in capsys.readouterr().err


def test_a_deleted_visibility_chunk_is_an_error(store: Path) -> None:
    (store / "visibility" / "c" / "2" / "0").unlink()
    with pytest.raises(DatasetError, match=r"chunks of 'visibility' are missing \(camera 2"):
        ReflectanceField.open(store)


def test_a_truncated_chunk_names_the_store_and_the_chunk(
    store: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    chunk = _chunk(store, 2, 1)
    chunk.write_bytes(chunk.read_bytes()[:40])
    field = ReflectanceField.open(store)
    field.camera_slab(0)  # the other cameras read
    with pytest.raises(DatasetError) as error:
        field.camera_slab(2)
    message = str(error.value)
    where = "camera 2 light 1 sample block 0 (radiance/c/2/1/0/0)"
    assert message.startswith(f"{store}: cannot read {where}")
    assert "damaged" in message
    assert error.value.__cause__ is None and error.value.__suppress_context__
    assert main(["verify", str(store), "--quiet"]) == 1
    out = capsys.readouterr().out
    assert "cannot read camera 2 light 1" in out and "digest not checked" in out


def test_nan_radiance_is_refused_with_count_and_location(
    store: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    radiance = zarr.open_group(str(store), mode="r+")["radiance"]
    slab = np.asarray(radiance[1, 3])
    slab[[5, 9], 0] = np.nan
    slab[700, 2] = np.inf
    radiance[1, 3] = slab
    field = ReflectanceField.open(store)
    with pytest.raises(DatasetError, match=r"3 non-finite radiance values .* camera 1, the "
                       r"first at light 3, sample 5"):  # fmt: skip
        field.camera_slab(1)
    with pytest.raises(DatasetError, match="non-finite"):
        field.load()
    # One light's image (the viewer's captured pictures) is checked too, in both widths.
    with pytest.raises(DatasetError, match=r"non-finite radiance .* camera 1 under light 3"):
        field.light_radiance(1, 3, widen=False)
    assert np.isfinite(field.light_radiance(1, 2)).all()
    assert main(["verify", str(store), "--quiet"]) == 1
    out = capsys.readouterr().out
    assert "3 non-finite radiance values in camera 1 light 3, the first at sample 5" in out
    assert "radiance differs from what was written" in out


def test_a_chunk_replaced_by_another_images_is_caught_by_the_digest(
    store: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    shutil.copyfile(_chunk(store, 0, 0), _chunk(store, 0, 1))
    ReflectanceField.open(store).camera_slab(0)  # reads: only the digest can tell
    check = check_store(store)
    assert check.digest == "differs" and not check.ok


def test_the_writer_refuses_non_finite_values_and_keeps_black_slabs(tmp_path: Path) -> None:
    camera = PinholeCamera(azimuth_deg=0.0, inclination_deg=30.0, width=8, height=8)
    lights = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
    points = np.zeros((6, 3))
    normals = np.tile([0.0, 0.0, 1.0], (6, 1))

    def writer(dtype: str) -> FieldStoreWriter:
        return FieldStoreWriter(tmp_path / f"{dtype}.zarr", points=points, normals=normals,
                                light_directions=lights, cameras=[camera], dtype=dtype)  # fmt: skip

    w = writer("float32")
    bad = np.ones((6, 3))
    bad[4, 1] = np.nan
    with pytest.raises(DatasetError, match=r"camera 0 light 1: 1 radiance values are NaN or "
                       r"infinite in float32 \(the first at sample 4\)"):  # fmt: skip
        w.write_slab(0, 1, bad)
    w.abort()
    half = writer("float16")
    with pytest.raises(DatasetError, match="NaN or infinite in float16"):
        half.write_slab(0, 0, np.full((6, 3), 1e6))  # beyond float16's range
    half.abort()
    black = writer("float32")
    black.write_slab(0, 0, np.zeros((6, 3)))  # a black image is data, its chunk is written
    black.write_slab(0, 1, np.ones((6, 3)))
    black.write_visibility(0, np.zeros(6, dtype=bool))
    path = black.finish()
    field = ReflectanceField.open(path)
    np.testing.assert_array_equal(field.camera_slab(0)[0], 0.0)
    assert check_store(path).ok


@pytest.mark.parametrize("dtype", ["float16", "float32"])
def test_one_light_of_either_width_is_checked_for_nan(tmp_path: Path, dtype: str) -> None:
    camera = PinholeCamera(azimuth_deg=0.0, inclination_deg=30.0, width=8, height=8)
    writer = FieldStoreWriter(tmp_path / "f.zarr", points=np.zeros((6, 3)),
                              normals=np.tile([0.0, 0.0, 1.0], (6, 1)),
                              light_directions=np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]),
                              cameras=[camera], dtype=dtype)  # fmt: skip
    writer.write_slab(0, 0, np.full((6, 3), 65504.0))  # float16's largest: finite
    writer.write_slab(0, 1, np.ones((6, 3)))
    writer.write_visibility(0, np.ones(6, dtype=bool))
    path = writer.finish()
    field = ReflectanceField.open(path)
    assert field.light_radiance(0, 0, widen=False).dtype == np.dtype(dtype)
    assert field.light_radiance(0, 0).max() == 65504.0
    for bad in (np.nan, np.inf, -np.inf):
        radiance = zarr.open_group(str(path), mode="r+")["radiance"]
        slab = np.ones((6, 3), dtype=dtype)
        slab[5, 2] = bad
        radiance[0, 1] = slab
        with pytest.raises(DatasetError, match="camera 0 under light 1"):
            ReflectanceField.open(path).light_radiance(0, 1)

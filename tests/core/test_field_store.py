from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zarr

from core.camera_model import PinholeCamera
from core.errors import DatasetError, InputError
from core.field_store import FieldStoreWriter, ReflectanceField
from core.store.integrity import check_store
from sim.field import field_cameras, simulate_field
from tests.full_disk import writes_under_limit


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("field") / "f.zarr"
    cameras = field_cameras(3, width=48, height=48)
    simulate_field(path, "glossy-sphere", lights=4, cameras=cameras, points=2000, dtype="float16")
    return path


def test_open_reads_the_small_arrays_and_slabs_on_demand(store: Path) -> None:
    field = ReflectanceField.open(store, cached_slabs=2)
    assert field.shape == (3, 4, 2000) and field.dtype == np.float16
    assert field.sample_kind == "points" and field.image_shape is None
    assert field.points is not None and field.points.shape == (2000, 3)
    assert len(field.cameras) == 3 and field.visibility.shape == (3, 2000)
    raw = zarr.open_group(str(store), mode="r")["radiance"]
    np.testing.assert_array_equal(field.camera_slab(1), raw[1])
    for camera in (0, 2, 1):
        field.camera_slab(camera)
    assert list(field._slabs) == [2, 1]  # the two most recent
    np.testing.assert_array_equal(field.load(), raw[...])


def test_missing_or_foreign_stores_are_refused(tmp_path: Path, store: Path) -> None:
    with pytest.raises(DatasetError, match="no such field store"):
        ReflectanceField.open(tmp_path / "nothing.zarr")
    group = zarr.open_group(str(tmp_path / "other.zarr"), mode="w")
    group.attrs["schema_version"] = 99
    with pytest.raises(DatasetError, match="schema version 99"):
        ReflectanceField.open(tmp_path / "other.zarr")
    group.attrs["schema_version"] = 1
    with pytest.raises(DatasetError, match="no 'radiance' array"):
        ReflectanceField.open(tmp_path / "other.zarr")


def test_camera_index_is_checked(store: Path) -> None:
    field = ReflectanceField.open(store)
    with pytest.raises(InputError, match=r"camera index 3 outside 0\.\.2"):
        field.camera_slab(3)


def test_a_subset_holds_the_chosen_slabs_in_memory(tmp_path: Path) -> None:
    path = tmp_path / "f.zarr"
    simulate_field(path, "diffuse-sphere", lights=5, cameras=field_cameras(3, width=16,
                   height=16), points=300)  # fmt: skip
    field = ReflectanceField.open(path)
    part = field.subset(cameras=np.array([2, 0]), lights=np.array([1, 4]), samples=np.arange(10))
    assert part.shape == (2, 2, 10) and part.path != field.path
    np.testing.assert_array_equal(part.camera_slab(0), field.camera_slab(2)[[1, 4], :10])
    np.testing.assert_array_equal(part.visibility, field.visibility[[2, 0], :10])
    assert part.cameras == [field.cameras[2], field.cameras[0]]
    with pytest.raises(InputError, match=r"light indices must be in 0\.\.4"):
        field.subset(lights=np.array([5]))


def test_a_store_is_put_in_place_only_when_complete(tmp_path: Path) -> None:
    cameras = [PinholeCamera(0.0, 30.0, width=4, height=4)]
    lights = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])

    def writer(**options: bool) -> FieldStoreWriter:
        return FieldStoreWriter(
            tmp_path / "f.zarr", points=None, normals=None, light_directions=lights,
            cameras=cameras, image_shape=(2, 3), **options,
        )  # fmt: skip

    first = writer()
    first.write_slab(0, 0, np.ones((6, 3)))
    assert not (tmp_path / "f.zarr").exists()  # nothing under the real name while writing
    with pytest.raises(DatasetError, match=r"2 slabs were never written \(camera 0 light 1, "
                       r"the visibility of camera 0\)"):  # fmt: skip
        first.finish()
    assert not list(tmp_path.iterdir())  # the partial store went too
    second = writer()
    second.write_visibility(0, np.ones(6, dtype=bool))
    for t in range(2):
        second.write_slab(0, t, np.full((6, 3), t + 1.0))
    second.finish()
    digest = ReflectanceField.open(tmp_path / "f.zarr").radiance_digest
    assert digest is not None and len(digest) == 64
    # A failed replacement leaves the old store as it was.
    third = writer(overwrite=True)
    third.write_slab(0, 0, np.zeros((6, 3)))
    third.abort()
    kept = ReflectanceField.open(tmp_path / "f.zarr")
    assert kept.radiance_digest == digest and float(kept.load().max()) == 2.0
    with pytest.raises(InputError, match="already there"):
        writer()


def test_a_black_part_of_a_slab_is_written_not_left_out(tmp_path: Path) -> None:
    # A slab of several chunks whose second block is black (samples no camera sees): the
    # writer must store that chunk, or the store would read as damaged (a missing chunk).
    from core.store.integrity import check_store

    points = np.random.default_rng(0).normal(size=(10, 3)).astype(np.float32)
    writer = FieldStoreWriter(
        tmp_path / "f.zarr", points=points, normals=points, light_directions=np.eye(3)[:1],
        cameras=field_cameras(1), sample_chunk=4,
    )  # fmt: skip
    slab = np.zeros((10, 3), dtype=np.float32)
    slab[:4] = 1.0
    writer.write_slab(0, 0, slab)
    writer.write_visibility(0, slab[:, 0] > 0)
    path = writer.finish()
    field = ReflectanceField.open(path)
    assert field.radiance.chunks == (1, 1, 4, 3)
    np.testing.assert_array_equal(field.camera_slab(0)[0], slab)
    assert check_store(path).ok


def _pixel_store(path: Path, height: int, width: int, lights: int, chunk: int) -> np.ndarray:
    """A pixel field of random radiance (T, H, W, 3), float16, ``chunk`` samples a chunk."""
    rng = np.random.default_rng(5)
    values = rng.random((lights, height, width, 3)).astype(np.float16)
    directions = rng.normal(size=(lights, 3))
    directions[:, 2] = np.abs(directions[:, 2]) + 0.2
    writer = FieldStoreWriter(
        path, points=None, normals=None,
        light_directions=directions / np.linalg.norm(directions, axis=1, keepdims=True),
        cameras=[PinholeCamera(0.0, 0.0, 10.0, 10.0, width, height)],
        image_shape=(height, width), dtype="float16", sample_chunk=chunk,
    )  # fmt: skip
    for t in range(lights):
        writer.write_slab(0, t, values[t].reshape(-1, 3))
    visible = rng.random(height * width) > 0.1
    writer.write_visibility(0, visible)
    writer.finish()
    return values


def test_tiles_are_the_views_windows_read_band_by_band(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import core.field_store

    values = _pixel_store(tmp_path / "p.zarr", 37, 53, 4, chunk=100)
    field = ReflectanceField.open(tmp_path / "p.zarr")
    # Bands of 3 rows (4 lights x 53 pixels x 3 x 2 bytes a row): a window spans several,
    # and several windows share a band.
    monkeypatch.setattr(core.field_store, "TILE_READ_BYTES", 3 * 4 * 53 * 3 * 2)
    origins = [(0, 0), (2, 40), (27, 5), (20, 43)]
    tiled = field.tiles(origins, 10, columns=3)
    assert tiled.image_shape == (20, 30) and tiled.shape == (1, 4, 600)
    assert tiled.cameras[0].width == 30 and tiled.cameras[0].height == 20
    assert tiled.provenance["tiles_of"]["origins"] == [list(o) for o in origins]
    mosaic = tiled.camera_slab(0).reshape(4, 20, 30, 3)
    seen = tiled.visibility[0].reshape(20, 30)
    visible = field.visibility[0].reshape(37, 53)
    for index, (row, column) in enumerate(origins):
        y, x = index // 3 * 10, index % 3 * 10
        np.testing.assert_array_equal(
            mosaic[:, y : y + 10, x : x + 10],
            values[:, row : row + 10, column : column + 10].astype(np.float32),
        )
        np.testing.assert_array_equal(seen[y : y + 10, x : x + 10],
                                      visible[row : row + 10, column : column + 10])  # fmt: skip
    # The mosaic's last cell holds no window: black, and no pixel of it counts.
    assert not mosaic[:, 10:, 10:].any() and not seen[10:, 10:].any()
    np.testing.assert_array_equal(tiled.light_directions, field.light_directions)


def test_tiles_outside_the_view_or_of_points_are_refused(tmp_path: Path, store: Path) -> None:
    _pixel_store(tmp_path / "p.zarr", 12, 16, 2, chunk=64)
    field = ReflectanceField.open(tmp_path / "p.zarr")
    with pytest.raises(InputError, match=r"at row 3, column 8 is not inside the 16 x 12 view"):
        field.tiles([(3, 8)], 10, columns=1)
    with pytest.raises(InputError, match="need a field of pixels"):
        ReflectanceField.open(store).tiles([(0, 0)], 4, columns=1)


# --- attributes and directions altered behind the writer's back (issue 28) -------------------


def _altered(store: Path, tmp_path: Path) -> tuple[Path, Any]:
    copy = tmp_path / "altered.zarr"
    shutil.copytree(store, copy)
    return copy, zarr.open_group(str(copy), mode="r+")


@pytest.mark.parametrize(
    ("name", "value", "words"),
    [
        ("samples", "points", "attribute samples is 'points'"),
        ("samples", {"kind": "pixels", "width": 20}, "attribute samples is {'kind': 'pixels'"),
        ("dark_cameras", ["x"], "attribute dark_cameras is ['x']"),
        ("light_model", "directional", "attribute light_model is 'directional'"),
        ("provenance", [1, 2], "attribute provenance is [1, 2]"),
        ("radiance_digest", 5, "attribute radiance_digest is 5"),
    ],
)
def test_an_attribute_of_the_wrong_type_is_refused_on_opening_and_by_verify(
    store: Path, tmp_path: Path, name: str, value: object, words: str
) -> None:
    copy, group = _altered(store, tmp_path)
    group.attrs[name] = value
    with pytest.raises(DatasetError) as raised:
        ReflectanceField.open(copy)
    assert str(raised.value).startswith(f"{copy}: {words}")
    report = check_store(copy)
    assert not report.ok and any(problem.startswith(words) for problem in report.problems)


@pytest.mark.parametrize(("scale", "index", "words"), [(10.0, 0, "of length 10 (3 more)"),
                                                       (np.nan, 2, "(nan, nan, nan)")])  # fmt: skip
def test_light_directions_that_are_not_unit_vectors_are_refused_with_their_index(
    store: Path, tmp_path: Path, scale: float, index: int, words: str
) -> None:
    copy, group = _altered(store, tmp_path)
    directions = np.asarray(group["light_directions"][...])
    if np.isnan(scale):
        directions[2] = np.nan
    else:
        directions *= scale
    group["light_directions"][...] = directions
    with pytest.raises(DatasetError) as raised:
        ReflectanceField.open(copy)
    assert str(raised.value).startswith(f"{copy}: light direction {index} is ")
    assert words in str(raised.value)
    assert not check_store(copy).ok


def test_the_writer_refuses_directions_that_are_not_unit_vectors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"light direction 1 is \(0, 0, 2\), of length 2"):
        FieldStoreWriter(
            tmp_path / "f.zarr", points=None, normals=None,
            light_directions=np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 2.0]]),
            cameras=[PinholeCamera(0.0, 30.0, width=4, height=4)], image_shape=(2, 3),
        )  # fmt: skip
    assert list(tmp_path.iterdir()) == []


def test_a_full_disk_leaves_no_partial_store_and_keeps_the_old_one(
    store: Path, tmp_path: Path
) -> None:
    # On a full disk `rig sim field` and `rig process` stopped with OSError 28 and left
    # .NAME.PID.partial stores (a child under a real file size limit, tests/full_disk.py).
    kept = tmp_path / "kept.zarr"
    shutil.copytree(store, kept)
    before = sorted((p.relative_to(kept), p.read_bytes()) for p in kept.rglob("*") if p.is_file())
    found = writes_under_limit(
        f"""
from sim.field import field_cameras, simulate_field
cameras = field_cameras(2, width=16, height=16)
for name, overwrite in (("new.zarr", False), ("kept.zarr", True)):
    attempt(name, lambda name=name, overwrite=overwrite: simulate_field(
        {str(tmp_path)!r} + "/" + name, "glossy-sphere", lights=3, cameras=cameras,
        points=6000, overwrite=overwrite))
""",
        limit=20_000,
    )
    for name in ("new.zarr", "kept.zarr"):
        assert found[name]["project"], found[name]["traceback"]
        assert found[name]["message"].startswith(f"{tmp_path / name}: cannot write: the file is")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.zarr"]  # no partial store
    after = sorted((p.relative_to(kept), p.read_bytes()) for p in kept.rglob("*") if p.is_file())
    assert after == before

"""Every array and attribute of a field store is bound to the digests its writer recorded.

Issue 28: ``rig verify`` said "intact", and ``rig fit`` / ``rig relight`` used the values, for
a store whose two cameras' visibility chunks were swapped, whose points were scaled, whose
radiance chunk came from another store with the digest attribute removed, and whose
``zarr.json`` said int32 for float32 radiance; zarr's own words named neither store nor array
for a chunk shape of the wrong rank or a negative size. Each case here is a store written by
the project's writer (:func:`sim.field.simulate_field`), then altered behind its back.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zarr

from app.cli import main
from core.errors import DatasetError
from core.field_store import ReflectanceField
from core.store.integrity import check_store
from core.store.writer import remove_stale_partials
from sim.field import field_cameras, simulate_field


def _simulated(path: Path, scene: str) -> Path:
    cameras = field_cameras(3, width=16, height=16)
    simulate_field(path, scene, lights=6, cameras=cameras, points=200)
    return path


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Two stores of one layout (same points, lights and cameras), different materials."""
    folder = tmp_path_factory.mktemp("stores")
    return {
        "glossy": _simulated(folder / "glossy.zarr", "glossy-sphere"),
        "diffuse": _simulated(folder / "diffuse.zarr", "diffuse-sphere"),
    }


@pytest.fixture
def store(written: dict[str, Path], tmp_path: Path) -> Path:
    copy = tmp_path / "f.zarr"
    shutil.copytree(written["glossy"], copy)
    return copy


def _edit_json(path: Path, edit: Callable[[dict[str, Any]], None]) -> None:
    document = json.loads(path.read_text())
    edit(document)
    path.write_text(json.dumps(document))


def _drop_attributes(store: Path, *names: str) -> None:
    def drop(document: dict[str, Any]) -> None:
        for name in names:
            del document["attributes"][name]

    _edit_json(store / "zarr.json", drop)


def _refused(store: Path, capsys: pytest.CaptureFixture[str], *words: str) -> None:
    """Opening, ``rig fit`` and ``rig verify`` all refuse ``store``, naming it and ``words``."""
    with pytest.raises(DatasetError) as raised:
        ReflectanceField.open(store)
    message = str(raised.value)
    assert message.startswith(f"{store}: ") and all(w in message for w in words), message
    assert main(["fit", str(store), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert f"rig fit: error: {store}: " in err and "Traceback" not in err
    assert not (store.parent / (store.name + ".models.npz")).exists()  # nothing was fitted
    assert main(["verify", str(store), "--quiet"]) == 1
    out = capsys.readouterr().out
    assert "DAMAGED" in out and all(w in out for w in words), out


def test_an_intact_store_is_bound_by_its_digests(
    written: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    ReflectanceField.open(written["glossy"])
    check = check_store(written["glossy"])
    assert check.ok and check.digest == "matches" and check.notes == ()
    record = zarr.open_group(str(written["glossy"]), mode="r").attrs["digests"]
    assert sorted(record["data"]) == sorted(record["metadata"]) == [
        "camera_directions", "light_directions", "normals", "points", "radiance", "visibility",
    ]  # fmt: skip
    assert {"cameras", "provenance", "radiance_digest", "samples"} <= set(record["attributes"])
    assert main(["verify", str(written["glossy"]), "--quiet"]) == 0
    assert "note:" not in capsys.readouterr().out


def test_two_cameras_visibility_chunks_swapped(
    store: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    first, second = store / "visibility" / "c" / "0" / "0", store / "visibility" / "c" / "1" / "0"
    one, two = first.read_bytes(), second.read_bytes()
    assert one != two
    first.write_bytes(two)
    second.write_bytes(one)
    _refused(store, capsys, "the values of 'visibility' differ from what was written")


def test_points_replaced_by_scaled_ones(store: Path, capsys: pytest.CaptureFixture[str]) -> None:
    points = zarr.open_group(str(store), mode="r+")["points"]
    points[...] = np.asarray(points[...]) * 1.5
    _refused(store, capsys, "the values of 'points' differ")


def test_a_radiance_chunk_of_another_store_with_the_digest_attribute_removed(
    store: Path, written: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    chunk = Path("radiance/c/1/2/0/0")
    shutil.copyfile(written["diffuse"] / chunk, store / chunk)
    _drop_attributes(store, "radiance_digest")
    _refused(store, capsys, "attribute radiance_digest was removed")
    # verify reads the radiance too: the chunk is named as data that differs.
    assert "the radiance differs from what was written" in "\n".join(check_store(store).problems)


def test_every_digest_removed_is_damage_not_an_old_store(
    store: Path, written: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    chunk = Path("radiance/c/1/2/0/0")
    shutil.copyfile(written["diffuse"] / chunk, store / chunk)
    _drop_attributes(store, "radiance_digest", "digests")
    _refused(store, capsys, "attribute digests was removed")


def test_zarr_json_says_int32_for_float32_radiance(
    store: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _edit_json(store / "radiance" / "zarr.json", lambda m: m.update(data_type="int32"))
    _refused(store, capsys, "array 'radiance' (radiance/zarr.json)", "its dtype is int32")


@pytest.mark.parametrize(
    ("edit", "words"),
    [
        pytest.param(
            lambda m: m["chunk_grid"]["configuration"].update(chunk_shape=[1, 1, 200]),
            "its shape [3, 6, 200, 3] has 4 dimensions and its chunk shape [1, 1, 200] 3",
            id="chunk rank",
        ),
        pytest.param(
            lambda m: m.update(shape=[3, 6, -200, 3]),
            "its shape [3, 6, -200, 3] holds a negative size",
            id="negative size",
        ),
        pytest.param(
            lambda m: m["chunk_grid"]["configuration"].update(chunk_shape=[1, 1, 0, 3]),
            "its chunk shape [1, 1, 0, 3] holds a size below 1",
            id="zero chunk",  # was a ZeroDivisionError
        ),
    ],
)
def test_damaged_array_metadata_is_named_not_in_zarrs_words(
    store: Path, capsys: pytest.CaptureFixture[str], edit: Callable[[dict[str, Any]], None],
    words: str,
) -> None:  # fmt: skip
    _edit_json(store / "radiance" / "zarr.json", edit)
    _refused(store, capsys, "array 'radiance' (radiance/zarr.json)", words)
    out_of_zarr = ("`chunk_shape`", "Expected all values to be non-negative")
    with pytest.raises(DatasetError) as raised:
        ReflectanceField.open(store)
    assert not any(words in str(raised.value) for words in out_of_zarr)


def test_an_edited_attribute_is_named(store: Path, capsys: pytest.CaptureFixture[str]) -> None:
    group = zarr.open_group(str(store), mode="r+")
    group.attrs["light_model"] = {"type": "directional", "irradiance": 3.0}
    _refused(store, capsys, "attribute light_model differs from what was written")


def test_a_store_written_before_digests_stays_readable_and_says_what_is_unbound(
    store: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # As the writer wrote stores before this change: the radiance digest, no record, no mark.
    _drop_attributes(store, "digests")
    _edit_json(store / "radiance" / "zarr.json", lambda m: m.update(attributes={}))
    field = ReflectanceField.open(store)
    assert field.radiance_digest is not None and field.load().shape == (3, 6, 200, 3)
    check = check_store(store)
    assert check.ok and check.digest == "matches"
    (note,) = check.notes
    assert "no digest of camera_directions, light_directions, normals, points, visibility" in note
    assert "rig process DATASET -o STORE --overwrite" in note
    assert main(["verify", str(store), "--quiet"]) == 0
    assert "note: written before digests were recorded" in capsys.readouterr().out


def test_relight_refuses_a_store_without_its_digests_beside_another_fields_fit(
    store: Path, written: dict[str, Path], tmp_path: Path, courtyard_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    from processing.sample_model_store import models_for_field

    # The other store's fit (same layout: same points, lights and cameras) beside this one,
    # whose digests were removed: the fit's radiance digest has nothing to be compared with.
    other_fit = tmp_path / "other.npz"
    models_for_field(ReflectanceField.open(written["diffuse"]), other_fit)
    _drop_attributes(store, "radiance_digest", "digests")
    argv = ["relight", str(store), "--env", str(courtyard_path), "--view", "20,40", "--size",
            "24x24", "--scheme", "model", "--models", str(other_fit), "-o",
            str(tmp_path / "r.png")]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"rig relight: error: {store}: " in err and "digests was removed" in err
    assert not (tmp_path / "r.png").exists()


def test_stale_partials_of_gone_processes_are_removed(tmp_path: Path) -> None:
    target = tmp_path / "f.zarr"
    gone, alive = 2**22 + 12345, 1  # beyond Linux's largest PID; init is always there
    for pid in (gone, alive):
        (tmp_path / f".f.zarr.{pid}.partial").mkdir()
    (tmp_path / f".other.zarr.{gone}.partial").mkdir()  # another store's: not this writer's
    assert remove_stale_partials(target) == [tmp_path / f".f.zarr.{gone}.partial"]
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        ".f.zarr.1.partial", f".other.zarr.{gone}.partial",
    ]  # fmt: skip


def test_a_store_older_than_digests_refuses_a_fit_that_names_one(
    store: Path, written: dict[str, Path], tmp_path: Path
) -> None:
    from processing.sample_model_store import StaleFitError, models_for_field

    other_fit = tmp_path / "other.npz"
    models_for_field(ReflectanceField.open(written["diffuse"]), other_fit)
    # As stores were written before any digest: no radiance digest, no record, no mark.
    _drop_attributes(store, "radiance_digest", "digests")
    _edit_json(store / "radiance" / "zarr.json", lambda m: m.update(attributes={}))
    field = ReflectanceField.open(store)
    assert field.radiance_digest is None
    with pytest.raises(StaleFitError, match="the store's is missing"):
        models_for_field(field, other_fit)

"""Fitting at bounded memory, block by block, in-process and on a Dask cluster (issue 18)."""

from __future__ import annotations

import shutil
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from app.cli import main
from core.cluster import dask_client
from core.errors import DatasetError, InputError
from core.field_store import ReflectanceField
from core.store.integrity import check_store
from processing.sample_model_store import read_sample_models
from processing.sample_models import BasisFit, SampleModels, fit_sample_models, sample_block_size
from sim.field import field_cameras, simulate_field
from tests.cluster_faults import kill_a_worker_mid_run
from tests.full_disk import run_limited

CHUNK = 700  # samples per stored chunk: 3000 samples are 4 full chunks and a short one
BYTES_PER_SAMPLE = 6 * 16 * 3 * 4  # float32 radiance of one sample, 6 cameras x 16 lights
RIG = str(Path(sys.executable).with_name("rig"))


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("scale") / "torus.zarr"
    simulate_field(path, "textured-torus", lights=16, cameras=field_cameras(6, width=48,
                   height=48), points=3000, dtype="float16", sample_chunk=CHUNK)  # fmt: skip
    return path


@pytest.fixture(scope="module")
def whole_fit(store: Path) -> SampleModels:
    """The reference: every sample in one block."""
    field = ReflectanceField.open(store)
    assert sample_block_size(field, 3000 * BYTES_PER_SAMPLE) == 3000
    return fit_sample_models(field, memory_bytes=3000 * BYTES_PER_SAMPLE)


def _assert_same_fit(a: SampleModels, b: SampleModels) -> None:
    assert list(a.fits) == list(b.fits)
    for name, fit in a.fits.items():
        other = b.fits[name]
        for key in ("normals", "rho_d", "f0", "alpha", "lit", "fitted"):
            np.testing.assert_array_equal(getattr(fit, key), getattr(other, key), err_msg=key)
        np.testing.assert_array_equal(fit.loo.squared_error, other.loo.squared_error)
        np.testing.assert_array_equal(fit.loo.energy, other.loo.energy)


def test_the_store_is_chunked_by_samples_and_reads_blocks_across_chunks(store: Path) -> None:
    field = ReflectanceField.open(store)
    assert field.sample_chunk == CHUNK and field.radiance.chunks == (1, 1, CHUNK, 3)
    block = field.sample_block(650, 1500)  # parts of three chunks
    expected = np.stack([field.camera_radiance(s)[:, 650:1500] for s in range(6)])
    assert block.dtype == np.float32 and block.shape == (850, 6, 16, 3)
    np.testing.assert_array_equal(block, expected.transpose(2, 0, 1, 3).astype(np.float32))
    assert check_store(store).digest == "matches"


def test_a_subset_reads_its_samples_across_chunks(store: Path) -> None:
    field = ReflectanceField.open(store)
    keep = np.sort(np.random.default_rng(1).choice(3000, size=400, replace=False))
    part = field.subset(cameras=np.array([4, 1]), lights=np.array([3, 0, 9]), samples=keep)
    whole = field.load().astype(np.float32)
    np.testing.assert_array_equal(part.radiance, whole[[4, 1]][:, [3, 0, 9]][:, :, keep])
    np.testing.assert_array_equal(part.visibility, field.visibility[[4, 1]][:, keep])


def test_the_slab_cache_keeps_to_its_byte_budget(
    store: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import core.field_store

    field = ReflectanceField.open(store, cached_slabs=8)
    slab_bytes = field.camera_slab(0).nbytes
    monkeypatch.setattr(core.field_store, "CACHED_SLAB_BYTES", 2 * slab_bytes + 1)
    for camera in range(6):
        field.camera_slab(camera)
    assert list(field._slabs) == [4, 5]  # the two newest


def test_blocks_follow_the_budget_and_the_chunks(store: Path) -> None:
    field = ReflectanceField.open(store)
    assert sample_block_size(field, 2 * CHUNK * BYTES_PER_SAMPLE + 5) == 2 * CHUNK
    assert sample_block_size(field, 300 * BYTES_PER_SAMPLE) == 300  # less than a chunk
    assert sample_block_size(field, 10**12) == 3000
    with pytest.raises(InputError, match="cannot hold one sample's radiance"):
        sample_block_size(field, BYTES_PER_SAMPLE - 1)


def test_a_fit_in_small_blocks_equals_the_fit_in_one(store: Path, whole_fit: SampleModels) -> None:
    field = ReflectanceField.open(store)
    blocks = fit_sample_models(field, memory_bytes=450 * BYTES_PER_SAMPLE)  # 7 blocks
    _assert_same_fit(whole_fit, blocks)


def test_a_missing_chunk_inside_a_slab_is_named(store: Path, tmp_path: Path) -> None:
    damaged = tmp_path / "torus.zarr"
    shutil.copytree(store, damaged)
    (damaged / "radiance" / "c" / "1" / "2" / "3" / "0").unlink()
    with pytest.raises(DatasetError, match=r"camera 1 light 2 sample block 3 \(radiance/c/1/2/3"):
        ReflectanceField.open(damaged)
    check = check_store(damaged)
    assert not check.ok and check.digest == "not checked" and check.chunks == 6 * 16 - 1


def test_rig_fit_saves_the_same_fit_beside_the_store(
    store: Path, whole_fit: SampleModels, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    target = tmp_path / "fit.npz"
    argv = ["fit", str(store), "--max-memory", str(1000 * BYTES_PER_SAMPLE), "-o", str(target),
            "--quiet"]  # fmt: skip
    assert main(argv) == 0
    assert "in blocks of 700 samples" in capsys.readouterr().err
    _assert_same_fit(whole_fit, read_sample_models(target, ReflectanceField.open(store)))


def test_rig_fit_refuses_a_budget_below_one_sample(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["fit", str(store), "--max-memory", "1K", "-o", str(tmp_path / "f.npz")]
    assert main(argv) == 2
    assert "cannot hold one sample's radiance" in capsys.readouterr().err
    assert not (tmp_path / "f.npz").exists()


def test_rig_fit_on_a_full_disk_keeps_the_old_fit_and_no_parts(store: Path, tmp_path: Path) -> None:
    # Its part files ended in an OSError traceback on a full disk (a real file size limit,
    # in a child: tests/full_disk.py); the fit already there stays.
    target = tmp_path / "fit.npz"
    target.write_bytes(b"the previous fit")
    done = run_limited([RIG, "fit", str(store), "-o", str(target), "--quiet"], limit=20_000)
    assert done.returncode == 2, done.stderr
    assert f"rig fit: error: {target}: cannot write: the file is larger" in done.stderr
    assert "Traceback" not in done.stderr
    assert target.read_bytes() == b"the previous fit"
    assert [p.name for p in tmp_path.iterdir()] == ["fit.npz"]


# --- on a Dask cluster ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def client() -> Iterator[Any]:
    with dask_client("local", workers=2, memory_limit=512 << 20, dashboard=False) as client:
        yield client


def test_a_local_cluster_gives_the_same_fit(
    store: Path, whole_fit: SampleModels, client: Any
) -> None:
    field = ReflectanceField.open(store)
    on_cluster = fit_sample_models(field, memory_bytes=CHUNK * BYTES_PER_SAMPLE, client=client)
    _assert_same_fit(whole_fit, on_cluster)


def test_a_worker_killed_mid_fit_is_replaced_and_the_fit_is_the_same(
    store: Path, whole_fit: SampleModels, client: Any
) -> None:
    field = ReflectanceField.open(store)
    fitted = kill_a_worker_mid_run(
        client, lambda: fit_sample_models(field, memory_bytes=100 * BYTES_PER_SAMPLE, client=client)
    )
    _assert_same_fit(whole_fit, fitted)


def test_a_subset_in_memory_cannot_go_to_the_cluster(store: Path, client: Any) -> None:
    part = ReflectanceField.open(store).subset(samples=np.arange(100))
    with pytest.raises(InputError, match="held in memory"):
        fit_sample_models(part, client=client)


def test_an_unreachable_scheduler_is_a_clear_error(
    store: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["fit", str(store), "--dask", "tcp://127.0.0.1:9", "--quiet"]) == 2
    assert "did not answer" in capsys.readouterr().err


def test_rig_fit_on_a_running_scheduler_and_worker(
    store: Path, whole_fit: SampleModels, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The --dask ADDRESS path against a real `dask scheduler` and `dask worker`."""
    import json
    import subprocess
    import sys

    dask = str(Path(sys.executable).with_name("dask"))
    info = tmp_path / "scheduler.json"
    scheduler = subprocess.Popen([dask, "scheduler", "--scheduler-file", str(info), "--port",
                                  "0", "--dashboard-address", ":0"])  # fmt: skip
    worker = None
    try:
        deadline = time.monotonic() + 60
        while not info.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        address = json.loads(info.read_text())["address"]
        worker = subprocess.Popen([dask, "worker", address, "--nworkers", "1", "--nthreads",
                                   "1", "--memory-limit", "512MiB"])  # fmt: skip
        target = tmp_path / "fit.npz"
        argv = ["fit", str(store), "--dask", address, "--max-memory",
                str(CHUNK * BYTES_PER_SAMPLE), "-o", str(target), "--quiet"]  # fmt: skip
        assert main(argv) == 0
        assert f"running on the Dask scheduler at {address}" in capsys.readouterr().err
        _assert_same_fit(whole_fit, read_sample_models(target, ReflectanceField.open(store)))
    finally:
        for process in (worker, scheduler):
            if process is not None:
                process.terminate()
                process.wait(timeout=30)


# --- a field of pixels (an RTI capture) ----------------------------------------------------


@pytest.fixture(scope="module")
def pixels(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An imported RTI capture: 40 x 30 pixels under 20 lights, a glossy bumpy relief."""
    from core.directions import hemisphere_layout
    from processing.rti import import_rti
    from sim.rti_capture import write_rti_capture

    tmp = tmp_path_factory.mktemp("pixels")
    lights = hemisphere_layout(20, "fibonacci")
    y, x = np.mgrid[0:30, 0:40] / 5.0
    normals = np.stack([0.5 * np.sin(x), 0.5 * np.cos(1.3 * y), np.ones_like(x)], axis=2)
    normals /= np.linalg.norm(normals, axis=2, keepdims=True)
    cosine = np.einsum("hwc,tc->thw", normals, lights)
    halfway = lights + np.array([0.0, 0.0, 1.0])
    halfway /= np.linalg.norm(halfway, axis=1, keepdims=True)
    lobe = np.clip(np.einsum("hwc,tc->thw", normals, halfway), 0.0, None) ** 40
    albedo = 0.3 + 0.2 * np.sin(x[:, :, None] * np.array([1.0, 1.7, 2.3]))
    images = albedo[None] * np.clip(cosine, 0.0, None)[..., None] + 0.3 * lobe[..., None]
    lp = write_rti_capture(tmp, "relief", images, lights, scale=0.8)
    return import_rti(lp, tmp / "relief.zarr").path


PIXEL_BYTES = 20 * 3 * 4  # float32 radiance of one pixel under 20 lights


@pytest.fixture(scope="module")
def whole_pixel_fit(pixels: Path) -> SampleModels:
    """Every model a pixel field has, every pixel in one block."""
    field = ReflectanceField.open(pixels)
    assert sample_block_size(field, 1200 * PIXEL_BYTES) == 1200
    return fit_sample_models(field, memory_bytes=1200 * PIXEL_BYTES)


def _assert_same_models(a: SampleModels, b: SampleModels) -> None:
    assert list(a.fits) == list(b.fits)
    for name, fit in a.fits.items():
        other = b.fits[name]
        assert type(fit) is type(other)
        if isinstance(fit, BasisFit) and isinstance(other, BasisFit):
            np.testing.assert_array_equal(fit.coefficients, other.coefficients, err_msg=name)
        else:
            for key in ("normals", "rho_d", "f0", "alpha", "lit", "fitted"):
                np.testing.assert_array_equal(getattr(fit, key), getattr(other, key),
                                              err_msg=f"{name} {key}")  # fmt: skip
        np.testing.assert_array_equal(fit.loo.squared_error, other.loo.squared_error)
        np.testing.assert_array_equal(fit.loo.energy, other.loo.energy)


def test_a_pixel_fit_in_blocks_equals_the_fit_in_one(
    pixels: Path, whole_pixel_fit: SampleModels, monkeypatch: pytest.MonkeyPatch
) -> None:
    import processing.sample_models.bases
    import processing.sample_models.stereo

    field = ReflectanceField.open(pixels)
    assert list(whole_pixel_fit.fits) == ["lambert", "lambert+ggx", "ptm", "hsh2", "hsh3"]
    # Blocks of 170 pixels (7 of them, the last short), and within a block the bases and
    # photometric stereo in chunks of 50: each pixel's fit is its own.
    monkeypatch.setattr(processing.sample_models.bases, "BASIS_CHUNK", 50)
    monkeypatch.setattr(processing.sample_models.stereo, "STEREO_CHUNK", 50)
    blocks = fit_sample_models(field, memory_bytes=170 * PIXEL_BYTES)
    _assert_same_models(whole_pixel_fit, blocks)


def test_a_streamed_fit_file_holds_the_fit_held_in_memory(
    pixels: Path, whole_pixel_fit: SampleModels, tmp_path: Path
) -> None:
    from processing.sample_model_store import fit_to_file, write_sample_models

    field = ReflectanceField.open(pixels)
    layout = fit_to_file(field, tmp_path / "streamed.npz", memory_bytes=170 * PIXEL_BYTES)
    assert layout.names == tuple(whole_pixel_fit.fits)
    write_sample_models(tmp_path / "held.npz", whole_pixel_fit, field)
    with np.load(tmp_path / "streamed.npz") as a, np.load(tmp_path / "held.npz") as b:
        assert sorted(a.files) == sorted(b.files)
        for key in a.files:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)
            assert a[key].dtype == b[key].dtype, key
    assert [p.name for p in tmp_path.iterdir()] != [] and not list(tmp_path.glob(".*parts"))
    _assert_same_models(whole_pixel_fit, read_sample_models(tmp_path / "streamed.npz", field))


def test_reading_some_models_reads_only_them(
    pixels: Path, whole_pixel_fit: SampleModels, tmp_path: Path
) -> None:
    from processing.sample_model_store import models_for_field, write_sample_models

    field = ReflectanceField.open(pixels)
    path = write_sample_models(tmp_path / "all.npz", whole_pixel_fit, field)
    some = read_sample_models(path, field, models=["hsh2", "lambert"])
    assert list(some.fits) == ["lambert", "hsh2"]  # in the file's order
    np.testing.assert_array_equal(
        some.fit("hsh2").coefficients,  # type: ignore[union-attr]
        whole_pixel_fit.fit("hsh2").coefficients,  # type: ignore[union-attr]
    )
    assert list(models_for_field(field, path, models=["ptm"]).fits) == ["ptm"]


def test_rig_fit_streams_a_pixel_field_in_blocks(
    pixels: Path, whole_pixel_fit: SampleModels, tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    target = tmp_path / "fit.npz"
    argv = ["fit", str(pixels), "--max-memory", str(300 * PIXEL_BYTES), "-o", str(target),
            "--quiet"]  # fmt: skip
    assert main(argv) == 0
    said = capsys.readouterr().err
    assert "fitting 1200 samples (1 cameras x 20 lights) in blocks of 300" in said
    _assert_same_models(whole_pixel_fit, read_sample_models(target, ReflectanceField.open(pixels)))


def test_a_pixel_field_streamed_from_a_cluster_is_the_same(
    pixels: Path, whole_pixel_fit: SampleModels, tmp_path: Path, client: Any
) -> None:
    from processing.sample_model_store import fit_to_file

    field = ReflectanceField.open(pixels)
    # Blocks finish in any order on a cluster: each is written at its own place.
    fit_to_file(field, tmp_path / "fit.npz", memory_bytes=100 * PIXEL_BYTES, client=client)
    _assert_same_models(whole_pixel_fit, read_sample_models(tmp_path / "fit.npz", field))


def test_too_few_lights_for_photometric_stereo_is_refused_before_any_block(
    pixels: Path,
) -> None:
    part = ReflectanceField.open(pixels).subset(lights=np.arange(3))
    with pytest.raises(InputError, match="photometric stereo needs at least 3 lights"):
        fit_sample_models(part, models=["lambert"])
    with pytest.raises(InputError, match="model 'hsh2' has 4 terms"):
        fit_sample_models(part, models=["hsh2"])

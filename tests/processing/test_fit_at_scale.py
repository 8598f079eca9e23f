"""Fitting at bounded memory, block by block, in-process and on a Dask cluster (issue 18)."""

from __future__ import annotations

import shutil
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from app.cli import main
from core.cluster import dask_client
from core.errors import DatasetError, InputError
from core.field_integrity import check_store
from core.field_store import ReflectanceField
from processing.sample_model_store import read_sample_models
from processing.sample_models import SampleModels, fit_sample_models, sample_block_size
from sim.field import field_cameras, simulate_field
from tests.cluster_faults import kill_a_worker_mid_run

CHUNK = 700  # samples per stored chunk: 3000 samples are 4 full chunks and a short one
BYTES_PER_SAMPLE = 6 * 16 * 3 * 4  # float32 radiance of one sample, 6 cameras x 16 lights


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

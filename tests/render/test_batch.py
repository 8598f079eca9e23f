"""Batch relighting, in-process and on a Dask cluster: the same frames, no partial store."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zarr

from app.cli import main
from core.camera_model import PinholeCamera
from core.cluster import dask_client
from core.errors import InputError
from core.sample_data import panorama_path
from render.batch import BatchPlan, read_batch_frames, relight_batch
from render.engines.interpolated import RelightSettings
from sim.field import field_cameras, simulate_field
from tests.cluster_faults import kill_a_worker_mid_run


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("batch") / "sphere.zarr"
    simulate_field(path, "glossy-sphere", lights=8, cameras=field_cameras(6, width=48,
                   height=48), points=3000)  # fmt: skip
    return path


def _plan(store: Path, environments: int = 2, frames: int = 3) -> BatchPlan:
    panoramas = [str(panorama_path(name)) for name in ("courtyard", "studio")]
    return BatchPlan(
        field=str(store), mode=RelightSettings.paper_configuration(k=16), models=None,
        panoramas=tuple(panoramas[i % 2] for i in range(environments)),
        camera=PinholeCamera(30.0, 50.0, 4.0, 40.0, 64, 48), sequence="turntable",
        frames=frames,
    )  # fmt: skip


@pytest.fixture(scope="module")
def in_process(store: Path, tmp_path_factory: pytest.TempPathFactory) -> NDArrayU8:
    out = relight_batch(_plan(store, 4), tmp_path_factory.mktemp("out") / "frames.zarr")
    frames = np.asarray(zarr.open_array(str(out / "frames"), mode="r")[:])
    assert frames.shape == (4, 3, 48, 64, 3) and frames.dtype == np.uint8
    assert frames.max() > 0
    return frames


NDArrayU8 = Any


def test_frames_are_the_sequence_of_each_environment(in_process: NDArrayU8) -> None:
    # environments 0 and 2 are the same panorama, 0 and 1 different ones
    np.testing.assert_array_equal(in_process[0], in_process[2])
    assert not np.array_equal(in_process[0], in_process[1])
    assert not np.array_equal(in_process[0, 0], in_process[0, 1])  # the turntable turns


@pytest.fixture(scope="module")
def client() -> Iterator[Any]:
    with dask_client("local", workers=2, memory_limit=768 << 20, dashboard=False) as client:
        yield client


def test_a_local_cluster_writes_the_same_frames(
    store: Path, in_process: NDArrayU8, client: Any, tmp_path: Path
) -> None:
    out = relight_batch(_plan(store, 4), tmp_path / "frames.zarr", client=client)
    assert [f for f in os.listdir(tmp_path) if "partial" in f] == []
    np.testing.assert_array_equal(np.asarray(zarr.open_array(str(out / "frames"))[:]), in_process)
    assert len(read_batch_frames(out, 1)) == 3


def test_a_worker_killed_mid_batch_leaves_a_complete_store(
    store: Path, in_process: NDArrayU8, client: Any, tmp_path: Path
) -> None:
    target = tmp_path / "frames.zarr"

    def nothing_under_the_real_name() -> None:
        assert not target.exists()

    kill_a_worker_mid_run(
        client, lambda: relight_batch(_plan(store, 4), target, client=client),
        nothing_under_the_real_name,
    )  # fmt: skip
    frames = np.asarray(zarr.open_array(str(target / "frames"))[:])
    np.testing.assert_array_equal(frames, in_process)


def test_a_failed_task_leaves_no_store(store: Path, tmp_path: Path) -> None:
    plan = _plan(store)
    broken = BatchPlan(**{**plan.__dict__, "panoramas": (plan.panoramas[0], "missing.exr")})
    with pytest.raises(InputError):
        relight_batch(broken, tmp_path / "frames.zarr")
    assert os.listdir(tmp_path) == []


def test_an_existing_output_and_a_model_mode_without_a_fit_are_refused(
    store: Path, tmp_path: Path
) -> None:
    (tmp_path / "frames.zarr").mkdir()
    with pytest.raises(InputError, match="exists"):
        relight_batch(_plan(store), tmp_path / "frames.zarr")
    from render.engines.modes import MOST_ACCURATE_MODELS

    with pytest.raises(InputError, match="saved fit"):
        BatchPlan(**{**_plan(store).__dict__, "mode": MOST_ACCURATE_MODELS})


def test_rig_batch_chooses_the_mode_fits_and_writes_gifs(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    field = tmp_path / "sphere.zarr"
    import shutil

    shutil.copytree(store, field)
    out = tmp_path / "batch.zarr"
    argv = ["batch", str(field), "--env", str(panorama_path("studio")), "--view", "20,40",
            "--size", "48x40", "--frames", "2", "--gif", "-o", str(out), "--quiet"]  # fmt: skip
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert "relighting mode:" in captured.err and "1 environments x 2 frames" in captured.out
    assert (field.parent / "sphere.zarr.models.npz").exists()
    assert (tmp_path / "batch" / "000-studio.gif").is_file()
    assert zarr.open_array(str(out / "frames")).shape == (1, 2, 40, 48, 3)
    assert main(argv) == 2  # the store is there now
    assert "exists" in capsys.readouterr().err
    no_view = ["batch", str(field), "--env", str(panorama_path("studio")), "-o",
               str(tmp_path / "x.zarr")]  # fmt: skip
    assert main(no_view) == 2
    assert "--view AZ,INCL is needed" in capsys.readouterr().err
    # --gif refuses, before any work, a folder that is a file and GIFs it would replace.
    gif = ["batch", str(field), "--env", str(panorama_path("studio")), "--view", "20,40",
           "--gif", "--quiet"]  # fmt: skip
    (tmp_path / "blocked").write_text("a file")
    assert main([*gif, "-o", str(tmp_path / "blocked.zarr")]) == 2
    assert "which is a file" in capsys.readouterr().err
    shutil.rmtree(out)
    before = (tmp_path / "batch" / "000-studio.gif").read_bytes()
    assert main([*gif, "-o", str(out)]) == 2
    assert "000-studio.gif: exists (--gif would replace it)" in capsys.readouterr().err
    assert (tmp_path / "batch" / "000-studio.gif").read_bytes() == before
    assert not out.exists()

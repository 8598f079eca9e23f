from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from core.errors import DatasetError, InputError
from core.field_store import ReflectanceField
from core.sample_data import rti_capture_path
from processing.rti import import_rti
from processing.sample_model_store import (
    StaleFitError,
    default_models_path,
    models_for_field,
    read_sample_models,
    write_sample_models,
)
from processing.sample_models import BasisFit, ParametricFit, SampleModels, fit_sample_models
from sim.field import field_cameras, simulate_field

RTI = rti_capture_path()


def _simulated(tmp: Path, name: str, points: int, scene: str = "glossy-sphere") -> ReflectanceField:
    path = tmp / f"{name}.zarr"
    simulate_field(
        path, scene, lights=8, cameras=field_cameras(4, width=32, height=32),
        points=points,
    )  # fmt: skip
    return ReflectanceField.open(path)


def _assert_same(a: SampleModels, b: SampleModels) -> None:
    assert (a.kind, a.sample_count, list(a.fits)) == (b.kind, b.sample_count, list(b.fits))
    np.testing.assert_array_equal(a.light_directions, b.light_directions)
    np.testing.assert_array_equal(a.camera_frame, b.camera_frame)
    for name, fit in a.fits.items():
        other = b.fits[name]
        np.testing.assert_array_equal(fit.loo.squared_error, other.loo.squared_error)
        if isinstance(fit, ParametricFit):
            assert isinstance(other, ParametricFit)
            assert fit.normals_fitted == other.normals_fitted
            for key in ("normals", "rho_d", "f0", "alpha", "lit", "fitted"):
                np.testing.assert_array_equal(getattr(fit, key), getattr(other, key))
        else:
            assert isinstance(fit, BasisFit) and isinstance(other, BasisFit)
            np.testing.assert_array_equal(fit.coefficients, other.coefficients)


def test_a_point_fit_round_trips(tmp_path: Path) -> None:
    field = _simulated(tmp_path, "a", 400)
    models = fit_sample_models(field)
    path = write_sample_models(tmp_path / "m.npz", models, field)
    loaded = read_sample_models(path, field)
    _assert_same(models, loaded)
    np.testing.assert_array_equal(models.points, loaded.points)
    assert loaded.view_direction is None and loaded.mark_directions is None


def test_a_pixel_fit_round_trips(tmp_path: Path) -> None:
    field = import_rti(RTI, tmp_path / "lion.zarr")
    models = fit_sample_models(field, ["lambert", "ptm"])
    loaded = read_sample_models(write_sample_models(tmp_path / "m.npz", models, field), field)
    _assert_same(models, loaded)
    assert loaded.points is None and loaded.view_direction is not None


def test_the_fit_is_saved_beside_the_field_and_reused(tmp_path: Path) -> None:
    field = _simulated(tmp_path, "b", 300)
    first = models_for_field(field)
    saved = default_models_path(field.path)
    assert saved == tmp_path / "b.zarr.models.npz" and saved.exists()
    stamp = saved.stat().st_mtime_ns
    _assert_same(first, models_for_field(field))
    assert saved.stat().st_mtime_ns == stamp  # read, not fitted again
    refit = models_for_field(field, models=["lambert"])  # held: no new fit
    assert saved.stat().st_mtime_ns == stamp and "lambert" in refit.fits


def test_a_fit_of_another_field_is_refused(tmp_path: Path) -> None:
    one, other = _simulated(tmp_path, "one", 300), _simulated(tmp_path, "other", 301)
    path = write_sample_models(tmp_path / "m.npz", fit_sample_models(one), one)
    with pytest.raises(DatasetError, match="shape"):
        read_sample_models(path, other)
    same_shape = _simulated(tmp_path, "same", 300)
    assert same_shape.shape == one.shape
    read_sample_models(path, same_shape)  # same scene and layout: the same field
    torus = _simulated(tmp_path, "torus", 300, "textured-torus")
    assert torus.shape == one.shape
    with pytest.raises(DatasetError, match="lights or points differ"):
        read_sample_models(path, torus)


@pytest.mark.parametrize("content", [b"not a zip", None])
def test_broken_files_are_named(tmp_path: Path, content: bytes | None) -> None:
    path = tmp_path / "m.npz"
    if content is None:
        np.savez(path, format=np.int64(99))
        message = "format"
    else:
        path.write_bytes(content)
        message = "not a readable models file"
    with pytest.raises(DatasetError, match=message) as error:
        read_sample_models(path)
    assert str(path) in str(error.value)


def test_a_fit_is_not_reused_for_other_data_of_the_same_geometry(tmp_path: Path) -> None:
    # A glossy store replaced by a diffuse scene of the same layout: shape, lights and points
    # all agree, only the data differ; the old glossy fit must not relight it.
    cameras = field_cameras(4, width=32, height=32)
    path = tmp_path / "f.zarr"
    simulate_field(path, "glossy-sphere", lights=8, cameras=cameras, points=400)
    glossy = models_for_field(ReflectanceField.open(path))
    kept = tmp_path / "kept.npz"
    write_sample_models(kept, glossy, ReflectanceField.open(path))
    with pytest.raises(InputError, match=r"already there.*--overwrite"):
        simulate_field(path, "diffuse-sphere", lights=8, cameras=cameras, points=400)
    simulate_field(path, "diffuse-sphere", lights=8, cameras=cameras, points=400, overwrite=True)
    assert not default_models_path(path).exists()  # what belonged to the old store went with it
    diffuse = ReflectanceField.open(path)
    with pytest.raises(StaleFitError, match="other data"):
        read_sample_models(kept, diffuse)
    with pytest.raises(StaleFitError):
        models_for_field(diffuse, kept)  # a file the caller named is refused, not replaced
    # Beside the store, a stale fit is simply fitted again.
    shutil.copy(kept, default_models_path(path))  # the glossy fit, planted beside the store
    refitted = models_for_field(diffuse)
    lobe = {name: m.fits["lambert+ggx"] for name, m in (("glossy", glossy), ("new", refitted))}
    assert isinstance(lobe["glossy"], ParametricFit) and isinstance(lobe["new"], ParametricFit)
    assert float(lobe["new"].f0.mean()) < 0.1 * float(lobe["glossy"].f0.mean())  # no lobe now
    assert read_sample_models(default_models_path(path), diffuse).sample_count == 400

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.camera_model import PinholeCamera
from core.directions import hemisphere_layout
from core.field_store import FieldStoreWriter, ReflectanceField
from processing.panorama import read_panorama
from processing.sample_model_store import default_models_path
from render.engines.interpolated import Relighter, RelightSettings
from render.engines.models import ModelRelighter, ModelRelightSettings
from render.engines.modes import MOST_ACCURATE_MODELS, most_accurate_mode, open_relighter
from sim.field import field_cameras, simulate_field


def test_a_glossy_field_is_relit_through_its_models(tmp_path: Path, courtyard_path: Path) -> None:
    path = tmp_path / "glossy.zarr"
    simulate_field(
        path, "glossy-sphere", lights=16, cameras=field_cameras(8, width=32, height=32),
        points=800,
    )  # fmt: skip
    field = ReflectanceField.open(path)
    choice = most_accurate_mode(field)
    assert choice.mode == MOST_ACCURATE_MODELS and choice.models is not None
    assert choice.comparison.model == "lambert+ggx"
    assert choice.comparison.model_error.relative_rmse < 0.05
    assert choice.comparison.interpolation_error.relative_rmse > 0.05
    assert "lambert+ggx" in choice.reason and default_models_path(path).exists()
    engine = open_relighter(field, choice.mode)  # reads the saved fit
    assert isinstance(engine, ModelRelighter)
    engine.set_lighting(read_panorama(courtyard_path))
    engine.set_view(PinholeCamera(10.0, 40.0, width=32, height=32))
    image = engine.render()
    assert image.coverage.mean() > 0.2 and np.all(image.rgb[image.coverage] > 0)


def test_a_field_the_models_cannot_explain_is_interpolated(tmp_path: Path) -> None:
    # Light that does not depend on the light direction (a glowing, translucent sample): no
    # BRDF times a cosine predicts it, interpolation does exactly.
    lights = hemisphere_layout(12)
    points = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0]], dtype=np.float32)
    normals = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]], dtype=np.float32)
    cameras = [PinholeCamera(az, 45.0, width=8, height=8) for az in (0.0, 120.0, 240.0)]
    writer = FieldStoreWriter(
        tmp_path / "glow.zarr", points=points, normals=normals, light_directions=lights,
        cameras=cameras,
    )  # fmt: skip
    for s in range(len(cameras)):
        for t in range(len(lights)):
            writer.write_slab(s, t, np.full((2, 3), 0.2, dtype=np.float32))
        writer.write_visibility(s, np.ones(2, dtype=bool))
    writer.finish()
    field = ReflectanceField.open(tmp_path / "glow.zarr")
    choice = most_accurate_mode(field)
    assert isinstance(choice.mode, RelightSettings) and choice.mode.scheme == "pixels"
    assert choice.comparison.interpolation_error.relative_rmse == pytest.approx(0.0, abs=1e-6)
    assert "interpolation" in choice.reason.split(" predicts")[0]
    assert isinstance(open_relighter(field, choice.mode), Relighter)


def test_model_settings_open_a_model_engine(tmp_path: Path) -> None:
    path = tmp_path / "d.zarr"
    simulate_field(
        path, "diffuse-sphere", lights=8, cameras=field_cameras(4, width=24, height=24),
        points=300,
    )  # fmt: skip
    field = ReflectanceField.open(path)
    engine = open_relighter(field, ModelRelightSettings(model="lambert", k=16))
    assert isinstance(engine, ModelRelighter) and engine.choice.chosen == "lambert"

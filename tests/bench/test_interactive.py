from __future__ import annotations

from pathlib import Path

import pytest

from bench.suite.product import bench_loop, interactive_record, interactive_variant
from core.field_store import ReflectanceField
from processing.sample_model_store import models_for_field
from render.engines.interpolated import RelightSettings
from render.engines.models import ModelRelightSettings
from sim.field import field_cameras, simulate_field


def test_the_loop_reports_every_mode_with_its_error_against_the_exact_reference(
    tmp_path: Path,
) -> None:
    path = tmp_path / "glossy.zarr"
    simulate_field(
        path, "glossy-sphere", lights=12, cameras=field_cameras(8, width=48, height=48),
        points=1500,
    )  # fmt: skip
    field = ReflectanceField.open(path)
    loop = bench_loop("glossy-sphere", (8, 12, 1500, 48), field, models_for_field(field),
                      repeats=2, bandwidth=1e10)  # fmt: skip
    record = interactive_record(loop)
    assert {"paper", "default", "models, precomputed"} <= set(record)
    for figures in record.values():
        assert figures["new_lighting_ms"] > 0 and figures["new_view_ms"] > 0
        assert figures["points"] == 1500
    # The default (the models under the exact 64-row grid) is its own reference; the
    # precomputed variant approximates it (split sum, harmonics), the paper samples K lights.
    assert record["default"]["settings"]["lighting"] == "grid"
    assert record["default"]["error_vs_reference"] == 0.0
    assert 0.0 < record["models, precomputed"]["error_vs_reference"] < 0.15
    assert 0.0 < record["paper"]["error_vs_reference"]


@pytest.mark.parametrize(
    ("mode", "lighting"),
    [
        (ModelRelightSettings(model="lambert", lighting="grid"), "precomputed"),
        (RelightSettings(), "precomputed"),
    ],
)
def test_the_interactive_variant_keeps_the_model(mode: object, lighting: str) -> None:
    variant = interactive_variant(mode)  # type: ignore[arg-type]
    assert variant.lighting == lighting
    assert variant.model == (mode.model if isinstance(mode, ModelRelightSettings) else "auto")

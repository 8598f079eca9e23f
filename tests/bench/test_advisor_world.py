"""rig advise against a path-traced truth, on a tiny world field."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bench.advisor_world import PANORAMA_HEIGHT, main, ratio_summary, world_truths
from core.errors import InputError
from core.field_store import ReflectanceField
from core.sample_data import panorama_path
from processing.panorama import downsample_panorama, panorama_from_array, read_panorama
from sim.field import field_cameras, simulate_field
from sim.world.mitsuba import render_world_field


def test_the_truth_is_the_world_seen_like_its_field(tmp_path: Path) -> None:
    views = field_cameras(4, width=24, height=24)
    path = render_world_field(tmp_path / "w.zarr", "matte-relief", lights=8, cameras=views,
                              points=300, spp=16, layout="fibonacci")  # fmt: skip
    field = ReflectanceField.open(path)
    rgb = downsample_panorama(read_panorama(panorama_path("courtyard")).rgb, PANORAMA_HEIGHT)
    truths = world_truths(field, {"c": panorama_from_array(rgb)}, {"v": views[1]}, spp=16)
    radiance, seen = truths[("c", "v")]
    # The same samples, seen by the same camera as the field's own slabs.
    np.testing.assert_array_equal(seen, field.visibility[1])
    assert radiance.shape == (300, 3) and np.all(radiance[seen] > 0) and not radiance[~seen].any()
    out = tmp_path / "out"
    assert main(["-o", str(out), "--field", str(path), "--spp", "16", "--samples", "300"]) == 0
    text = (out / "advisor_world.md").read_text()
    assert "## The advisor: predicted against true error" in text
    assert "within 1.5x either way" in text


def test_only_a_path_traced_field_is_taken(tmp_path: Path) -> None:
    simulate_field(tmp_path / "s.zarr", "diffuse-sphere", lights=4,
                   cameras=field_cameras(2, width=8, height=8), points=50)  # fmt: skip
    field = ReflectanceField.open(tmp_path / "s.zarr")
    with pytest.raises(InputError, match="not a path-traced world field"):
        world_truths(field, {}, {}, spp=4)


def test_the_ratio_summary_counts_predictions_within_the_factor() -> None:
    rows = [{"predicted": p, "true": {"captured": t, "between": t}}
            for p, t in ((0.1, 0.1), (0.2, 0.1), (0.05, 0.1), (0.14, 0.1))]  # fmt: skip
    assert ratio_summary(rows).endswith("within 1.5x either way: 50%")

"""bench.stability's pieces on a tiny field: the method table, the changed captures, the LDR
panorama, the missing-pose case and the report table (the study itself is not run here; its
cases are measured in tests/render/test_stability.py)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bench import stability
from bench.stability import (
    METHODS,
    SKY_HEIGHT,
    Sizes,
    energy_matched_ldr,
    format_stability,
    in_memory,
    sensor_field,
)
from core.colour import luminance
from core.directions import panorama_solid_angles
from core.field_store import ReflectanceField
from render.engines.interpolated import RelightSettings, best_settings
from render.engines.modes import MOST_ACCURATE_MODELS
from sim.skies import procedural_sky

TINY = Sizes(points=200, image=16)


@pytest.fixture(scope="module")
def out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("stability")


@pytest.fixture(scope="module")
def field(out: Path) -> ReflectanceField:
    return stability._field(out, "diffuse-sphere", 2, 4, TINY)


def _energy(rgb: Any) -> float:
    image = np.asarray(rgb, dtype=np.float32)
    return float(np.sum(luminance(image) * panorama_solid_angles(*image.shape[:2])))


# -- the fields ---------------------------------------------------------------------------------


def test_fields_are_simulated_once_under_a_descriptive_name(
    out: Path, field: ReflectanceField
) -> None:
    path = out / "fields" / "diffuse-sphere-S2-T4-200-16px.zarr"
    assert field.path == path and path.is_dir()
    assert field.shape == (2, 4, 200)
    assert [(c.width, c.height) for c in field.cameras] == [(16, 16), (16, 16)]
    stamp = {p: p.stat().st_mtime_ns for p in path.rglob("*")}
    again = stability._field(out, "diffuse-sphere", 2, 4, TINY)  # reused, not simulated again
    assert again.path == path
    assert {p: p.stat().st_mtime_ns for p in path.rglob("*")} == stamp
    np.testing.assert_array_equal(again.load(), field.load())


def test_in_memory_holds_other_radiance_under_its_own_path(field: ReflectanceField) -> None:
    original = field.load().copy()
    doubled = in_memory(field, original.astype(np.float64) * 2.0)
    assert doubled.path.name == "diffuse-sphere-S2-T4-200-16px.zarr[changed]"
    assert doubled.path.parent == field.path.parent and not doubled.path.exists()
    assert doubled.shape == field.shape
    loaded = doubled.load()
    assert loaded.dtype == np.float32
    np.testing.assert_array_equal(loaded, original * 2.0)
    np.testing.assert_array_equal(field.load(), original)  # the store is untouched
    np.testing.assert_array_equal(doubled.visibility, field.visibility)


def _visible(field: ReflectanceField) -> Any:
    return np.broadcast_to(field.visibility[:, None, :, None], field.load().shape)


def test_a_saturated_sensor_clips_at_the_full_well(field: ReflectanceField) -> None:
    radiance = field.load().astype(np.float64)
    visible = _visible(field)
    top = float(np.percentile(radiance[visible], 99.9))
    captured = sensor_field(field, 3.0).load()
    assert captured.shape == radiance.shape and captured.dtype == np.float32
    assert np.all(captured[~visible] == 0.0)
    # The 99.9th percentile at 3x the full well: everything above a third of it clips there.
    ceiling = top / 3.0
    assert float(captured.max()) == pytest.approx(ceiling, rel=1e-5)
    clipped = radiance[visible] > 1.05 * ceiling
    assert clipped.mean() > 0.05
    np.testing.assert_allclose(captured[visible][clipped], ceiling, rtol=1e-5)


def test_a_well_exposed_sensor_reads_the_radiance_back(field: ReflectanceField) -> None:
    radiance = field.load().astype(np.float64)
    visible = _visible(field)
    top = float(np.percentile(radiance[visible], 99.9))
    captured = sensor_field(field, 0.8).load().astype(np.float64)
    bright = visible & (radiance > 0.1 * top)
    relative = np.abs(captured[bright] - radiance[bright]) / radiance[bright]
    assert np.median(relative) < 0.03
    assert float(captured.max()) < top / 0.8  # nothing reaches the ceiling
    # A far too short exposure: photon and read noise dominate.
    starved = sensor_field(field, 0.002).load().astype(np.float64)
    assert np.median(np.abs(starved[bright] - radiance[bright]) / radiance[bright]) > 0.1


def test_the_sensor_noise_is_deterministic_for_a_seed(field: ReflectanceField) -> None:
    first = sensor_field(field, 0.8, seed=3).load()
    np.testing.assert_array_equal(sensor_field(field, 0.8, seed=3).load(), first)
    assert not np.array_equal(sensor_field(field, 0.8, seed=4).load(), first)


# -- the methods and the panoramas --------------------------------------------------------------


def test_the_three_methods_compared(field: ReflectanceField) -> None:
    assert list(METHODS) == ["best interpolation", "paper", "models"]
    assert METHODS["best interpolation"](field) == best_settings(field)
    paper = METHODS["paper"](field)
    assert paper == RelightSettings.paper_configuration(64)
    assert isinstance(paper, RelightSettings) and paper.paper and paper.k == 64
    assert METHODS["models"](field) is MOST_ACCURATE_MODELS


def test_the_test_skies() -> None:
    sun, no_sun = stability._sky(0.9), stability._sky(0.0)
    assert SKY_HEIGHT == 64
    assert sun.shape == no_sun.shape == (64, 128, 3) and sun.dtype == np.float32
    # With 90 % of the light in the sun the rest carries a tenth of the total.
    assert _energy(sun) * 0.1 == pytest.approx(_energy(no_sun), rel=0.02)


def test_the_ldr_panorama_keeps_the_total_light_and_loses_the_sun() -> None:
    sky = procedural_sky(32, sun_share=0.9)
    ldr = energy_matched_ldr(sky)
    assert ldr.shape == sky.shape and ldr.dtype == np.float32
    assert _energy(ldr) == pytest.approx(_energy(sky), rel=1e-5)
    assert float(ldr.max()) < 0.05 * float(sky.max())  # the sun is clipped
    # An 8-bit photo: at most 256 levels per channel.
    for channel in range(3):
        assert np.unique(ldr[:, :, channel]).size <= 256


def test_an_ldr_photo_of_a_uniform_panorama_is_the_panorama() -> None:
    uniform = np.full((16, 32, 3), 0.5, np.float32)
    np.testing.assert_allclose(energy_matched_ldr(uniform), 0.5, rtol=1e-5)


# -- the missing pose, the rows and the report --------------------------------------------------


def test_a_missing_camera_pose_is_refused_by_processing(out: Path) -> None:
    expected = [
        {"configuration": "camera pose complete", "outcome": "—"},
        {
            "configuration": "camera pose missing",
            "outcome": "DatasetError: images/light_c1_l0_e0.png: the measured pose has no "
            "camera_azimuth_deg",
        },
    ]
    assert stability._missing_pose(out) == expected
    assert stability._missing_pose(out) == expected  # a second run replaces the dataset


def _row(method: str, error: float, warnings: list[str]) -> dict[str, Any]:
    return {
        "method": method,
        "relative_rmse": error,
        "sample_relative_rmse": error,
        "warnings": warnings,
        "messages": [f"about {w}" for w in warnings],
    }


def test_case_rows_carry_their_case_and_are_printed(capsys: pytest.CaptureFixture[str]) -> None:
    results: list[dict[str, Any]] = []
    rows = [_row("paper", 0.1234, ["sun-ghosting", "grazing-view"]), _row("models", 0.01, [])]
    stability._case(results, "sun, glossy", "T=30, captured view", True, rows)
    assert results == [
        {"case": "sun, glossy", "configuration": "T=30, captured view", "failing": True} | row
        for row in rows
    ]
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2
    assert lines[0].split() == [*"T=30, captured view".split(), "paper", "12.34%",
                                "sun-ghosting,", "grazing-view"]  # fmt: skip
    assert lines[1].split()[-2:] == ["1.00%", "—"]


def test_format_stability_writes_the_markdown_table() -> None:
    results = {
        "sizes": {"points": 2000, "image": 64},
        "rows": [
            {"case": "LDR panorama", "configuration": "8-bit photo", "failing": True}
            | _row("paper", 0.41237, ["clipped-panorama"]),
            {"case": "LDR panorama", "configuration": "HDR", "failing": False}
            | _row("models", 0.004, []),
        ],
        "missing_pose": [{"configuration": "camera pose missing", "outcome": "DatasetError: x"}],
    }
    assert format_stability(json.loads(json.dumps(results))) == (
        "Relative RMSE against the simulator's ground truth (2000 points, 64 px images); "
        "warnings as `rig relight` gives them.\n"
        "\n"
        "| case | configuration | method | error | warning |\n"
        "|---|---|---|---|---|\n"
        "| LDR panorama | 8-bit photo | paper | 41.24% | clipped-panorama |\n"
        "| LDR panorama | HDR (benign) | models | 0.40% | — |\n"
        "| missing camera pose | camera pose missing | processing | - | DatasetError: x |\n"
    )
    del results["missing_pose"]  # optional
    assert format_stability(results).count("\n") == 6

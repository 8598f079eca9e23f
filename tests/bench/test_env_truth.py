"""The pure parts of bench/env_truth.py and its report: the light-stage sum, the scores, the report.

No renders: the sum is checked on synthetic captures whose relit answer is known.
"""

from __future__ import annotations

import subprocess

import numpy as np
import pytest

from bench.env_truth import RIG, light_stage_sum, relative_rmse, scores
from bench.env_truth_report import CLI_METHODS, SUM_FULL, SUM_UPPER, Score, format_tables
from core.directions import hemisphere_layout

ALBEDO = np.array([0.8, 0.5, 0.2])


def lambertian_capture(directions: np.ndarray) -> np.ndarray:
    """A 2 x 3 image of a horizontal Lambertian surface per light: albedo / pi max(cos, 0)."""
    cosine = np.clip(directions[:, 2], 0.0, None)
    return np.broadcast_to(
        (ALBEDO / np.pi)[None, None, None, :] * cosine[:, None, None, None],
        (len(directions), 2, 3, 3),
    ).copy()


def test_one_light_takes_the_whole_panorama() -> None:
    # One light at the zenith: its cell is the whole sphere (4 pi sr), or the upper half (2 pi).
    zenith = np.array([[0.0, 0.0, 1.0]])
    sky = np.full((16, 32, 3), 2.0)
    images = lambertian_capture(zenith)
    full = light_stage_sum(images, zenith, sky)
    upper = light_stage_sum(images, zenith, sky, upper_only=True)
    np.testing.assert_allclose(full, np.broadcast_to(ALBEDO / np.pi * 2.0 * 4 * np.pi, full.shape))
    np.testing.assert_allclose(upper, np.broadcast_to(ALBEDO / np.pi * 2.0 * 2 * np.pi, full.shape))


def test_a_dense_dome_relights_a_lambertian_surface_under_a_white_sky_to_its_albedo() -> None:
    # Radiance 1 over the upper hemisphere: a Lambertian surface facing up reflects its albedo.
    directions = hemisphere_layout(400, "fibonacci")
    sky = np.ones((64, 128, 3))
    relit = light_stage_sum(lambertian_capture(directions), directions, sky, upper_only=True)
    np.testing.assert_allclose(relit, np.broadcast_to(ALBEDO, relit.shape), rtol=0.01)


def test_each_panorama_pixel_goes_to_its_nearest_light() -> None:
    # Light only in the +x half of the sky: all of it to the light at +x, none to the one at -x.
    lights = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    rows, cols = 8, 16
    sky = np.zeros((rows, cols, 3))
    sky[:, cols // 4 : 3 * cols // 4] = 1.0  # the middle half of the columns faces +x
    images = np.zeros((2, 1, 1, 3))
    images[0], images[1] = 1.0, 100.0
    relit = light_stage_sum(images, lights, sky)
    np.testing.assert_allclose(relit, 2.0 * np.pi, rtol=1e-9)  # half the sphere, radiance 1


def test_relative_rmse_and_scores() -> None:
    truth = np.ones((4, 4, 3))
    truth[:2] = 2.0
    pred = 1.1 * truth
    everything = np.ones((4, 4), dtype=bool)
    assert relative_rmse(pred, truth, everything) == pytest.approx(0.1)
    assert relative_rmse(pred, truth, np.zeros((4, 4), dtype=bool)) is None
    top = np.zeros((4, 4), dtype=bool)
    top[:2] = True
    result = scores(pred, truth, top, ~top, 0.5)
    assert result["rel_rmse_object"] == pytest.approx(0.1)
    assert result["ratio"] == pytest.approx(1.1) and result["ratio_base"] == pytest.approx(1.1)
    assert result["seconds"] == 0.5 and result["error"] == ""


def score(value: float | None, error: str = "") -> Score:
    return {"rel_rmse": value, "rel_rmse_object": value, "rel_rmse_base": value, "ratio": 1.0,
            "ratio_object": 1.0, "ratio_base": 1.0, "seconds": 1.0, "error": error,
            "note": ""}  # fmt: skip


def test_the_report_lists_every_method_beside_the_sums() -> None:
    methods = {SUM_FULL: score(0.2), SUM_UPPER: score(0.05)}
    methods |= {label: score(0.1) for label, _ in CLI_METHODS}
    failed = dict(methods)
    failed[CLI_METHODS[0][0]] = score(None, "exit 1: boom")
    records = {"scene": {"49": {"white": methods, "courtyard": failed}}}
    text = format_tables(records)
    assert "## Relative RMSE, mean over panoramas" in text
    row = next(line for line in text.splitlines() if f"| {CLI_METHODS[1][0]} |" in line)
    # The method's mean (10 %), then the two sums' means beside it.
    assert row.startswith("| scene | 49 |") and row.endswith("| 20.0 % | 5.0 % |")
    assert "10.0 %" in row
    failed_row = next(line for line in text.splitlines() if f"| {CLI_METHODS[0][0]} |" in line)
    assert "failed" in failed_row
    assert f"- scene 49 courtyard {CLI_METHODS[0][0]}: exit 1: boom" in text
    assert "## White sky: base brightness pred / truth" in text


def test_the_command_line_variants_use_flags_rig_relight_has() -> None:
    labels = [label for label, _ in CLI_METHODS]
    assert len(set(labels)) == len(labels)
    usage = subprocess.run([str(RIG), "relight", "--help"], capture_output=True, text=True,
                           check=True).stdout  # fmt: skip
    for _, flags in CLI_METHODS:
        for flag in flags:
            if flag.startswith("-"):
                assert flag in usage, flag

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

from app.cli.plan import add_plan, format_duration
from capture.plan_file import load_plan
from core.errors import InputError
from rig.config import simulated_config

PLAN = """
exposures_ms = [10, 40]
[cameras]
azimuth_deg = {start = 0, stop = 360, step = 90}
inclination_deg = [30, 60]
[lights]
layout = "grid"
count = 12
"""


def _run(tmp_path: Path, plan_text: str, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    config = tmp_path / "rig.toml"
    config.write_text(simulated_config("/dev/ttyS1", "/dev/ttyS2").to_toml(), encoding="utf-8")
    plan = tmp_path / "plan.toml"
    plan.write_text(plan_text, encoding="utf-8")
    parser = argparse.ArgumentParser()
    add_plan(parser.add_subparsers())
    args = parser.parse_args(["plan", "--config", str(config), "--plan", str(plan)])
    status = args.handler(args)
    return status, capsys.readouterr().out


def test_plan_prints_counts_duration_gain_and_limits(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    status, out = _run(tmp_path, PLAN, capsys)
    assert status == 0
    plan = load_plan(tmp_path / "plan.toml")
    config = simulated_config("/dev/ttyS1", "/dev/ttyS2")
    estimate = plan.estimate(config)
    skipped = plan.skipped(config)
    images = estimate.images
    assert "cameras: 8   lights: 12   exposures: 2 (10, 40 ms)   dark frames: yes" in out
    assert (
        f"images: {estimate.total_images} (light {images['light']}, dark 16, calibration 0)" in out
    )
    assert f"skipped pairs: {len(skipped)}\n" in out
    for c, t, reason in skipped:
        assert f"  camera {c}, light {t}: {reason}\n" in out
    duration = re.search(
        r"estimated duration: (.+) = motion ([\d.]+) s \+ exposure ([\d.]+) s", out
    )
    assert duration is not None
    assert duration.group(1) == format_duration(estimate.total_s)
    assert float(duration.group(2)) == pytest.approx(estimate.motion_s, abs=0.05)
    assert float(duration.group(3)) == pytest.approx(estimate.exposure_s, abs=0.05)
    assert "(0.5 s per image)" in out
    assert f"the optimised order saves {estimate.gain_s:.1f} s" in out
    assert estimate.gain_s > 0
    limits = [line for line in out.splitlines() if line.startswith("  ") and "limits" in line]
    assert [line.split()[0] for line in limits] == [
        "camera_azimuth",
        "camera_inclination",
        "light_azimuth",
        "light_inclination",
    ]
    assert all(line.endswith("OK") for line in limits)
    assert "camera_azimuth      plan 0 .. 270 deg   limits 0 .. 359 deg   OK" in out
    assert out.rstrip().endswith("the plan is runnable (nothing was moved)")


def test_out_of_limit_plan_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = PLAN.replace("{start = 0, stop = 360, step = 90}", "[-20, 90, 370]")
    status, out = _run(tmp_path, text, capsys)
    assert status == 2
    assert "camera_azimuth      plan -20 .. 370 deg   limits 0 .. 359 deg   VIOLATION" in out
    assert "camera_inclination  plan 30 .. 60 deg   limits 0 .. 90 deg   OK" in out
    assert "camera 0, light 0: camera_azimuth_deg = -20 is below axes.camera_azimuth.min_deg" in out
    assert "the plan is not runnable: a camera or light pose lies outside the limits" in out


def test_bad_plan_file_is_an_input_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(InputError, match=r"plan\.toml: exposures_ms\[0\] = -1 must be positive"):
        _run(tmp_path, PLAN.replace("[10, 40]", "[-1]"), capsys)


def test_format_duration() -> None:
    assert format_duration(12.34) == "12.3 s"
    assert format_duration(245.0) == "4 min 05 s"
    assert format_duration(3723.4) == "1 h 02 min 03 s"

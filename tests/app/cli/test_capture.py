"""``rig capture --config``: a capture drives the devices its config names."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.cli import main
from capture.dataset import Dataset
from sim.simulated_rig import SimulatedRig, simulated_capture_config

PLAN = """
exposures_ms = [20.0]
dark_frames = false
[cameras]
azimuth_deg = [0, 90]
inclination_deg = [60]
[lights]
layout = "fibonacci"
count = 3
"""


def test_a_simulated_camera_capture_drives_the_configs_own_ports(tmp_path: Path) -> None:
    # The emulators stand for devices started elsewhere (`rig sim start`, or real
    # controllers): the capture must move them, not emulators of its own.
    config = simulated_capture_config("glossy-sphere", size=32, points=500, speed=20.0)
    with SimulatedRig(config) as simulated:
        (tmp_path / "rig.toml").write_text(simulated.config.to_toml(), encoding="utf-8")
        (tmp_path / "plan.toml").write_text(PLAN, encoding="utf-8")
        moves_before = sum("G1" in line for line in simulated.gantry.lines)
        argv = ["capture", "--config", str(tmp_path / "rig.toml"), "--plan",
                str(tmp_path / "plan.toml"), "--quiet", "-o", str(tmp_path / "d")]  # fmt: skip
        assert main(argv) == 0
        assert sum("G1" in line for line in simulated.gantry.lines) > moves_before
    dataset = Dataset.open(tmp_path / "d")
    assert dataset.rig_config["gantry"]["port"] == simulated.config.gantry.port  # type: ignore[union-attr]
    assert dataset.verify().complete


def test_a_config_mixing_in_process_and_real_ports_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = simulated_capture_config("glossy-sphere", size=32, points=500)
    with SimulatedRig(config) as simulated:
        text = simulated.config.to_toml().replace(
            simulated.config.servos.port,  # type: ignore[union-attr]
            "/dev/null",
        )
    (tmp_path / "rig.toml").write_text(text, encoding="utf-8")
    (tmp_path / "plan.toml").write_text(PLAN, encoding="utf-8")
    argv = ["capture", "--config", str(tmp_path / "rig.toml"), "--plan",
            str(tmp_path / "plan.toml"), "--quiet", "-o", str(tmp_path / "d")]  # fmt: skip
    assert main(argv) == 2
    assert "name every device's port" in capsys.readouterr().err


def test_a_plan_outside_the_limits_is_refused_before_anything_moves(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # `rig plan` calls this plan not runnable; a capture used to leave the camera out.
    config = simulated_capture_config("glossy-sphere", size=32, points=500, speed=20.0)
    with SimulatedRig(config) as simulated:
        (tmp_path / "rig.toml").write_text(simulated.config.to_toml(), encoding="utf-8")
        (tmp_path / "plan.toml").write_text(PLAN.replace("[0, 90]", "[0, 370]"), encoding="utf-8")
        moves_before = sum("G1" in line for line in simulated.gantry.lines)
        argv = ["capture", "--config", str(tmp_path / "rig.toml"), "--plan",
                str(tmp_path / "plan.toml"), "--quiet", "-o", str(tmp_path / "d")]  # fmt: skip
        assert main(argv) == 2
        assert sum("G1" in line for line in simulated.gantry.lines) == moves_before
    err = capsys.readouterr().err
    assert "camera_azimuth uses 0 .. 370 deg, limits 0 .. 359 deg" in err
    assert not (tmp_path / "d").exists()

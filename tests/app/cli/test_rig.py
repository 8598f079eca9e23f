from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from app.cli import main
from rig.config import load_config


def _start(tmp_path: Path) -> tuple[subprocess.Popen[str], Path]:
    config = tmp_path / "sim.toml"
    process = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "sim", "start", "--write-config", str(config)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    deadline = time.monotonic() + 60
    while not config.exists():
        if process.poll() is not None or time.monotonic() > deadline:
            process.kill()
            raise AssertionError(f"rig sim start did not write its config: {process.stdout}")
        time.sleep(0.1)
    return process, config


def test_sim_start_serves_a_config_that_doctor_passes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    process, config = _start(tmp_path)
    try:
        ports = (load_config(config).servos.port, load_config(config).gantry.port)  # type: ignore[union-attr]
        assert all(os.path.exists(port) for port in ports)
        assert main(["doctor", "--config", str(config)]) == 0
        report = capsys.readouterr().out
        for row in ("axis camera_azimuth", "axis light_inclination", "light (spindle)", "camera"):
            assert row in report
        assert "FAILED" not in report
    finally:
        process.send_signal(signal.SIGTERM)
        output, _ = process.communicate(timeout=30)
    assert process.returncode == 0 and "simulated rig stopped" in output
    assert all(port in output for port in ports)


def test_doctor_names_a_missing_device(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    process, config = _start(tmp_path)
    process.send_signal(signal.SIGTERM)  # the emulators go away; the config stays
    process.communicate(timeout=30)
    assert main(["doctor", "--config", str(config)]) == 1
    report = capsys.readouterr().out
    port = load_config(config).gantry.port  # type: ignore[union-attr]
    assert "FAILED" in report and port in report


def test_doctor_passes_on_a_busy_machine(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The emulators run in their own process, as with `rig sim start` beside a loaded machine
    # (load average above 8 on 2 cores): their replies come late, as a real servo's never
    # would, and the drivers must wait longer on each retry rather than fail.
    process, config = _start(tmp_path)
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(16)]
    try:
        time.sleep(1.0)
        status = main(["doctor", "--config", str(config)])
        report = capsys.readouterr().out
    finally:
        for burner in burners:
            burner.kill()
        for burner in burners:
            burner.wait()
        process.send_signal(signal.SIGTERM)
        process.communicate(timeout=60)
    assert status == 0, report
    assert "FAILED" not in report

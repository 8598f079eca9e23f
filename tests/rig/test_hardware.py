from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterator

import numpy as np
import pytest

from core.errors import DeviceError, SafetyError
from rig.config import simulated_config
from rig.hardware import LightGantry, servo_axis
from rig.pose import RigPose
from sim.dynamixel.faults import FaultConfig
from sim.grbl.emulator import GrblEmulator, GrblFaults
from sim.simulated_rig import SimulatedRig


@pytest.fixture()
def simulated() -> Iterator[SimulatedRig]:
    with SimulatedRig() as rig:
        yield rig


def test_the_rig_moves_every_axis_together(simulated: SimulatedRig) -> None:
    with simulated.rig(camera=False) as rig:
        start = rig.pose()
        assert start.camera_inclination_deg == pytest.approx(
            simulated.config.park.camera_inclination_deg, abs=0.1
        )
        target = RigPose(90.0, 30.0, 200.0, 60.0)
        reached = rig.move_to(target)
        assert reached is not None
        for (role, want), (_, got) in zip(target.items(), reached.items(), strict=True):
            assert got == pytest.approx(want, abs=0.3), role
        x, y, _ = simulated.gantry.machine_position()
        assert (x, y) == pytest.approx((200.0, 60.0), abs=0.01)


def test_unsafe_poses_are_refused_before_any_byte(simulated: SimulatedRig) -> None:
    with simulated.rig(camera=False) as rig:
        assert simulated.servos is not None
        before = simulated.servos.bytes_received, len(simulated.gantry.lines)
        with pytest.raises(SafetyError, match="camera_inclination"):
            rig.move_to(RigPose(0.0, 120.0, 180.0, 45.0))
        with pytest.raises(SafetyError, match="separation"):
            rig.move_to(RigPose(0.0, 45.0, 0.0, 45.0))  # the light behind the camera
        # Reading the pose talks to the devices; no motion command was sent.
        assert simulated.servos.goal_writes(1) == 0 and simulated.servos.goal_writes(2) == 0
        assert not any("G1" in line for line in simulated.gantry.lines[before[1] :])


def test_the_light_and_the_camera_see_the_rig(simulated: SimulatedRig) -> None:
    with simulated.rig() as rig:
        rig.move_to(RigPose(0.0, 40.0, 90.0, 40.0))
        dark = rig.capture(20.0)
        rig.light_on(0.5)
        assert simulated.gantry.light.on and simulated.gantry.light.intensity == pytest.approx(0.5)
        lit = rig.capture(20.0)
        assert lit.pixels is not None and dark.pixels is not None
        assert lit.pixels.astype(float).mean() > dark.pixels.astype(float).mean() + 1.0
        again = rig.capture(20.0)
        assert again.pixels is not None and np.array_equal(again.pixels, lit.pixels)
    assert not simulated.gantry.light.on  # leaving the rig switched it off


def test_leaving_on_an_error_stops_everything(simulated: SimulatedRig) -> None:
    with pytest.raises(RuntimeError), simulated.rig(camera=False) as rig:
        rig.light_on()
        rig.move_to(RigPose(120.0, 80.0, 300.0, 10.0), wait=False)
        raise RuntimeError("operator pressed stop")
    assert not simulated.gantry.light.on
    assert simulated.servos is not None
    assert simulated.servos.register(1, 64, 1) == 0  # torque off


def test_a_servo_that_stops_answering_is_named() -> None:
    faults = FaultConfig(silent_ids=frozenset({2}), silent_after=40)
    with SimulatedRig(servo_faults=faults) as simulated:
        with (
            pytest.raises(DeviceError, match="servo 2") as error,
            simulated.rig(camera=False) as rig,
        ):
            for azimuth in range(10, 300, 10):
                rig.move_to(RigPose(float(azimuth), 45.0, 180.0, 45.0))
        # Closing could not switch the silent servo's torque off: said, not hidden.
        assert any("torque" in note for note in getattr(error.value, "__notes__", []))


def test_a_gantry_alarm_mid_move_is_reported() -> None:
    with SimulatedRig(gantry_faults=GrblFaults(hard_limit_after_moves=2)) as simulated:
        with simulated.rig(camera=False) as rig:
            rig.move_to(RigPose(0.0, 0.0, 100.0, 45.0))
            with pytest.raises(DeviceError, match="ALARM:1"):
                rig.move_to(RigPose(0.0, 0.0, 300.0, 45.0))


def test_config_offsets_map_to_the_drivers_convention() -> None:
    axis = simulated_config("a", "b").axes["camera_azimuth"]
    shifted = dataclasses.replace(axis, offset_deg=-90.0, direction=-1, gear_ratio=2.0)
    driver = servo_axis(shifted)
    # The config's device degrees count from tick 0; the driver's offset is the centre tick.
    for rig_deg in (-90.0, 0.0, 45.0):
        device = shifted.to_device(rig_deg)
        ticks = (
            2048 + driver.direction * driver.gear_ratio * (rig_deg - driver.offset_deg) / 360 * 4096
        )
        assert ticks == pytest.approx(device / 360 * 4096)


@pytest.mark.parametrize(("homing", "needs"), [(1, "homing"), (0, "an unlock")])
def test_a_controller_locked_in_alarm_says_what_it_needs(homing: int, needs: str) -> None:
    # GRBL with homing enabled powers up locked; without homing in the config nothing may move,
    # and the first G-code would only come back as "error:9".
    with GrblEmulator(settings={22: homing}) as emulator:
        if not homing:
            emulator.inject_alarm(2)
            time.sleep(0.8)
        config = simulated_config("/dev/null", emulator.port)
        gantry = LightGantry(config)
        with pytest.raises(DeviceError, match=rf"locked in alarm and needs {needs}.*gantry\."):
            gantry.connect()
        gantry.close()
        assert not any(line.startswith("M5") for line in emulator.lines)

"""The Dynamixel driver against the byte-level emulator, through the real ``dynamixel_sdk``."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace

import pytest

from core.errors import ConfigError, DeviceError, ProtocolError, SafetyError
from rig.dynamixel import DynamixelChain, ServoAxisConfig, ServoHardwareError
from sim.dynamixel.emulator import ServoChainEmulator
from sim.dynamixel.faults import FaultConfig
from sim.dynamixel.motion import TrapezoidMove, acceleration_ticks_per_s2, velocity_ticks_per_s
from sim.dynamixel.protocol import Instruction, Packet
from sim.dynamixel.servo import ServoSpec

AZIMUTH = ServoAxisConfig(
    id=1,
    role="azimuth",
    min_deg=-150.0,
    max_deg=150.0,
    velocity_deg_s=240.0,
    acceleration_deg_s2=2000.0,
)
# A reversed, geared axis with an offset: 2 servo degrees per axis degree.
INCLINATION = ServoAxisConfig(
    id=2,
    role="inclination",
    offset_deg=10.0,
    direction=-1,
    gear_ratio=2.0,
    min_deg=-60.0,
    max_deg=80.0,
    velocity_deg_s=120.0,
    acceleration_deg_s2=1000.0,
)
AXES = (AZIMUTH, INCLINATION)
BAUD = 1_000_000
# A reply allowance well above the SDK's 34 ms where no reply is meant to go missing (a
# loaded host may stall the emulator thread); fault tests use a short one so that each
# timeout costs little. A spurious timeout is retried either way.
CALM = {"latency_s": 0.1, "retry_backoff_s": 0.01}
FAST = {"latency_s": 0.04, "retry_backoff_s": 0.01}


@pytest.fixture
def emulator() -> Iterator[ServoChainEmulator]:
    with ServoChainEmulator([ServoSpec(id=1), ServoSpec(id=2)]) as emu:
        yield emu


@pytest.fixture
def chain(emulator: ServoChainEmulator) -> Iterator[DynamixelChain]:
    with DynamixelChain(emulator.port, BAUD, AXES, **CALM) as connected:
        yield connected


def writes(packets: list[Packet], address: int | None = None) -> list[tuple[int, int, int]]:
    """(id, address, value) of every WRITE packet, optionally only to ``address``."""
    found = []
    for p in packets:
        if p.instruction == Instruction.WRITE:
            addr = int.from_bytes(p.params[:2], "little")
            value = int.from_bytes(p.params[2:], "little", signed=True)
            if address is None or addr == address:
                found.append((p.packet_id, addr, value))
    return found


def ticks(axis: ServoAxisConfig, deg: float) -> int:
    """The expected goal, written out independently of the driver."""
    return round(2048 + axis.direction * axis.gear_ratio * (deg - axis.offset_deg) * 4096 / 360)


def move_time(emulator: ServoChainEmulator, servo_id: int, start: int, goal: int) -> float:
    """The emulator's motion model for the profile the driver wrote."""
    velocity = velocity_ticks_per_s(emulator.register(servo_id, 112, 4))
    acceleration = acceleration_ticks_per_s2(emulator.register(servo_id, 108, 4))
    return TrapezoidMove(float(start), float(goal), 0.0, velocity, acceleration).duration


# -- connect and configure ---------------------------------------------------------------------


def test_connect_pings_configures_and_holds(emulator: ServoChainEmulator) -> None:
    with DynamixelChain(emulator.port, BAUD, AXES, **CALM) as chain:
        assert [p.instruction for p in emulator.packets()[:2]] == [Instruction.PING] * 2
        assert chain.positions_deg() == pytest.approx({"azimuth": 0.0, "inclination": 10.0})
        for axis in AXES:
            lo, hi = sorted((ticks(axis, axis.min_deg), ticks(axis, axis.max_deg)))
            assert emulator.register(axis.id, 11, 1) == 3
            assert (emulator.register(axis.id, 52, 4), emulator.register(axis.id, 48, 4)) == (
                lo,
                hi,
            )
            assert emulator.register(axis.id, 64, 1) == 1
        # 240 deg/s = 40 rpm = 175 units; 2000 deg/s^2 = 20000 rev/min^2 = 93 units.
        assert (emulator.register(1, 112, 4), emulator.register(1, 108, 4)) == (175, 93)


def test_eeprom_is_written_only_with_torque_off_and_only_when_it_differs(
    emulator: ServoChainEmulator,
) -> None:
    # Left by someone else: torque on, extended position mode, a homing offset, full range.
    for servo_id in (1, 2):
        emulator.set_register(servo_id, 64, 1)
        emulator.set_register(servo_id, 11, 4)
        emulator.set_register(servo_id, 20, 100)
    with DynamixelChain(emulator.port, BAUD, AXES, **CALM):
        pass
    log = writes(emulator.packets())
    for servo_id in (1, 2):
        own = [(addr, value) for i, addr, value in log if i == servo_id]
        torque_off = own.index((64, 0))
        eeprom = [k for k, (addr, _) in enumerate(own) if addr < 64]
        assert [own[k][0] for k in eeprom] == [11, 20, 48, 52]
        assert torque_off < min(eeprom)
        assert max(eeprom) < own.index((64, 1))
        assert emulator.register(servo_id, 20, 4) == 0
    # A second connection finds the EEPROM right and leaves it alone.
    before = len(emulator.packets())
    with DynamixelChain(emulator.port, BAUD, AXES, **CALM):
        pass
    assert [a for _, a, _ in writes(emulator.packets()[before:]) if a < 64] == []


@pytest.mark.parametrize(
    ("servos", "message"),
    [
        ([ServoSpec(id=1), ServoSpec(id=2, model=1060)], r"servo 2 \(inclination\).*1060"),
        ([ServoSpec(id=1)], r"servo 2 \(inclination\) does not answer a ping"),
    ],
    ids=["wrong-model", "missing-servo"],
)
def test_connect_refuses_a_wrong_or_missing_servo(servos: list[ServoSpec], message: str) -> None:
    with ServoChainEmulator(servos) as emulator:
        chain = DynamixelChain(emulator.port, BAUD, AXES, retries=1, **FAST)
        with pytest.raises(DeviceError, match=message) as caught:
            chain.connect()
        assert emulator.port in str(caught.value)
        if "1060" in message:
            assert "XL430-W250" in str(caught.value) and "XM430-W350" in str(caught.value)
        assert emulator.register(1, 64, 1) == 0
        with pytest.raises(DeviceError, match="not connected"):
            chain.position_deg("azimuth")


def test_failure_during_configure_switches_torque_off_again() -> None:
    # Servo 2 answers its ping, error check and torque-off write, then falls silent, after
    # servo 1 was configured with torque on.
    faults = FaultConfig(silent_ids=frozenset({2}), silent_after=3)
    with ServoChainEmulator([ServoSpec(id=1), ServoSpec(id=2)], faults=faults) as emulator:
        chain = DynamixelChain(emulator.port, BAUD, AXES, retries=1, **FAST)
        with pytest.raises(DeviceError, match=r"servo 2 \(inclination\)") as caught:
            chain.connect()
        assert emulator.register(1, 64, 1) == 0
        assert writes(emulator.packets(), 64)[:2] == [(1, 64, 0), (1, 64, 1)]
        assert any("servo 2" in note for note in caught.value.__notes__)


def test_unopenable_port_and_bad_configs() -> None:
    with pytest.raises(DeviceError, match="/nonexistent/tty"):
        DynamixelChain("/nonexistent/tty", BAUD, AXES).connect()
    with pytest.raises(ConfigError, match="direction"):
        replace(AZIMUTH, direction=0)
    with pytest.raises(ConfigError, match="min_deg"):
        replace(AZIMUTH, min_deg=10.0, max_deg=-10.0)
    with pytest.raises(ConfigError, match="outside one servo turn"):
        DynamixelChain("/dev/null", BAUD, [replace(INCLINATION, max_deg=120.0)])
    with pytest.raises(ConfigError, match="distinct"):
        DynamixelChain("/dev/null", BAUD, [AZIMUTH, replace(INCLINATION, id=1)])


# -- motion ----------------------------------------------------------------------------------


def test_single_move_arrives_in_the_model_time(
    emulator: ServoChainEmulator, chain: DynamixelChain
) -> None:
    expected = move_time(emulator, 1, 2048, ticks(AZIMUTH, 60.0))
    started = time.monotonic()
    chain.move_to_deg("azimuth", 60.0)
    elapsed = time.monotonic() - started
    assert expected - 0.01 <= elapsed <= expected + 0.4
    assert chain.position_deg("azimuth") == pytest.approx(60.0, abs=0.1)
    assert emulator.register(1, 122, 1) == 0
    assert writes(emulator.packets(), 116) == [(1, 116, ticks(AZIMUTH, 60.0))]


def test_synced_move_uses_one_sync_write_and_arrives(
    emulator: ServoChainEmulator, chain: DynamixelChain
) -> None:
    start = len(emulator.packets())
    targets = {"azimuth": -45.0, "inclination": 35.0}
    expected = max(move_time(emulator, a.id, 2048, ticks(a, targets[a.role])) for a in AXES)
    started = time.monotonic()
    chain.move_many_deg(targets)
    elapsed = time.monotonic() - started
    assert expected - 0.01 <= elapsed <= expected + 0.4
    assert chain.positions_deg() == pytest.approx(targets, abs=0.1)
    sent = [p.instruction for p in emulator.packets()[start:]]
    assert sent.count(Instruction.SYNC_WRITE) == 1
    assert Instruction.WRITE not in sent
    assert Instruction.SYNC_READ in sent
    assert emulator.register(2, 116, 4) == ticks(INCLINATION, 35.0)


def test_move_without_wait_then_wait(emulator: ServoChainEmulator, chain: DynamixelChain) -> None:
    chain.move_to_deg("inclination", -20.0, wait=False)
    assert emulator.register(2, 122, 1) == 1
    chain.wait_until_arrived(["inclination"])
    assert chain.position_deg("inclination") == pytest.approx(-20.0, abs=0.1)


def test_move_with_torque_off_is_reported_not_waited_for(chain: DynamixelChain) -> None:
    chain.torque(False, ["inclination"])
    with pytest.raises(DeviceError, match=r"servo 2 \(inclination\): torque is off"):
        chain.move_to_deg("inclination", 30.0)
    chain.move_many_deg({})
    chain.wait_until_arrived([])


def test_arrival_timeout_names_the_laggard(chain: DynamixelChain) -> None:
    chain.move_to_deg("azimuth", 140.0, wait=False)
    with pytest.raises(DeviceError, match=r"servo 1 \(azimuth\) at .* target 140\.0\d deg, moving"):
        chain.wait_until_arrived(["azimuth"], timeout_s=0.05)


@pytest.mark.parametrize(
    "targets",
    [
        {"azimuth": 150.5},
        {"inclination": -61.0},
        {"azimuth": 0.0, "inclination": 81.0},
        {"azimuth": math.nan},
    ],
    ids=["above", "below", "one-of-two", "nan"],
)
def test_out_of_limit_moves_are_refused_before_any_byte(
    emulator: ServoChainEmulator, chain: DynamixelChain, targets: dict[str, float]
) -> None:
    before = emulator.bytes_received
    with pytest.raises(SafetyError, match=r"soft limits .* nothing was sent") as caught:
        chain.move_many_deg(targets)
    assert "servo" in str(caught.value) and emulator.port in str(caught.value)
    time.sleep(0.01)
    assert emulator.bytes_received == before


def test_unknown_role_is_refused(chain: DynamixelChain) -> None:
    with pytest.raises(ConfigError, match="turntable"):
        chain.move_to_deg("turntable", 0.0)


def test_data_limit_from_the_servo_is_a_clear_error(
    emulator: ServoChainEmulator, chain: DynamixelChain
) -> None:
    # The servo's own limit is narrower than the config's (changed behind our back).
    emulator.set_register(1, 48, ticks(AZIMUTH, 90.0))
    with pytest.raises(DeviceError, match=r"servo 1 \(azimuth\).*Goal Position.*data limit"):
        chain.move_to_deg("azimuth", 120.0)
    # In a sync move the refused goal is found on read-back and reported the same way.
    with pytest.raises(DeviceError, match=r"servo 1 \(azimuth\).*data limit"):
        chain.move_many_deg({"azimuth": 120.0, "inclination": 20.0})


# -- faults ----------------------------------------------------------------------------------

W = frozenset({Instruction.WRITE})


@dataclass(frozen=True)
class FaultCase:
    name: str
    faults: FaultConfig
    error: type[Exception] | None = None
    match: str = ""
    retries: int = 3


FAULT_CASES = [
    FaultCase("two-dropped-replies", FaultConfig(drop_first=2)),
    FaultCase("two-corrupted-replies", FaultConfig(corrupt_first=2)),
    FaultCase("lost-requests", FaultConfig(lose_first=2)),
    FaultCase("slow-replies-within-timeout", FaultConfig(delay_s=0.005, delay_probability=1.0)),
    FaultCase("one-late-reply", FaultConfig(delay_s=0.06, delay_first=1)),
    FaultCase(
        "random-drops-and-corruption",
        FaultConfig(seed=3, drop_probability=0.1, corrupt_probability=0.05),
        retries=8,
    ),
    FaultCase(
        "servo-stops-answering",
        FaultConfig(silent_ids=frozenset({2}), silent_after=0),
        DeviceError,
        r"servo 2 \(inclination\).*failed after 4 attempts",
    ),
    FaultCase(
        "every-reply-corrupted",
        FaultConfig(corrupt_probability=1.0),
        DeviceError,
        r"servo [12] .*Incorrect status packet",
    ),
    # Every reply late by more than the first wait allows (a loaded machine): each retry waits
    # twice as long, so the replies are taken.
    FaultCase("every-reply-late", FaultConfig(delay_s=0.06, delay_probability=1.0)),
    FaultCase(
        "every-reply-later-than-every-wait",
        FaultConfig(delay_s=0.4, delay_probability=1.0),
        DeviceError,
        r"servo [12] .*failed after 4 attempts",
    ),
]


@pytest.mark.parametrize("case", FAULT_CASES, ids=[c.name for c in FAULT_CASES])
def test_injected_faults_are_retried_or_reported(
    emulator: ServoChainEmulator, case: FaultCase
) -> None:
    with DynamixelChain(emulator.port, BAUD, AXES, retries=case.retries, **FAST) as chain:
        emulator.set_faults(case.faults)
        if case.error is None:
            chain.move_many_deg({"azimuth": 6.0, "inclination": 14.0})
            chain.move_to_deg("azimuth", -3.0)
            assert chain.positions_deg() == pytest.approx(
                {"azimuth": -3.0, "inclination": 14.0}, abs=0.1
            )
        else:
            with pytest.raises(case.error, match=case.match) as caught:
                chain.move_many_deg({"azimuth": 20.0, "inclination": 20.0})
            assert emulator.port in str(caught.value)
        emulator.set_faults(FaultConfig())
    # Late replies leave requests queued in the emulator; torque ends up off once it catches up.
    deadline = time.monotonic() + 3.0
    while (emulator.register(1, 64, 1), emulator.register(2, 64, 1)) != (0, 0):
        assert time.monotonic() < deadline, "torque still on after close"
        time.sleep(0.01)


def test_write_with_lost_reply_is_confirmed_by_reading_not_resent(
    emulator: ServoChainEmulator, chain: DynamixelChain
) -> None:
    emulator.set_faults(FaultConfig(drop_first=1, instructions=W))
    start = len(emulator.packets())
    chain.move_to_deg("azimuth", 25.0)
    assert emulator.goal_writes(1) == 1
    after = emulator.packets()[start:]
    assert len(writes(after, 116)) == 1
    read_back = after[1]
    assert (read_back.instruction, read_back.params[:2]) == (Instruction.READ, b"\x74\x00")
    assert chain.position_deg("azimuth") == pytest.approx(25.0, abs=0.1)


def test_write_lost_on_the_way_is_sent_again_after_the_read_back(
    emulator: ServoChainEmulator, chain: DynamixelChain
) -> None:
    emulator.set_faults(FaultConfig(lose_first=1, instructions=W))
    start = len(emulator.packets())
    chain.move_to_deg("azimuth", -25.0)
    after = emulator.packets()[start:]
    kinds = [p.instruction for p in after[:3]]
    assert kinds == [Instruction.WRITE, Instruction.READ, Instruction.WRITE]
    assert emulator.goal_writes(1) == 1  # the first never reached the servo
    assert chain.position_deg("azimuth") == pytest.approx(-25.0, abs=0.1)


def test_lost_sync_write_is_completed_by_confirmed_single_writes(
    emulator: ServoChainEmulator, chain: DynamixelChain
) -> None:
    emulator.set_faults(FaultConfig(lose_first=1, instructions=frozenset({0x83})))
    chain.move_many_deg({"azimuth": 15.0, "inclination": 40.0})
    assert (emulator.goal_writes(1), emulator.goal_writes(2)) == (1, 1)
    assert len(writes(emulator.packets(), 116)) == 2
    assert chain.positions_deg() == pytest.approx({"azimuth": 15.0, "inclination": 40.0}, abs=0.1)


# -- hardware errors -------------------------------------------------------------------------


def test_overload_is_reported_in_words_and_cleared_by_reboot(
    emulator: ServoChainEmulator, chain: DynamixelChain
) -> None:
    emulator.set_faults(FaultConfig(overload_after_moves=1, overload_ids=frozenset({1})))
    chain.move_to_deg("azimuth", 10.0)
    with pytest.raises(ServoHardwareError, match=r"servo 1 \(azimuth\).*overload") as caught:
        chain.move_to_deg("azimuth", -30.0)
    assert (caught.value.servo_id, caught.value.role, caught.value.errors) == (
        1,
        "azimuth",
        ["overload"],
    )
    assert chain.hardware_errors() == {"azimuth": ["overload"], "inclination": []}
    assert emulator.register(1, 64, 1) == 0
    with pytest.raises(ServoHardwareError, match="overload"):
        chain.position_deg("azimuth")  # every status packet carries the alert bit
    chain.reboot("azimuth")
    assert chain.hardware_errors() == {"azimuth": [], "inclination": []}
    assert emulator.register(1, 112, 4) == 175  # profile restored after the reboot
    chain.torque(True, ["azimuth"])
    emulator.set_faults(FaultConfig())
    chain.move_to_deg("azimuth", -30.0)
    assert chain.position_deg("azimuth") == pytest.approx(-30.0, abs=0.1)


def test_hardware_errors_on_connect(emulator: ServoChainEmulator) -> None:
    emulator.inject_hardware_error(2, 0x04 | 0x01)
    with pytest.raises(
        ServoHardwareError, match=r"servo 2 \(inclination\).*input voltage .* overheating"
    ):
        DynamixelChain(emulator.port, BAUD, AXES, **CALM).connect()
    chain = DynamixelChain(emulator.port, BAUD, AXES, **CALM)
    chain.connect(clear_errors=True)
    try:
        assert chain.hardware_errors() == {"azimuth": [], "inclination": []}
    finally:
        chain.close()


def test_overheating_is_reported_on_the_next_status_packet(
    emulator: ServoChainEmulator, chain: DynamixelChain
) -> None:
    emulator.set_temperature(1, 90)
    with pytest.raises(ServoHardwareError, match="overheating"):
        chain.position_deg("azimuth")
    assert issubclass(ServoHardwareError, DeviceError)
    assert issubclass(ProtocolError, DeviceError)


# -- torque off on every exit path ---------------------------------------------------------


def test_torque_off_after_close_and_after_an_exception(emulator: ServoChainEmulator) -> None:
    chain = DynamixelChain(emulator.port, BAUD, AXES, **CALM)
    chain.connect()
    assert emulator.register(1, 64, 1) == 1
    chain.close()
    assert (emulator.register(1, 64, 1), emulator.register(2, 64, 1)) == (0, 0)
    with pytest.raises(RuntimeError, match="operator abort"):
        with DynamixelChain(emulator.port, BAUD, AXES, **CALM) as chain:
            chain.move_to_deg("azimuth", 30.0, wait=False)
            raise RuntimeError("operator abort")
    assert (emulator.register(1, 64, 1), emulator.register(2, 64, 1)) == (0, 0)
    assert emulator.register(1, 122, 1) == 0  # stopped where it was


def test_close_reports_a_servo_it_could_not_switch_off(emulator: ServoChainEmulator) -> None:
    chain = DynamixelChain(emulator.port, BAUD, AXES, retries=1, **FAST)
    chain.connect()
    emulator.set_faults(FaultConfig(silent_ids=frozenset({2})))
    with pytest.raises(DeviceError, match=r"torque could not be switched off.*servo 2"):
        chain.close()
    assert emulator.register(1, 64, 1) == 0
    with pytest.raises(ValueError, match="inside") as caught:
        with DynamixelChain(emulator.port, BAUD, [AZIMUTH], **FAST):
            emulator.set_faults(FaultConfig(silent_ids=frozenset({1})))
            raise ValueError("inside")
    assert any("torque could not be switched off" in n for n in caught.value.__notes__)

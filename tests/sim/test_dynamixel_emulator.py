"""The Dynamixel Protocol 2.0 emulator: wire format, control table, motion model, faults.

The pty tests talk to the emulator through the real ``dynamixel_sdk`` (PortHandler and the
Protocol 2.0 PacketHandler), never through the emulator's own encoder.
"""

from __future__ import annotations

import itertools
import math
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
from dynamixel_sdk import (
    COMM_RX_CORRUPT,
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
    PortHandler,
)
from hypothesis import given
from hypothesis import strategies as st

from sim.dynamixel.emulator import ServoChainEmulator
from sim.dynamixel.faults import FaultConfig
from sim.dynamixel.motion import TrapezoidMove, acceleration_ticks_per_s2, velocity_ticks_per_s
from sim.dynamixel.protocol import (
    Instruction,
    PacketParser,
    ResultError,
    crc16,
    decode,
    encode,
    stuff,
    unstuff,
)
from sim.dynamixel.servo import ServoSpec

PH = PacketHandler(2.0)


class TimedPort(PortHandler):  # type: ignore[misc]
    """The SDK's port with an adjustable reply allowance (the SDK's own is a fixed 34 ms).

    Checks that expect an answer allow a generous 250 ms, so a loaded host cannot fail them;
    checks that expect silence shorten it so that they cost little time.
    """

    latency_ms = 250.0

    def setPacketTimeout(self, packet_length: int) -> None:
        self.packet_start_time = self.getCurrentTime()
        self.packet_timeout = self.tx_time_per_byte * packet_length + self.latency_ms


@pytest.fixture
def emulator() -> Iterator[ServoChainEmulator]:
    with ServoChainEmulator([ServoSpec(id=1), ServoSpec(id=2, position_ticks=1000)]) as emu:
        yield emu


@pytest.fixture
def port(emulator: ServoChainEmulator) -> Iterator[TimedPort]:
    handler = TimedPort(emulator.port)
    assert handler.openPort()
    yield handler
    handler.closePort()


@contextmanager
def short_timeout(port: TimedPort) -> Iterator[None]:
    """A 30 ms reply allowance for calls that expect no answer."""
    port.latency_ms = 30.0
    try:
        yield
    finally:
        port.latency_ms = 250.0


def raw_exchange(
    port: PortHandler, packet: bytes, timeout_ms: float = 250.0
) -> tuple[list[int], int]:
    """Send hand-made bytes and read one status packet with the SDK's receiver."""
    port.clearPort()
    port.writePort(packet)
    port.setPacketTimeoutMillis(timeout_ms)
    rx, result = PH.rxPacket(port, False)
    return list(rx), result


# -- wire format ------------------------------------------------------------------------------


def test_crc_matches_the_e_manual_ping_examples() -> None:
    # Instruction and status packet of the e-manual's PING example (id 1, model 1030, fw 38).
    assert encode(1, Instruction.PING) == bytes.fromhex("FFFFFD0001030001194E")
    status = bytes.fromhex("FFFFFD0001070055000604 26")
    assert crc16(status) == 0x5D65


@given(st.binary(max_size=64))
def test_crc_agrees_with_the_sdk(data: bytes) -> None:
    assert crc16(data) == PH.updateCRC(0, list(data), len(data))


@given(st.lists(st.sampled_from([0x00, 0x01, 0xFD, 0xFF]) | st.integers(0, 255), max_size=40))
def test_stuffing_round_trips_and_hides_headers(params: list[int]) -> None:
    body = bytes([Instruction.WRITE, *params])
    stuffed = stuff(body)
    assert unstuff(stuffed) == body
    for i in range(len(stuffed) - 2):
        if stuffed[i : i + 3] == b"\xff\xff\xfd":
            assert stuffed[i + 3 : i + 4] == b"\xfd"
    # The SDK stuffs the same way and its parser reads our packet back.
    packet = encode(7, Instruction.WRITE, bytes(params))
    sdk = [0xFF, 0xFF, 0xFD, 0x00, 7, (len(body) + 2) & 0xFF, (len(body) + 2) >> 8, *body, 0, 0]
    sdk = PH.addStuffing(sdk)
    assert bytes(sdk[:-2]) == packet[:-2]
    assert decode(packet).params == bytes(params)
    assert decode(packet).crc_ok


def test_parser_resynchronises_on_garbage_split_and_stale_packets() -> None:
    parser = PacketParser(stale_s=0.05)
    ping = encode(1, Instruction.PING)
    read = encode(2, Instruction.READ, bytes([132, 0, 4, 0]))
    assert parser.feed(b"\x00\xff\x13" + ping[:5], now=0.0) == []
    (first,) = parser.feed(ping[5:] + read[:3], now=0.01)
    assert (first.packet_id, first.instruction, first.crc_ok) == (1, Instruction.PING, True)
    (second,) = parser.feed(read[3:], now=0.02)
    assert second.params == bytes([132, 0, 4, 0])
    # A packet cut short and left there is dropped; the next one still parses.
    assert parser.feed(read[:9], now=0.03) == []
    assert [p.packet_id for p in parser.feed(ping, now=0.5)] == [1]
    # An impossible length field is skipped, not waited for.
    assert [p.packet_id for p in parser.feed(b"\xff\xff\xfd\x00\x01\xff\xff" + ping)] == [1]
    bad = bytearray(ping)
    bad[-1] ^= 0x01
    assert parser.feed(bytes(bad))[0].crc_ok is False


# -- motion model ----------------------------------------------------------------------------


def test_unit_conversions_follow_the_x_series_units() -> None:
    assert velocity_ticks_per_s(100) == pytest.approx(22.9 * 4096 / 60)
    assert acceleration_ticks_per_s2(10) == pytest.approx(2145.77 * 4096 / 3600)


@pytest.mark.parametrize(
    ("distance", "velocity", "acceleration", "duration", "profile"),
    [
        (1000.0, 500.0, 1000.0, 0.5 + 1000.0 / 500.0, 0x30),  # trapezoid: 2 x 0.5 s + cruise
        (100.0, 500.0, 1000.0, 2.0 * math.sqrt(0.1), 0x20),  # triangle: never reaches 500
        (1000.0, 500.0, math.inf, 2.0, 0x10),  # rectangular velocity profile
    ],
)
def test_trapezoid_move_times_and_shape(
    distance: float, velocity: float, acceleration: float, duration: float, profile: int
) -> None:
    for sign in (1.0, -1.0):
        move = TrapezoidMove(2000.0, 2000.0 + sign * distance, 10.0, velocity, acceleration)
        assert move.duration == pytest.approx(duration)
        assert move.profile_bits == profile
        assert move.position(9.0) == 2000.0
        assert move.position(10.0 + duration / 2) == pytest.approx(2000.0 + sign * distance / 2)
        assert move.position(10.0 + duration + 1.0) == pytest.approx(2000.0 + sign * distance)
        samples = [move.position(10.0 + duration * k / 50) for k in range(51)]
        steps = [sign * (b - a) for a, b in itertools.pairwise(samples)]
        assert min(steps) >= -1e-9  # monotonic towards the goal
        assert max(abs(move.velocity_at(10.0 + duration * k / 50)) for k in range(50)) <= (
            velocity + 1e-9
        )


# -- through the SDK on the pty --------------------------------------------------------------


def test_ping_broadcast_ping_and_missing_id(port: PortHandler) -> None:
    assert PH.ping(port, 1) == (1020, COMM_SUCCESS, 0)
    with short_timeout(port):
        assert PH.ping(port, 3)[1] == COMM_RX_TIMEOUT
    # Broadcast PING: every servo answers, in id order. (The SDK's broadcastPing works too
    # but always waits ~0.8 s for 252 possible servos; reading two replies is enough here.)
    port.clearPort()
    port.writePort(encode(0xFE, Instruction.PING))
    port.setPacketTimeoutMillis(250)
    replies = [PH.rxPacket(port, False) for _ in range(2)]
    assert [(rx[4], rx[9] | rx[10] << 8, result) for rx, result in replies] == [
        (1, 1020, COMM_SUCCESS),
        (2, 1020, COMM_SUCCESS),
    ]


def test_broadcast_write_and_reboot_have_no_reply(
    emulator: ServoChainEmulator, port: PortHandler
) -> None:
    assert PH.write1ByteTxRx(port, 0xFE, 65, 1) == (COMM_SUCCESS, 0)  # returns without reading
    assert PH.reboot(port, 0xFE) == (COMM_SUCCESS, 0)
    time.sleep(0.005)
    assert port.getBytesAvailable() == 0  # nobody answered
    time.sleep(0.03)
    assert [emulator.register(i, 65, 1) for i in (1, 2)] == [0, 0]  # LED is RAM: reset


def test_baud_rate_can_be_set_on_the_pty(emulator: ServoChainEmulator) -> None:
    handler = TimedPort(emulator.port)
    assert handler.openPort()
    try:
        for baud in (57600, 1_000_000, 4_000_000):
            assert handler.setBaudRate(baud)
            assert PH.ping(handler, 2)[1] == COMM_SUCCESS
    finally:
        handler.closePort()


def test_read_write_and_control_table_rules(port: PortHandler) -> None:
    assert PH.read2ByteTxRx(port, 1, 0) == (1020, COMM_SUCCESS, 0)
    assert PH.read4ByteTxRx(port, 2, 132) == (1000, COMM_SUCCESS, 0)
    assert PH.write4ByteTxRx(port, 1, 48, 3000) == (COMM_SUCCESS, 0)  # EEPROM, torque off
    assert PH.write1ByteTxRx(port, 1, 64, 1) == (COMM_SUCCESS, 0)
    assert PH.write4ByteTxRx(port, 1, 48, 3500) == (COMM_SUCCESS, ResultError.ACCESS)
    assert PH.write4ByteTxRx(port, 1, 116, 3001) == (COMM_SUCCESS, ResultError.DATA_LIMIT)
    assert PH.write1ByteTxRx(port, 1, 64, 2) == (COMM_SUCCESS, ResultError.DATA_RANGE)
    assert PH.write2ByteTxRx(port, 1, 116, 5) == (COMM_SUCCESS, ResultError.DATA_LENGTH)
    assert PH.write1ByteTxRx(port, 1, 132, 5) == (COMM_SUCCESS, ResultError.ACCESS)
    assert PH.write1ByteTxRx(port, 1, 66, 5) == (COMM_SUCCESS, ResultError.ACCESS)
    assert PH.readTxRx(port, 1, 140, 10)[1:] == (COMM_SUCCESS, ResultError.ACCESS)
    assert PH.read4ByteTxRx(port, 1, 48) == (3000, COMM_SUCCESS, 0)
    assert PH.read4ByteTxRx(port, 1, 116) == (2048, COMM_SUCCESS, 0)  # goal := present on torque
    assert PH.read1ByteTxRx(port, 1, 146) == (35, COMM_SUCCESS, 0)


def test_malformed_packets_are_ignored_or_answered_with_the_right_error(
    emulator: ServoChainEmulator, port: PortHandler
) -> None:
    damaged = bytearray(encode(1, Instruction.READ, bytes([132, 0, 4, 0])))
    damaged[-2] ^= 0xFF
    rx, result = raw_exchange(port, bytes(damaged))
    assert (result, rx[4], rx[8]) == (COMM_SUCCESS, 1, ResultError.CRC)
    rx, result = raw_exchange(port, encode(1, Instruction.READ, bytes([132, 0, 4])))
    assert (result, rx[8]) == (COMM_SUCCESS, ResultError.DATA_LENGTH)
    rx, result = raw_exchange(port, encode(1, Instruction.BULK_WRITE, b""))
    assert (result, rx[8]) == (COMM_SUCCESS, ResultError.INSTRUCTION)
    # Garbage and a packet cut short: no answer; once the fragment is stale (50 ms) it is
    # dropped and the next packet is answered.
    before = emulator.bytes_received
    _, result = raw_exchange(port, bytes.fromhex("0013 FFFFFD00 01 1000 02 84"), 30.0)
    assert result == COMM_RX_TIMEOUT
    # The emulator's thread may read the bytes after the 30 ms allowance on a loaded host; the
    # staleness clock starts when it does.
    deadline = time.monotonic() + 5.0
    while emulator.bytes_received < before + 11 and time.monotonic() < deadline:
        time.sleep(0.005)
    assert emulator.bytes_received == before + 11
    time.sleep(0.06)
    assert PH.ping(port, 1)[1] == COMM_SUCCESS


def test_byte_stuffing_on_the_wire(port: PortHandler) -> None:
    # Homing Offset -131073 is FF FF FD FF: the write and the read-back need stuffing.
    value = int.from_bytes(b"\xff\xff\xfd\xff", "little", signed=True)
    assert PH.writeTxRx(port, 1, 20, 4, [0xFF, 0xFF, 0xFD, 0xFF]) == (COMM_SUCCESS, 0)
    data, result, error = PH.readTxRx(port, 1, 20, 4)
    assert (bytes(data), result, error) == (b"\xff\xff\xfd\xff", COMM_SUCCESS, 0)
    assert value == -131073


def test_sync_write_sync_read_and_motion(emulator: ServoChainEmulator, port: PortHandler) -> None:
    for servo_id in (1, 2):
        assert PH.write4ByteTxRx(port, servo_id, 112, 300) == (COMM_SUCCESS, 0)
        assert PH.write4ByteTxRx(port, servo_id, 108, 200) == (COMM_SUCCESS, 0)
        assert PH.write1ByteTxRx(port, servo_id, 64, 1) == (COMM_SUCCESS, 0)
    writer = GroupSyncWrite(port, PH, 116, 4)
    writer.addParam(1, list((2248).to_bytes(4, "little")))
    writer.addParam(2, list((900).to_bytes(4, "little")))
    started = time.monotonic()
    assert writer.txPacket() == COMM_SUCCESS
    reader = GroupSyncRead(port, PH, 116, 20)
    reader.addParam(1)
    reader.addParam(2)
    while True:
        assert reader.txRxPacket() == COMM_SUCCESS
        if not (reader.getData(1, 122, 1) or reader.getData(2, 122, 1)):
            break
        time.sleep(0.005)
    elapsed = time.monotonic() - started
    v, a = velocity_ticks_per_s(300), acceleration_ticks_per_s2(200)
    expected = TrapezoidMove(2048.0, 2248.0, 0.0, v, a).duration
    assert expected - 0.01 <= elapsed <= expected + 0.3
    assert (reader.getData(1, 132, 4), reader.getData(2, 132, 4)) == (2248, 900)
    assert (emulator.goal_writes(1), emulator.goal_writes(2)) == (1, 1)


def test_overload_sets_the_alert_bit_until_reboot() -> None:
    faults = FaultConfig(overload_after_moves=0, overload_ids=frozenset({1}))
    servos = [ServoSpec(id=1, reboot_s=0.2), ServoSpec(id=2)]
    with ServoChainEmulator(servos, faults=faults) as emulator:
        port = TimedPort(emulator.port)
        assert port.openPort()
        try:
            assert PH.write1ByteTxRx(port, 1, 64, 1) == (COMM_SUCCESS, 0)
            assert PH.write4ByteTxRx(port, 1, 116, 2048) == (COMM_SUCCESS, 0)  # a null move
            assert PH.read1ByteTxRx(port, 1, 70) == (0x20, COMM_SUCCESS, 0x80)
            assert PH.read1ByteTxRx(port, 1, 64) == (0, COMM_SUCCESS, 0x80)
            assert PH.write1ByteTxRx(port, 1, 64, 1) == (COMM_SUCCESS, 0x80 | 0x01)
            assert PH.ping(port, 2) == (1020, COMM_SUCCESS, 0)  # the other servo is fine
            assert PH.reboot(port, 1) == (COMM_SUCCESS, 0x80)
            with short_timeout(port):
                assert PH.ping(port, 1)[1] == COMM_RX_TIMEOUT  # booting
            time.sleep(0.2)
            assert PH.read1ByteTxRx(port, 1, 70) == (0, COMM_SUCCESS, 0)
            assert PH.read1ByteTxRx(port, 1, 64) == (0, COMM_SUCCESS, 0)
        finally:
            port.closePort()


def test_overheating_on_demand(emulator: ServoChainEmulator, port: PortHandler) -> None:
    emulator.set_temperature(2, 85)
    assert PH.read1ByteTxRx(port, 2, 146) == (85, COMM_SUCCESS, 0x80)
    assert PH.read1ByteTxRx(port, 2, 70) == (0x04, COMM_SUCCESS, 0x80)


class ShortTimeoutPort(PortHandler):  # type: ignore[misc]
    """The SDK's port with a 10 ms reply allowance, so dropped replies cost little time."""

    def setPacketTimeout(self, packet_length: int) -> None:
        self.setPacketTimeoutMillis(10)


def test_reply_faults_are_deterministic_for_a_seed(emulator: ServoChainEmulator) -> None:
    def pattern(seed: int) -> list[tuple[int, str]]:
        emulator.set_faults(FaultConfig(seed=seed, drop_probability=0.3, corrupt_probability=0.3))
        handler = ShortTimeoutPort(emulator.port)
        assert handler.openPort()
        before = len(emulator.packets())
        try:
            for _ in range(12):
                PH.ping(handler, 1)
            # Every ping handled before the log is read or the faults reset: on a loaded
            # machine the emulator's thread can lag the 10 ms reply allowance.
            deadline = time.monotonic() + 60.0
            while len(emulator.packets()) < before + 12 and time.monotonic() < deadline:
                time.sleep(0.01)
        finally:
            handler.closePort()
        return emulator.fault_log()

    first = pattern(7)
    assert first == pattern(7)
    assert {kind for _, kind in first} == {"dropped", "corrupted"}
    assert first != pattern(8)


def test_corrupted_delayed_and_silent(emulator: ServoChainEmulator, port: TimedPort) -> None:
    emulator.set_faults(FaultConfig(corrupt_first=1))
    assert PH.ping(port, 1)[1] == COMM_RX_CORRUPT
    assert PH.ping(port, 1)[1] == COMM_SUCCESS
    emulator.set_faults(FaultConfig(delay_s=0.1, delay_first=1))
    with short_timeout(port):
        assert PH.ping(port, 1)[1] == COMM_RX_TIMEOUT
    time.sleep(0.12)
    assert PH.ping(port, 1)[1] == COMM_SUCCESS  # the late reply was flushed before sending
    emulator.set_faults(FaultConfig(silent_ids=frozenset({2}), silent_after=1))
    assert PH.ping(port, 2)[1] == COMM_SUCCESS
    with short_timeout(port):
        assert PH.write1ByteTxRx(port, 2, 65, 1)[0] == COMM_RX_TIMEOUT
    assert emulator.register(2, 65, 1) == 0  # not executed either
    assert PH.ping(port, 1)[1] == COMM_SUCCESS


def test_close_removes_the_pty() -> None:
    emulator = ServoChainEmulator([ServoSpec(id=5)])
    path = emulator.port
    assert os.path.exists(path)
    emulator.close()
    emulator.close()
    assert not os.path.exists(path)


def test_bad_specs_and_faults_are_refused() -> None:
    with pytest.raises(ValueError, match="distinct"):
        ServoChainEmulator([ServoSpec(id=1), ServoSpec(id=1)])
    with pytest.raises(ValueError, match="drop_probability"):
        FaultConfig(drop_probability=1.5)

"""The GRBL 1.1 emulator at the byte level, through a plain pyserial port."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
import serial

from sim.grbl_emulator import FaultRule, GrblEmulator, GrblFaults, LightState
from sim.grbl_lines import LineAssembler
from sim.grbl_motion import Profile

FAST = {110: 36000.0, 111: 36000.0, 112: 36000.0, 120: 20000.0, 121: 20000.0, 122: 20000.0}
BANNER = b"Grbl 1.1h ['$' for help]\r\n"
LOCKED = b"[MSG:'$H'|'$X' to unlock]\r\n"


class Line:
    """A raw serial line to the emulator, with helpers that wait for replies."""

    def __init__(self, port: str) -> None:
        self.serial = serial.Serial(port, 115200, timeout=0.5)

    def send(self, data: bytes) -> None:
        self.serial.write(data)

    def lines(self, count: int) -> list[str]:
        out = [
            self.serial.readline().decode("ascii", "replace").rstrip("\r\n") for _ in range(count)
        ]
        assert all(out), f"timed out after {out}"
        return out

    def ask(self, command: str) -> str:
        self.send(command.encode() + b"\n")
        return self.lines(1)[0]

    def status(self) -> str:
        self.send(b"?")
        return self.lines(1)[0]

    def quiet(self, seconds: float = 0.05) -> bytes:
        time.sleep(seconds)
        return self.serial.read(self.serial.in_waiting)


@contextmanager
def grbl(
    settings: dict[int, float] | None = None, faults: GrblFaults | None = None
) -> Iterator[tuple[GrblEmulator, Line]]:
    with GrblEmulator(settings={**FAST, **(settings or {})}, faults=faults) as emulator:
        line = Line(emulator.port)
        try:
            yield emulator, line
        finally:
            line.serial.close()


def test_banner_on_soft_reset_and_pty_removed_on_close() -> None:
    with grbl() as (emulator, line):
        line.send(b"\x18")
        assert line.quiet() == BANNER
        port = emulator.port
        assert os.path.exists(port)
    assert not os.path.exists(port)


def test_status_is_answered_mid_line() -> None:
    with grbl() as (emulator, line):
        line.send(b"G0 X-1?")
        assert line.lines(1)[0].startswith("<Idle|MPos:0.000,0.000,0.000|FS:0,0")
        line.send(b" Y-2\n")
        assert line.lines(1) == ["ok"]
        assert emulator.lines == ["G0X-1Y-2"]


def test_wco_then_ov_then_every_tenth_report_when_idle() -> None:
    with grbl() as (_, line):
        line.send(b"\x18")
        line.quiet()
        reports = [line.status() for _ in range(12)]
        assert "WCO:" in reports[0] and "Ov:" not in reports[0]
        assert "Ov:100,100,100" in reports[1]
        assert [("WCO:" in r) for r in reports[2:12]] == [False] * 8 + [True, False]


ERRORS = [
    ("X", "error:2"),
    ("1", "error:1"),
    ("G5", "error:20"),
    ("G2 X1 I1", "error:20"),
    ("Q1", "error:20"),
    ("G0 G1 X1", "error:21"),
    ("M3 M5", "error:21"),
    ("G1 X1", "error:22"),
    ("G1.5 X1", "error:23"),
    ("M3.5", "error:23"),
    ("X1 X2", "error:25"),
    ("G92", "error:26"),
    ("N99999999", "error:27"),
    ("G4", "error:28"),
    ("G80 X1", "error:31"),
    ("P1", "error:36"),
    ("T300", "error:38"),
    ("F-1", "error:4"),
    ("G1 X" + "1" * 90, "error:11"),
    ("$Q", "error:3"),
    ("$100=-1", "error:4"),
    ("$0=2", "error:6"),
    ("$20=1", "error:10"),
    ("$999=1", "error:3"),
    ("$H", "error:5"),
    ("", "ok"),
    ("(comment only)", "ok"),
    ("g0 x-1 ; lower case and a comment", "ok"),
]


@pytest.fixture(scope="module")
def shared() -> Iterator[Line]:
    with grbl() as (_, line):
        yield line


@pytest.mark.parametrize(("command", "reply"), ERRORS)
def test_replies(shared: Line, command: str, reply: str) -> None:
    assert shared.ask(command) == reply


def test_carriage_return_and_newline_are_two_lines() -> None:
    with grbl() as (_, line):
        line.send(b"G0 X-1\r\n")
        assert line.lines(2) == ["ok", "ok"]


def test_settings_listing_and_change() -> None:
    with grbl() as (emulator, line):
        line.send(b"$$\n")
        listing = line.lines(35)
        assert listing[0] == "$0=10" and listing[-1] == "ok"
        assert "$11=0.010" in listing and "$30=1000" in listing and "$110=36000.000" in listing
        assert line.ask("$110=1234.5") == "ok"
        assert emulator.settings[110] == 1234.5
        line.send(b"$G\n")
        assert line.lines(2) == ["[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]", "ok"]


def test_move_follows_the_trapezoid_and_g91_and_g4() -> None:
    with grbl() as (emulator, line):
        start = time.monotonic()
        assert line.ask("G1 X-90 F30000") == "ok"
        profile = Profile.plan(90.0, 0.0, 500.0, 20000.0)
        time.sleep(profile.t1 + 0.05)
        asked = time.monotonic() - start
        report = line.status()
        elapsed = time.monotonic() - start
        assert report.startswith("<Run|")
        x = -float(report.split("MPos:")[1].split(",")[0])
        # The report is of some instant between asking and the answer (a loaded machine
        # may delay either end; only the order is certain).
        assert profile.at(asked - 0.03)[0] - 1.0 <= x <= profile.at(elapsed)[0] + 1.0
        while not line.status().startswith("<Idle"):
            time.sleep(0.01)
        assert profile.duration - 0.05 <= time.monotonic() - start < profile.duration + 2.0
        assert line.ask("G91 G0 X10 Y-5") == "ok"
        assert line.ask("G4 P0.2") == "ok"  # after the move and the dwell
        assert emulator.machine_position() == pytest.approx((-80.0, -5.0, 0.0))
        assert time.monotonic() - start > profile.duration + 0.2


def test_soft_limit_alarm_is_critical_until_reset() -> None:
    with grbl({20: 1, 22: 1, 130: 50.0}) as (emulator, line):
        assert emulator.state == "Alarm"  # homing enabled: locked from the start
        line.send(b"$X\n")
        assert line.lines(2) == ["[MSG:Caution: Unlocked]", "ok"]
        assert line.ask("G0 X-10") == "ok"
        time.sleep(0.1)
        line.send(b"G0 X-60\n")
        assert line.lines(2) == ["ALARM:2", "[MSG:Reset to continue]"]
        line.send(b"?G0 X-1\n")
        assert line.quiet(0.1) == b""  # nothing is served, not even status
        line.send(b"\x18")
        assert line.quiet() == b"ok\r\n" + BANNER + LOCKED
        assert line.ask("G0 X-1") == "error:9"
        assert line.status().startswith("<Alarm|MPos:-10.000,0.000,0.000")
        assert emulator.machine_position()[0] == pytest.approx(-10.0)


def test_soft_limit_during_motion_stops_with_a_hold_first() -> None:
    with grbl({20: 1, 22: 1, 130: 500.0, 110: 3000.0}) as (emulator, line):
        line.ask("$X")
        line.lines(1)
        assert line.ask("G0 X-100") == "ok"
        time.sleep(0.2)
        line.send(b"G0 X1\n")
        assert line.lines(2) == ["ALARM:2", "[MSG:Reset to continue]"]
        stopped = emulator.machine_position()[0]
        assert -100.0 < stopped < 0.0  # a controlled stop along the first move


def test_hard_alarm_injected_and_reset_during_motion() -> None:
    with grbl({110: 600.0}) as (emulator, line):
        line.ask("M8")
        line.ask("G0 X-50")
        time.sleep(0.1)
        emulator.inject_alarm(1)
        assert line.lines(2) == ["ALARM:1", "[MSG:Reset to continue]"]
        assert emulator.light == LightState(False, 0.0, "off")
        line.send(b"\x18")
        assert line.quiet() == BANNER + LOCKED
        assert "Pn:" not in line.status()
        line.ask("$X")
        line.lines(1)
        line.ask("G0 X-50")
        line.send(b"\x18")  # reset while running: position lost, ALARM:3
        assert line.quiet() == b"ALARM:3\r\n" + BANNER + LOCKED


def test_homing() -> None:
    with grbl({22: 1, 24: 6000.0, 25: 30000.0, 27: 2.0}) as (emulator, line):
        line.send(b"$H\n?")
        time.sleep(0.01)
        assert emulator.state == "Home"
        replies = line.lines(2)
        assert replies[0] == "ok" and replies[1].startswith("<Idle|MPos:-2.000,-2.000,-2.000")


def test_feed_hold_and_cycle_start() -> None:
    with grbl({110: 1200.0}) as (emulator, line):
        line.ask("G0 X-10")
        time.sleep(0.15)
        line.send(b"!")
        assert line.status().startswith("<Hold:1")
        time.sleep(0.1)
        held = line.status()
        assert held.startswith("<Hold:0")
        time.sleep(0.05)
        assert line.status().split("|")[1] == held.split("|")[1]
        line.send(b"~")
        deadline = time.monotonic() + 3
        while not line.status().startswith("<Idle") and time.monotonic() < deadline:
            time.sleep(0.02)
        assert emulator.machine_position()[0] == pytest.approx(-10.0)


def test_idle_feed_hold_is_hold_zero() -> None:
    with grbl() as (_, line):
        line.send(b"!")
        assert line.status().startswith("<Hold:0")
        line.send(b"~")
        assert line.status().startswith("<Idle")


def test_light_states_and_accessory_field() -> None:
    with grbl() as (emulator, line):
        assert line.ask("M3 S250") == "ok"
        assert emulator.light == LightState(True, 0.25, "spindle")
        reports = [line.status() for _ in range(3)]
        assert any("|A:S" in r for r in reports) and all("FS:0,250" in r for r in reports)
        assert line.ask("S2000") == "ok"  # clamped to $30
        assert emulator.light == LightState(True, 1.0, "spindle")
        assert line.ask("M5 M8") == "ok"
        assert emulator.light == LightState(True, 1.0, "coolant")
        assert line.ask("M9") == "ok"
        assert not emulator.light.on


def test_work_offsets_and_wpos_reports() -> None:
    with grbl({10: 0}) as (emulator, line):
        line.ask("G0 X-10 Y-10")
        assert line.ask("G92 X0 Y0") == "ok"
        time.sleep(0.1)
        report = line.status()
        assert report.startswith("<Idle|WPos:0.000,0.000,0.000") and "WCO:-10.000,-10.000" in report
        line.ask("G0 X5")
        time.sleep(0.1)
        assert emulator.machine_position()[0] == pytest.approx(-5.0)
        assert line.ask("G53 G0 X-1") == "ok"
        time.sleep(0.1)
        assert emulator.machine_position()[0] == pytest.approx(-1.0)


def test_receive_buffer_overflow_loses_bytes() -> None:
    with grbl({10: 3}) as (emulator, line):
        line.send(b"G4 P0.3\n" + b"G0 X-1\n" * 30)  # 218 bytes while GRBL waits in the dwell
        time.sleep(0.1)
        assert "Bf:15,0" in line.status()
        time.sleep(0.4)
        assert emulator.rx_overflow_bytes == 8 + 7 * 30 - 128 - 8
        received = line.quiet(0.1).count(b"ok")
        assert received == 1 + 128 // 7


def test_extended_ascii_is_ignored() -> None:
    with grbl() as (emulator, line):
        line.send(b"\x90\xa0G0 X-1\n")
        assert line.lines(1) == ["ok"]
        assert emulator.lines == ["G0X-1"] and not emulator.light.on


def test_line_assembler_filters_like_grbl() -> None:
    assembler = LineAssembler()
    results = [assembler.feed(b) for b in b"g1 (x) x1 /;tail\n"]
    assert results[-1] == ("G1X1", False)


def test_faults_are_deterministic_for_a_seed() -> None:
    def replies(seed: int) -> list[str]:
        faults = GrblFaults(seed=seed, drop_reply=FaultRule(probability=0.5))
        with grbl(faults=faults) as (_, line):
            line.send(b"G0 X-1\n" * 10)
            return [entry for entry in line.quiet(0.2).decode().split("\r\n") if entry]

    first = replies(7)
    assert 0 < len(first) < 10
    assert replies(7) == first


def test_delay_and_garbage_faults() -> None:
    faults = GrblFaults(
        delay_reply=FaultRule(pattern="M8"), delay_s=0.2, garbage=FaultRule(pattern="M9")
    )
    with grbl(faults=faults) as (_, line):
        start = time.monotonic()
        assert line.ask("M8") == "ok"
        assert time.monotonic() - start >= 0.2
        line.send(b"M9\n")
        noise = line.serial.readline()
        assert any(b >= 0x80 for b in noise)
        assert line.lines(1) == ["ok"]


def test_hard_limit_fault_after_moves() -> None:
    faults = GrblFaults(hard_limit_after_moves=2)
    with grbl({110: 6000.0}, faults=faults) as (emulator, line):
        line.send(b"G0 X-10\nG0 X-30\n")
        assert line.lines(4) == ["ok", "ok", "ALARM:1", "[MSG:Reset to continue]"]
        assert -30.0 < emulator.machine_position()[0] < -10.0

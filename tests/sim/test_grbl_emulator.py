"""The GRBL 1.1 emulator at the byte level, through a plain pyserial port."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
import serial

from sim.grbl.emulator import FaultRule, GrblEmulator, GrblFaults, LightState
from sim.grbl.lines import LineAssembler
from sim.grbl.motion import Profile

FAST = {110: 36000.0, 111: 36000.0, 112: 36000.0, 120: 20000.0, 121: 20000.0, 122: 20000.0}
BANNER = b"Grbl 1.1h ['$' for help]\r\n"
LOCKED = b"[MSG:'$H'|'$X' to unlock]\r\n"


class Line:
    """A raw serial line to the emulator, with helpers that wait for replies."""

    def __init__(self, port: str) -> None:
        # Longer than GRBL's 500 ms pause after an ALARM line, so a read spans it.
        self.serial = serial.Serial(port, 115200, timeout=1.5)

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

    def idle(self, timeout: float = 5.0) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            report = self.status()
            if report.startswith("<Idle"):
                return report
            time.sleep(0.01)
        raise AssertionError(f"not idle after {timeout} s: {report}")


@contextmanager
def grbl(
    settings: dict[int, float] | None = None, faults: GrblFaults | None = None, **options: Any
) -> Iterator[tuple[GrblEmulator, Line]]:
    merged = {**FAST, **(settings or {})}
    with GrblEmulator(settings=merged, faults=faults, **options) as emulator:
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
    ("G2 X1 I1", "error:22"),  # an arc needs a feed rate (GRBL 1.1 has arcs)
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
        # Decelerating (Hold:1), then stopped (Hold:0); on a loaded machine the status may
        # arrive after the short deceleration has ended.
        assert line.status().startswith(("<Hold:1", "<Hold:0"))
        deadline = time.monotonic() + 2
        while not (held := line.status()).startswith("<Hold:0") and time.monotonic() < deadline:
            time.sleep(0.02)
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


# -- GRBL 1.1h behaviours beyond the basics ---------------------------------------------------

BANNER_TEXT = BANNER.decode().rstrip("\r\n")
LOCKED_TEXT = LOCKED.decode().rstrip("\r\n")


def test_startup_lines_are_validated_stored_and_run_after_every_reset() -> None:
    with grbl() as (emulator, line):
        assert line.ask("$N0=G20") == "ok"
        assert line.ask("$N1=G5") == "error:20"  # executed to check it: refused, not stored
        line.send(b"$N\n")
        assert line.lines(3) == ["$N0=G20", "$N1=", "ok"]
        line.send(b"\x18")
        assert line.lines(2) == [BANNER_TEXT, ">G20:ok"]
        assert line.ask("G91 G0 X3 Y3") == "ok"  # inches, from the startup line
        line.idle()
        assert emulator.machine_position() == pytest.approx((76.2, 76.2, 0.0))
        # A line valid when stored (F was set) can fail at startup: echoed with its error.
        assert line.ask("G21 G1 F100") == "ok"
        assert line.ask("$N1=G1X1") == "ok"
        line.idle()
        line.send(b"\x18")
        assert line.lines(3) == [BANNER_TEXT, ">G20:ok", ">G1X1:error:22"]
        assert emulator.startup_lines == ["G20", "G1X1"]
        line.send(b"$G\n")
        assert line.lines(2)[0].startswith("[GC:G0 G54 G17 G20 G90")  # the G1 was refused


def test_startup_lines_are_stored_only_when_idle_and_skipped_in_alarm() -> None:
    with grbl({22: 1, 24: 6000.0, 25: 30000.0}, startup_lines=["G20"]) as (emulator, line):
        assert emulator.state == "Alarm"  # no startup lines in Alarm
        assert line.ask("$N1=G91") == "error:8"
        line.send(b"$G\n")
        assert "G21" in line.lines(2)[0]
        line.send(b"$H\n")  # a homing that succeeds runs them before its ok
        assert line.lines(2) == [">G20:ok", "ok"]


def test_inch_reports_with_13_equal_1() -> None:
    with grbl({10: 1, 110: 6000.0}) as (_, line):
        assert line.ask("G0 X-25.4 Y-50.8") == "ok"
        line.idle()
        assert line.ask("$13=1") == "ok"
        assert line.ask("G92 X0") == "ok"
        report = line.status()
        assert report.startswith("<Idle|MPos:-1.0000,-2.0000,0.0000|FS:0.0,0")
        assert "|WCO:-1.0000,0.0000,0.0000" in report
        line.send(b"$G\n")
        modes = line.lines(2)[0]
        assert modes.startswith("[GC:G0 G54 G17 G21 G90") and "F0.0" in modes  # inch/min
        line.send(b"$#\n")
        parameters = line.lines(12)
        assert "[G92:-1.0000,0.0000,0.0000]" in parameters and "[TLO:0.0000]" in parameters
        assert line.ask("G1 Y-101.6 F1270") == "ok"  # 50 inch/min
        time.sleep(0.5)
        assert "|FS:50.0,0" in line.status()


def test_position_at_power_up_and_in_steps() -> None:
    with grbl(position=(-5.0, 0.0, 0.0)) as (emulator, line):
        assert line.status().startswith("<Idle|MPos:-5.000,0.000,0.000")
        assert line.ask("G91 G0 X1") == "ok"  # the parser starts where the machine is
        line.idle()
        assert emulator.machine_position() == pytest.approx((-4.0, 0.0, 0.0))
    with grbl() as (emulator, line):
        assert line.status().startswith("<Idle|MPos:0.000,0.000,0.000")
        line.ask("G0 X-10 Y-10")
        line.idle()
        assert line.ask("$100=500") == "ok"  # twice the steps per mm: the steps stay
        assert line.status().startswith("<Idle|MPos:-5.000,-10.000,0.000")
        assert emulator.machine_position() == pytest.approx((-5.0, -10.0, 0.0))
        line.ask("G90 G0 X-10")  # the parser still thinks -10: GRBL moves by its own steps
        line.idle()
        assert emulator.machine_position()[0] == pytest.approx(-10.0)


def test_reset_to_continue_comes_after_a_pause_and_an_early_reset_is_discarded() -> None:
    with grbl() as (emulator, line):
        emulator.inject_alarm(1)
        alarmed = time.monotonic()
        assert line.lines(1) == ["ALARM:1"]
        line.send(b"\x18?")  # during GRBL's pause: the reset is dropped, nothing answered
        assert line.lines(1) == ["[MSG:Reset to continue]"]
        assert time.monotonic() - alarmed >= 0.45
        assert line.quiet(0.1) == b""
        assert emulator.state == "Alarm"
        line.send(b"\x18")
        assert line.quiet(0.1) == BANNER + LOCKED
    with grbl(critical_message_delay_s=0.1) as (emulator, line):
        emulator.inject_alarm(2)
        alarmed = time.monotonic()
        assert line.lines(2) == ["ALARM:2", "[MSG:Reset to continue]"]
        assert 0.08 <= time.monotonic() - alarmed < 0.45


@pytest.mark.parametrize("code", [8, 9])
def test_a_failed_homing_alarms_then_resets_itself(code: int) -> None:
    settings = {22: 1, 24: 6000.0, 25: 30000.0, 27: 2.0, 130: 20.0, 131: 20.0, 132: 20.0}
    with grbl(settings, GrblFaults(homing_fails=code)) as (emulator, line):
        line.send(b"$H\n")
        assert line.lines(1) == [f"ALARM:{code}"]
        line.send(b"\x18?")  # absorbed: GRBL is resetting already
        assert line.quiet(0.2) == b""
        assert line.lines(3) == ["ok", BANNER_TEXT, LOCKED_TEXT]
        assert line.quiet(0.1) == b""
        assert emulator.state == "Alarm"
        assert line.ask("G0 X-1") == "error:9"


def test_limit_switches_show_in_pn_and_every_edge_is_a_hard_limit() -> None:
    with grbl() as (emulator, line):
        emulator.press_limit("x")  # hard limits off ($21=0): only the pin shows
        assert "|Pn:X" in line.status() and emulator.state == "Idle"
        emulator.release_limit("X")
        assert "Pn:" not in line.status()
    with grbl({21: 1}) as (emulator, line):
        emulator.press_limit("Y")
        assert line.lines(2) == ["ALARM:1", "[MSG:Reset to continue]"]
        line.send(b"\x18")  # still pressed: GRBL checks the limits after the banner
        assert line.lines(3) == [BANNER_TEXT, "[MSG:Check Limits]", LOCKED_TEXT]
        assert line.status().startswith("<Alarm|") and "|Pn:Y" in line.status()
        line.ask("$X")
        line.lines(1)
        emulator.release_limit("Y")  # the release is an edge too
        assert line.lines(2) == ["ALARM:1", "[MSG:Reset to continue]"]
        line.send(b"\x18")
        assert line.lines(2) == [BANNER_TEXT, LOCKED_TEXT]
        assert "Pn:" not in line.status()


def test_laser_mode_lights_only_with_motion() -> None:
    # 10 units/s at 40 units/s^2: a 5-unit move accelerates for 0.25 s, cruises, decelerates.
    with grbl({32: 1, 110: 600.0, 120: 40.0}) as (emulator, line):
        assert line.ask("M3 S500") == "ok"  # G0 mode: no power
        assert emulator.light == LightState(False, 0.0, "off")
        reports = [line.status() for _ in range(3)]
        assert all("|FS:0,0" in r for r in reports) and not any("|A:" in r for r in reports)
        line.send(b"$G\n")
        assert " M3 " in line.lines(2)[0]  # the modal state is M3 S500
        assert line.ask("G1 X-5 F600") == "ok"
        time.sleep(0.4)
        assert emulator.state == "Run" and emulator.light == LightState(True, 0.5, "spindle")
        assert "|FS:600,500" in line.status()
        line.idle()
        assert emulator.light.on  # M3 is constant power: it stays on when the motion stops
        assert line.ask("G0 X0") == "ok"
        time.sleep(0.2)
        assert emulator.state == "Run" and not emulator.light.on  # rapids are never powered
        line.idle()
        assert line.ask("M4") == "ok"  # dynamic power: dark at rest
        assert not emulator.light.on
        assert line.ask("G1 X-5") == "ok"
        time.sleep(0.1)
        accelerating = emulator.light
        time.sleep(0.3)
        cruising = emulator.light
        assert 0.0 < accelerating.intensity < 0.4 and cruising.intensity == pytest.approx(0.5)
        assert any("|A:C" in line.status() for _ in range(2))
        line.idle()
        assert not emulator.light.on  # M4 goes dark when motion ends
        assert line.ask("G1 X0") == "ok"
        time.sleep(0.2)
        line.send(b"!")
        time.sleep(0.4)
        assert line.status().startswith("<Hold:0") and not emulator.light.on
        line.send(b"~")
        assert line.lines(1) == ["[MSG:Restoring spindle]"]
        time.sleep(0.1)
        assert emulator.light.on
    with grbl() as (emulator, line):
        assert line.ask("M3 S500") == "ok"  # $32=0: the spindle runs at once
        assert emulator.light == LightState(True, 0.5, "spindle")


def test_arcs_follow_the_circle() -> None:
    with grbl({10: 3}) as (emulator, line):
        line.send(b"G17 G2 X-20 Y0 I-10 J0 F3000\n")  # 78 segments: more than the planner holds
        samples = []
        deadline = time.monotonic() + 10
        while emulator.state == "Idle" and time.monotonic() < deadline:
            time.sleep(0.001)
        while emulator.state != "Idle" and time.monotonic() < deadline:
            samples.append(emulator.machine_position())
            time.sleep(0.005)
        assert line.lines(1) == ["ok"]
        assert emulator.machine_position() == pytest.approx((-20.0, 0.0, 0.0))
        assert len(samples) > 20
        radii = [math.hypot(x + 10.0, y) for x, y, _ in samples]
        assert all(abs(r - 10.0) < 0.01 for r in radii)  # chords within $12 of the circle
        assert min(y for _, y, _ in samples) == pytest.approx(-10.0, abs=0.05)  # clockwise
        assert line.ask("G3 X0 Y0 R10") == "ok"  # radius format, back along the other half
        line.idle()
        assert emulator.machine_position() == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
        assert line.ask("G91 G2 X0 I5") == "ok"  # a full circle back to the start
        line.idle()
        assert emulator.machine_position() == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)


ARC_ERRORS = [
    ("G90 G2 I1", "error:26"),  # no axis words
    ("G2 Z-1 I1", "error:32"),  # none in the plane
    ("G2 X-1", "error:35"),  # no offsets in the plane (and no R)
    ("G2 X-5 I1", "error:33"),  # the radii to start and target differ
    ("G91 G2 X0 Y0 R5", "error:33"),  # R mode: the target is the start
    ("G2 X-50 R10", "error:34"),  # the radius is shorter than half the chord
    ("G2 X-3 R2 I1", "error:36"),  # I unused with R
    ("G53 G2 X-1 I1", "error:30"),
    ("G1 X-1 R1", "error:36"),
]


@pytest.mark.parametrize(("command", "reply"), ARC_ERRORS)
def test_arc_errors(shared: Line, command: str, reply: str) -> None:
    assert shared.ask("G90 G1 F100") == "ok"
    assert shared.ask(command) == reply


def test_sleep_until_a_reset_wakes_it_locked() -> None:
    with grbl() as (emulator, line):
        assert line.ask("M3 S500") == "ok" and line.ask("M8") == "ok"
        line.send(b"$SLP\n")
        assert line.lines(2) == ["ok", "[MSG:Sleeping]"]
        assert emulator.light == LightState(False, 0.0, "off")
        assert line.status().startswith("<Sleep|")
        line.send(b"G0 X-1\n!~$X\n")  # nothing but a reset is acted on
        assert line.quiet(0.2) == b""
        assert line.status().startswith("<Sleep|") and emulator.lines[-1] == "$SLP"
        line.send(b"\x18")
        assert line.quiet(0.1) == BANNER + LOCKED  # as after an alarm: the position is lost
        assert emulator.state == "Alarm" and emulator.machine_position() == (0.0, 0.0, 0.0)
        assert line.ask("G0 X-1") == "error:9"


def test_spindle_and_coolant_changes_wait_for_the_planner() -> None:
    with grbl({110: 600.0}) as (emulator, line):
        assert line.ask("G1 X-5 F600") == "ok"  # about half a second
        started = time.monotonic()
        line.serial.timeout = 0.1
        line.send(b"M8\n")
        assert line.serial.readline() == b""  # a host that gives up early...
        assert emulator.state == "Run" and not emulator.light.on
        line.serial.timeout = 1.5
        assert line.lines(1) == ["ok"]  # ...sees the ok late, once the motion is done
        assert time.monotonic() - started >= 0.4
        assert emulator.state == "Idle" and emulator.light == LightState(True, 1.0, "coolant")
        assert line.ask("G1 X0") == "ok"
        assert line.ask("M8") == "ok"  # no change: GRBL does not wait
        assert emulator.state == "Run"
        assert line.ask("M3 S100") == "ok"  # a change waits again
        assert emulator.state == "Idle" and emulator.light.intensity == pytest.approx(0.1)

"""The GRBL gantry driver against the byte-level emulator, through the real pyserial."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.errors import DeviceError, InputError, ProtocolError, SafetyError
from rig.grbl import (
    GantryAxes,
    GantryAxisConfig,
    GrblAlarmError,
    GrblCommandError,
    GrblGantry,
    GrblTimeoutError,
)
from rig.grbl_protocol import (
    ALARM_CODES,
    ERROR_CODES,
    ReplyKind,
    classify,
    parse_status,
    validate_command,
)
from sim.grbl.emulator import FaultRule, GrblEmulator, GrblFaults, LightState
from sim.grbl.motion import Profile

FAST = {110: 36000.0, 111: 36000.0, 112: 36000.0, 120: 20000.0, 121: 20000.0, 122: 20000.0}
AXES = GantryAxes(GantryAxisConfig("X", -180.0, 180.0), GantryAxisConfig("Y", 0.0, 90.0))


@contextmanager
def rig(
    settings: dict[int, float] | None = None,
    faults: GrblFaults | None = None,
    axes: GantryAxes = AXES,
    **options: object,
) -> Iterator[tuple[GrblEmulator, GrblGantry]]:
    """An emulator and a connected driver; both closed afterwards."""
    kwargs: dict[str, object] = {"feed_deg_min": 30000.0, "timeout_s": 0.5}
    kwargs.update(options)
    with GrblEmulator(settings={**FAST, **(settings or {})}, faults=faults) as emulator:
        gantry = GrblGantry(emulator.port, 115200, axes, **kwargs)  # type: ignore[arg-type]
        with gantry:
            yield emulator, gantry


@pytest.fixture(scope="module")
def shared() -> Iterator[tuple[GrblEmulator, GrblGantry]]:
    with rig() as pair:
        yield pair


# -- connect ------------------------------------------------------------------------------------


def test_connect_soft_resets_and_reads_the_banner_and_settings() -> None:
    with rig() as (emulator, gantry):
        assert emulator.received.startswith(b"\x18")
        assert gantry.version == "1.1h"
        assert "$$" in emulator.lines
        assert gantry.settings()[110] == 36000.0
        assert gantry.status().state == "Idle"


def test_connect_without_banner_names_the_port() -> None:
    master, slave = os.openpty()  # a serial line where nothing answers
    try:
        gantry = GrblGantry(os.ttyname(slave), 115200, AXES, timeout_s=0.1)
        with pytest.raises(DeviceError, match=rf"no GRBL banner from {os.ttyname(slave)}"):
            gantry.connect()
        assert os.read(master, 100) == b"\x18\x18"  # two soft resets, nothing else
    finally:
        os.close(master)
        os.close(slave)


def test_connect_to_a_missing_port_names_it() -> None:
    with pytest.raises(DeviceError, match="/dev/does-not-exist"):
        GrblGantry("/dev/does-not-exist", 115200, AXES).connect()


# -- status reports -----------------------------------------------------------------------------

STATUS_CASES = [
    ("<Idle|MPos:0.000,0.000,0.000|FS:0,0>", "Idle", None, (0.0, 0.0, 0.0), None),
    ("<Hold:1|MPos:1.5,-2.000,3.000|FS:500,8000|WCO:1,1,1>", "Hold", 1, (1.5, -2.0, 3.0), None),
    ("<Door:2|WPos:-2.500,0.000,11.000|F:500|WCO:0.000,1.551,5.664>", "Door", 2, None, None),
    (
        "<Run|WPos:1.000,2.000,3.000|Bf:15,128|FS:100,0|Ov:100,100,100|A:SF>",
        "Run",
        None,
        None,
        None,
    ),
    ("<Alarm|MPos:0.000,0.000,0.000|FS:0,0|Pn:XZ>", "Alarm", None, (0.0, 0.0, 0.0), None),
]


@pytest.mark.parametrize(("line", "state", "sub", "mpos", "_unused"), STATUS_CASES)
def test_status_examples(
    line: str, state: str, sub: int | None, mpos: tuple[float, ...] | None, _unused: object
) -> None:
    status = parse_status(line)
    assert (status.state, status.substate, status.mpos) == (state, sub, mpos)


def test_status_work_position_converts_with_wco() -> None:
    status = parse_status("<Idle|WPos:-2.500,0.000,11.000|FS:0,0|WCO:0.000,1.551,5.664>")
    assert status.machine_position() == pytest.approx((-2.5, 1.551, 16.664))
    later = parse_status("<Idle|WPos:1.000,1.000,1.000|FS:0,0>")
    assert later.machine_position() is None
    assert later.machine_position((1.0, 2.0, 3.0)) == (2.0, 3.0, 4.0)


@pytest.mark.parametrize(
    "line", ["Idle|MPos:0,0,0", "<Walk|MPos:0,0,0>", "<Idle|FS:0,0>", "<Idle|MPos:0,x,0>"]
)
def test_malformed_status_is_refused(line: str) -> None:
    with pytest.raises(ValueError):
        parse_status(line)


_coords = st.tuples(*[st.floats(-1e4, 1e4, allow_nan=False).map(lambda v: round(v, 3))] * 3)


@settings(max_examples=200)
@given(
    state=st.sampled_from(["Idle", "Run", "Hold:0", "Hold:1", "Jog", "Alarm", "Door:1", "Home"]),
    machine=st.booleans(),
    position=_coords,
    optional=st.permutations(["Bf", "Ln", "FS", "Pn", "WCO", "Ov"]),
    keep=st.lists(st.booleans(), min_size=6, max_size=6),
    wco=_coords,
    feed=st.integers(0, 50000),
)
def test_status_fields_in_any_order(
    state: str,
    machine: bool,
    position: tuple[float, float, float],
    optional: list[str],
    keep: list[bool],
    wco: tuple[float, float, float],
    feed: int,
) -> None:
    text = {
        "Bf": "Bf:15,128",
        "Ln": "Ln:42",
        "FS": f"FS:{feed},1000",
        "Pn": "Pn:XP",
        "WCO": "WCO:" + ",".join(f"{v:.3f}" for v in wco),
        "Ov": "Ov:100,120,80|A:SF",
    }
    fields = [text[name] for name, kept in zip(optional, keep, strict=True) if kept]
    pos = ("MPos:" if machine else "WPos:") + ",".join(f"{v:.3f}" for v in position)
    status = parse_status("<" + "|".join([state, pos, *fields]) + ">")
    assert status.state == state.split(":")[0]
    assert (status.mpos if machine else status.wpos) == pytest.approx(position)
    present = {name for name, kept in zip(optional, keep, strict=True) if kept}
    assert (status.wco is not None) == ("WCO" in present)
    assert (status.feed == feed) == ("FS" in present)
    assert status.overrides == ((100, 120, 80) if "Ov" in present else None)
    assert status.accessories == ("SF" if "Ov" in present else None)
    assert status.buffer == ((15, 128) if "Bf" in present else None)
    assert status.pins == ("XP" if "Pn" in present else "")


def test_code_tables_are_complete_and_in_words() -> None:
    assert sorted(ERROR_CODES) == [*range(1, 18), *range(20, 39)]
    assert sorted(ALARM_CODES) == list(range(1, 10))
    assert "locked out" in ERROR_CODES[9]
    assert "Hard limit" in ALARM_CODES[1] and "Soft limit" in ALARM_CODES[2]


@pytest.mark.parametrize(
    ("line", "kind", "code"),
    [
        ("ok", ReplyKind.OK, None),
        ("error:22", ReplyKind.ERROR, 22),
        ("ALARM:2", ReplyKind.ALARM, 2),
        ("Grbl 1.1h ['$' for help]", ReplyKind.BANNER, None),
        ("[MSG:'$H'|'$X' to unlock]", ReplyKind.MESSAGE, None),
        ("[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]", ReplyKind.FEEDBACK, None),
        ("$110=500.000", ReplyKind.SETTING, None),
        (">G54G20:ok", ReplyKind.STARTUP, None),
        ("o\ufffdk", ReplyKind.UNKNOWN, None),
    ],
)
def test_classify(line: str, kind: ReplyKind, code: int | None) -> None:
    reply = classify(line)
    assert (reply.kind, reply.code) == (kind, code)


# -- commands refused before sending ---------------------------------------------------------


@pytest.mark.parametrize(
    ("command", "problem"),
    [
        ("G1 X1 %", "program delimiter"),
        ("G1 X1\nG1 X2", "newline"),
        ("G1 X1\r", "newline"),
        ("M3 S1\u00e9", "non-ASCII"),
        ("G1 X1 ?", "real-time"),
        ("G1 X1 !", "real-time"),
        ("\x18", "control character"),
        ("", "empty"),
        ("G1 X" + "1" * 80, "at most 79"),
    ],
)
def test_forbidden_commands_are_refused_before_writing(
    shared: tuple[GrblEmulator, GrblGantry], command: str, problem: str
) -> None:
    with pytest.raises(InputError, match=problem):
        validate_command(command, port="/dev/x")
    emulator, gantry = shared
    before = emulator.received
    with pytest.raises(InputError, match=problem):
        gantry._command(command)
    time.sleep(0.01)
    assert emulator.received == before


@pytest.mark.parametrize(
    ("azimuth", "inclination"), [(181.0, 10.0), (0.0, -0.5), (0.0, 90.01), (math.nan, 0.0)]
)
def test_soft_limits_refused_before_writing(
    shared: tuple[GrblEmulator, GrblGantry], azimuth: float, inclination: float
) -> None:
    emulator, gantry = shared
    before = emulator.received
    with pytest.raises(SafetyError, match="nothing was sent"):
        gantry.move_to_deg(azimuth, inclination)
    time.sleep(0.01)
    assert emulator.received == before


# -- motion -------------------------------------------------------------------------------------


def test_moves_arrive_with_the_motion_models_timing() -> None:
    with rig() as (emulator, gantry):
        start = time.monotonic()
        status = gantry.move_to_deg(90.0, 45.0)
        elapsed = time.monotonic() - start
        assert status is not None and status.state == "Idle"
        assert emulator.position_deg() == pytest.approx((90.0, 45.0), abs=1e-9)
        assert gantry.position_deg() == pytest.approx((90.0, 45.0))
        length = math.hypot(90.0, 45.0)
        u = (90.0 / length, 45.0 / length)
        accel = min(20000.0 / u[0], 20000.0 / u[1])
        rate = min(30000.0, 36000.0 / u[0], 36000.0 / u[1]) / 60.0
        expected = Profile.plan(length, 0.0, rate, accel).duration
        assert expected <= elapsed < expected + 2.0  # generous: CI machines are loaded
        assert any(line.startswith("G21G90G53G1X90.000Y45.000F") for line in emulator.lines)


def test_axis_mapping_offset_direction_and_scale() -> None:
    axes = GantryAxes(
        GantryAxisConfig("Y", -180.0, 180.0, offset_deg=10.0, direction=-1, units_per_deg=2.0),
        GantryAxisConfig("X", 0.0, 90.0, offset_deg=90.0),
    )
    with rig(axes=axes) as (emulator, gantry):
        gantry.move_to_deg(30.0, 60.0)
        assert emulator.machine_position()[:2] == pytest.approx((-30.0, -40.0))
        assert gantry.position_deg() == pytest.approx((30.0, 60.0))


def test_work_position_reports_are_converted_with_wco() -> None:
    with rig(settings={10: 0}) as (emulator, gantry):
        gantry._command("G92 X5 Y-5")  # a stray work offset on the controller
        gantry.move_to_deg(20.0, 30.0)
        assert gantry.status().wpos is not None
        assert emulator.position_deg() == pytest.approx((20.0, 30.0))
        assert gantry.position_deg() == pytest.approx((20.0, 30.0))


def test_feed_hold_and_resume_during_a_move() -> None:
    with rig(feed_deg_min=1200.0, timeout_s=1.0) as (emulator, gantry):
        gantry.move_to_deg(10.0, 0.0, wait=False)  # 0.5 s at 20 deg/s
        time.sleep(0.15)
        gantry.feed_hold()
        held = gantry._wait_for(lambda s: s.substate == 0, 1.0, "test")
        assert held.state == "Hold"
        first = emulator.position_deg()
        time.sleep(0.1)
        assert emulator.position_deg() == first
        assert 0.0 < first[0] < 10.0
        gantry.resume()
        assert gantry.status().state == "Run"
        final = gantry.wait_until_idle(5.0)
        assert final.mpos == pytest.approx((10.0, 0.0, 0.0))


def test_wait_until_idle_times_out_during_a_hold() -> None:
    with rig(feed_deg_min=600.0) as (_, gantry):
        gantry.move_to_deg(30.0, 0.0, wait=False)
        gantry.feed_hold()
        with pytest.raises(GrblTimeoutError, match="Hold"):
            gantry.wait_until_idle(0.15)


# -- alarms, unlock, homing ---------------------------------------------------------------------


def test_emulator_soft_limit_alarm_then_lockout_then_explicit_unlock() -> None:
    wide = GantryAxes(GantryAxisConfig("X", -500, 500), GantryAxisConfig("Y", -500, 500))
    homing = {20: 1, 22: 1, 130: 100.0, 131: 100.0, 132: 100.0}
    with rig(settings=homing, axes=wide) as (emulator, gantry):
        assert gantry.status().state == "Alarm"  # power-up with homing enabled
        assert "$X" not in emulator.lines  # never unlocked behind the operator's back
        with pytest.raises(GrblCommandError, match=r"error:9 \(G-code lock.*unlock"):
            gantry.move_to_deg(-10.0, -10.0)
        gantry.unlock()
        gantry.move_to_deg(-10.0, -10.0)
        with pytest.raises(GrblAlarmError, match=r"ALARM:2.*Soft limit") as alarm:
            gantry.move_to_deg(10.0, -10.0)  # GRBL's machine space is -100..0
        assert alarm.value.code == 2 and emulator.port in str(alarm.value)
        assert "G90 G53 G1 X10.000" in alarm.value.command
        assert gantry.status().state == "Alarm"
        with pytest.raises(GrblCommandError) as refused:
            gantry.move_to_deg(-20.0, -10.0)
        assert refused.value.code == 9 and "locked out" in refused.value.meaning
        assert gantry.position_deg() == pytest.approx((-10.0, -10.0))  # retained (ALARM:2)
        gantry.unlock()
        gantry.move_to_deg(-20.0, -10.0)


def test_unlock_on_connect_is_a_config_decision() -> None:
    with rig(settings={22: 1}, unlock_on_connect=True) as (emulator, gantry):
        assert "$X" in emulator.lines
        assert gantry.status().state == "Idle"


def test_homing_enabled() -> None:
    with rig(settings={22: 1, 24: 6000.0, 25: 30000.0, 27: 2.0}) as (emulator, gantry):
        status = gantry.home()
        assert status.state == "Idle"
        assert emulator.machine_position() == pytest.approx((-2.0, -2.0, -2.0))


def test_homing_disabled_is_refused_before_sending() -> None:
    with rig() as (emulator, gantry):
        with pytest.raises(DeviceError, match=r"homing is disabled \(\$22=0\)"):
            gantry.home()
        assert "$H" not in emulator.lines
        with pytest.raises(GrblCommandError, match="error:5"):
            gantry._command("$H")  # GRBL itself refuses too


def test_settings_round_trip() -> None:
    with rig() as (emulator, gantry):
        gantry.set_setting(22, 1)
        gantry.set_setting(20, 1)
        assert emulator.settings[20] == 1
        gantry.set_setting(22, 0)  # GRBL drops soft limits with homing
        assert gantry.settings()[20] == 0
        with pytest.raises(GrblCommandError, match="error:10"):
            gantry.set_setting(20, 1)


# -- light --------------------------------------------------------------------------------------


def test_spindle_light_intensity() -> None:
    with rig() as (emulator, gantry):
        gantry.light_on(0.25)
        assert emulator.light == LightState(True, 0.25, "spindle")
        gantry.light_on()
        assert emulator.light == LightState(True, 1.0, "spindle")
        gantry.light_off()
        assert emulator.light == LightState(False, 0.0, "off")
        with pytest.raises(InputError):
            gantry.light_on(1.5)


def test_coolant_light_is_on_off() -> None:
    with rig(light="coolant") as (emulator, gantry):
        gantry.light_on()
        assert emulator.light == LightState(True, 1.0, "coolant")
        before = emulator.received
        with pytest.raises(InputError, match="on/off only"):
            gantry.light_on(0.5)
        assert emulator.received == before
        gantry.light_off()
        assert not emulator.light.on


def test_context_manager_turns_the_light_off_on_an_exception() -> None:
    with GrblEmulator(settings=FAST) as emulator:
        with pytest.raises(RuntimeError), GrblGantry(emulator.port, 115200, AXES) as gantry:
            gantry.light_on(0.5)
            assert emulator.light.on
            raise RuntimeError("capture failed")
        assert emulator.light == LightState(False, 0.0, "off")
        assert emulator.state == "Idle"


def test_context_manager_stops_a_move_and_keeps_the_position() -> None:
    with GrblEmulator(settings=FAST) as emulator:
        with (
            pytest.raises(RuntimeError),
            GrblGantry(emulator.port, 115200, AXES, feed_deg_min=600.0) as gantry,
        ):
            gantry.light_on(1.0)
            gantry.move_to_deg(90.0, 0.0, wait=False)  # 9 s
            time.sleep(0.2)
            raise RuntimeError("operator abort")
        stopped = emulator.position_deg()
        time.sleep(0.1)
        assert emulator.position_deg() == stopped and 0.0 < stopped[0] < 90.0
        assert emulator.state == "Idle"  # reset at Hold:0: no ALARM:3
        assert not emulator.light.on


# -- faults -------------------------------------------------------------------------------------


def test_a_lost_reply_is_never_resent_the_gantry_stops_instead() -> None:
    # The line ran, its ok was lost: sending it again could run it twice, and its late ok would
    # be taken for the next line's. The driver stops the gantry and says so.
    faults = GrblFaults(drop_reply=FaultRule(pattern=r"^\$\$$", limit=1))
    with GrblEmulator(settings=FAST, faults=faults) as emulator:
        gantry = GrblGantry(emulator.port, 115200, AXES, timeout_s=0.1)
        with pytest.raises(GrblTimeoutError, match=r"outcome is unknown.*stopped") as lost:
            gantry.connect()
        assert lost.value.command == "$$" and emulator.port in str(lost.value)
        assert emulator.lines.count("$$") == 1
        assert not gantry.link.is_open


def test_a_move_whose_reply_is_lost_is_stopped_not_resent() -> None:
    faults = GrblFaults(drop_reply=FaultRule(pattern="G1", limit=1))
    with rig(faults=faults, feed_deg_min=600.0, timeout_s=0.1) as (emulator, gantry):
        with pytest.raises(GrblTimeoutError, match="outcome is unknown"):
            gantry.move_to_deg(45.0, 10.0)
        assert sum("G1" in line for line in emulator.lines) == 1
        status = gantry.status()
        assert status.state == "Idle"  # feed hold, then a reset at Hold:0: no alarm
        azimuth, _ = gantry.position_deg()
        assert 0.0 <= azimuth < 45.0  # stopped on the way, position kept
        gantry.move_to_deg(45.0, 10.0)  # the gantry is ready again: a new, known move
        assert emulator.position_deg() == pytest.approx((45.0, 10.0))


def test_all_replies_lost_is_a_clean_error_naming_port_and_command() -> None:
    faults = GrblFaults(drop_reply=FaultRule())
    with GrblEmulator(settings=FAST, faults=faults) as emulator:
        gantry = GrblGantry(emulator.port, 115200, AXES, timeout_s=0.1, retries=1)
        with pytest.raises(GrblTimeoutError, match=rf"{emulator.port}.*'\$\$'"):
            gantry.connect()
        assert not gantry.link.is_open


def test_lost_status_reports_are_retried() -> None:
    faults = GrblFaults(seed=3, drop_status=FaultRule(probability=0.3))
    with rig(faults=faults, timeout_s=0.05, retries=8) as (emulator, gantry):
        gantry.move_to_deg(30.0, 20.0)
        gantry.move_to_deg(-30.0, 70.0)
        assert emulator.position_deg() == pytest.approx((-30.0, 70.0))


def test_delayed_replies_within_the_timeout_work() -> None:
    faults = GrblFaults(delay_reply=FaultRule(probability=0.5), delay_s=0.1, seed=2)
    with rig(faults=faults) as (emulator, gantry):
        gantry.move_to_deg(10.0, 10.0)
        gantry.light_on(0.5)
        assert emulator.light.intensity == 0.5


def test_reply_later_than_the_timeout_is_a_clean_error() -> None:
    faults = GrblFaults(delay_reply=FaultRule(pattern="M3"), delay_s=0.5)
    with rig(faults=faults, timeout_s=0.1, retries=0) as (emulator, gantry):
        with pytest.raises(GrblTimeoutError, match=rf"{emulator.port}.*'M3 S500.000'"):
            gantry.light_on(0.5)
        assert sum(line.startswith("M3") for line in emulator.lines) == 1
        gantry.light_off()  # the late ok was not taken for this line's: the reset dropped it
        assert not emulator.light.on


def test_line_noise_is_skipped() -> None:
    faults = GrblFaults(seed=5, garbage=FaultRule(probability=0.7))
    with rig(faults=faults) as (emulator, gantry):
        gantry.move_to_deg(15.0, 25.0)
        gantry.light_on(1.0)
        assert gantry.noise_lines > 0
        assert emulator.position_deg() == pytest.approx((15.0, 25.0))


def test_endless_noise_is_a_protocol_error() -> None:
    with rig() as (emulator, gantry):
        gantry.link._rx += b"\xff\xfe noise\r\n" * 60
        with pytest.raises(ProtocolError, match=emulator.port):
            gantry.status()


def test_hard_limit_alarm_mid_move() -> None:
    faults = GrblFaults(hard_limit_after_moves=2)
    with rig(faults=faults, feed_deg_min=12000.0) as (emulator, gantry):
        gantry.light_on(1.0)
        gantry.move_to_deg(10.0, 10.0)
        with pytest.raises(GrblAlarmError, match=r"ALARM:1 \(Hard limit") as alarm:
            gantry.move_to_deg(50.0, 10.0)
        assert alarm.value.port == emulator.port and "X50.000" in alarm.value.command
        assert not emulator.light.on  # GRBL kills spindle and coolant with the alarm
        assert 10.0 < emulator.position_deg()[0] < 50.0
        assert emulator.received.count(b"\x18") == 2  # connect, and the reset after ALARM:1
        status = gantry.status()
        assert status.state == "Alarm"
        with pytest.raises(GrblCommandError, match="error:9"):
            gantry.move_to_deg(0.0, 10.0)
        gantry.unlock()
        gantry.move_to_deg(0.0, 10.0)


def test_full_cycle_connect_home_move_light_alarm_unlock() -> None:
    settings = {22: 1, 24: 6000.0, 25: 30000.0, 27: 2.0}
    wide = GantryAxes(GantryAxisConfig("X", -180.0, 180.0), GantryAxisConfig("Y", -90.0, 90.0))
    faults = GrblFaults(hard_limit_after_moves=2)  # the second motion block
    with rig(settings=settings, faults=faults, axes=wide) as (emulator, gantry):
        assert gantry.status().state == "Alarm"  # homing enabled: locked until homed
        assert gantry.home().state == "Idle"
        gantry.move_to_deg(-30.0, -20.0)
        gantry.light_on(0.25)
        assert emulator.light.on and emulator.light.intensity == pytest.approx(0.25)
        with pytest.raises(GrblAlarmError, match="ALARM:1"):
            gantry.move_to_deg(-60.0, -40.0)
        assert not emulator.light.on  # GRBL switched the light off with the alarm
        with pytest.raises(GrblCommandError) as refused:
            gantry.move_to_deg(-40.0, -30.0)
        assert refused.value.code == 9
        gantry.unlock()
        gantry.move_to_deg(-40.0, -30.0)
        assert gantry.position_deg() == pytest.approx((-40.0, -30.0))
        gantry.light_on(1.0)
        gantry.light_off()
        assert not emulator.light.on


# -- the controller as the firmware really behaves ------------------------------------------


def test_a_startup_line_in_inches_cannot_turn_millimetres_into_inches() -> None:
    # `$N0=G20` runs after every reset: without pinning, X3 would be 3 inches (76.2 mm).
    with GrblEmulator(settings=FAST, startup_lines=["G20"]) as emulator:
        with GrblGantry(emulator.port, 115200, AXES, feed_deg_min=30000.0) as gantry:
            assert gantry.startup_lines == {0: "G20", 1: ""}
            assert {"G21", "G90", "G94"} <= gantry.modal_state()
            gantry.move_to_deg(3.0, 3.0)
            assert emulator.position_deg() == pytest.approx((3.0, 3.0))
            gantry.safe_stop()  # a reset: the startup line runs again, and is pinned again
            gantry.move_to_deg(6.0, 4.0)
            assert emulator.position_deg() == pytest.approx((6.0, 4.0))


def test_reports_in_inches_are_converted() -> None:
    with rig(settings={13: 1}) as (emulator, gantry):
        gantry.move_to_deg(10.0, 5.0)  # the arrival check reads the report: in inches here
        assert emulator.position_deg() == pytest.approx((10.0, 5.0))
        assert gantry.position_deg() == pytest.approx((10.0, 5.0), abs=3e-3)  # 0.0001 inch


def test_a_critical_alarm_is_reset_only_after_reset_to_continue() -> None:
    # GRBL discards a reset sent before it says "Reset to continue": a driver that resets at
    # once is never answered again.
    with GrblEmulator(
        settings=FAST, faults=GrblFaults(hard_limit_after_moves=1), critical_message_delay_s=0.8
    ) as emulator:
        with GrblGantry(emulator.port, 115200, AXES, feed_deg_min=600.0) as gantry:
            with pytest.raises(GrblAlarmError, match="ALARM:1") as alarm:
                gantry.move_to_deg(20.0, 0.0)
            assert "Reset to continue" not in str(alarm.value)  # it came: nothing to add
            assert gantry.status().state == "Alarm"  # the controller answers again
            gantry.unlock()
            gantry.move_to_deg(5.0, 0.0)
            assert emulator.position_deg() == pytest.approx((5.0, 0.0))


@pytest.mark.parametrize("code", [8, 9])
def test_a_failed_homing_is_one_alarm_not_an_unexpected_reset(code: int) -> None:
    settings = {22: 1, 24: 6000.0, 25: 30000.0, 27: 2.0}
    with rig(settings=settings, faults=GrblFaults(homing_fails=code)) as (_, gantry):
        with pytest.raises(GrblAlarmError, match=f"ALARM:{code}") as alarm:
            gantry.home()
        assert "reset unexpectedly" not in str(alarm.value)
        assert gantry.status().state == "Alarm"  # locked, and talking


def test_rates_and_accelerations_are_written_when_they_differ() -> None:
    axes = GantryAxes(
        GantryAxisConfig("X", -180.0, 180.0, max_rate_deg_min=6000.0, acceleration_deg_s2=360.0),
        GantryAxisConfig(
            "Y", 0.0, 90.0, units_per_deg=2.0, max_rate_deg_min=3000.0, acceleration_deg_s2=90.0
        ),
    )
    with GrblEmulator() as emulator:  # the firmware's defaults: 500 mm/min, 10 mm/s^2
        with GrblGantry(emulator.port, 115200, axes, feed_deg_min=3000.0):
            pass
        held = emulator.settings
        assert (held[110], held[120], held[111], held[121]) == (6000.0, 360.0, 6000.0, 180.0)
        writes = sum(line.startswith("$11") or line.startswith("$12") for line in emulator.lines)
        assert writes == 4
        with GrblGantry(emulator.port, 115200, axes, feed_deg_min=3000.0) as gantry:
            gantry.move_to_deg(30.0, 10.0)
        # Already right: nothing written the second time (EEPROM writes wear the memory).
        again = sum(line.startswith("$11") or line.startswith("$12") for line in emulator.lines)
        assert again == writes


def test_laser_mode_is_refused_before_anything_moves() -> None:
    with GrblEmulator(settings={**FAST, 32: 1}) as emulator:
        with pytest.raises(DeviceError, match=r"laser mode \(\$32=1\).*\$32=0"):
            GrblGantry(emulator.port, 115200, AXES).connect()
        assert not any("G1" in line for line in emulator.lines)


def test_a_startup_line_that_moves_is_refused() -> None:
    with GrblEmulator(settings=FAST, startup_lines=["G0 X10"]) as emulator:
        with pytest.raises(DeviceError, match=r"\$N0=G0 ?X10.*names an axis"):
            GrblGantry(emulator.port, 115200, AXES).connect()


def test_a_light_switch_behind_a_move_waits_for_it_and_replies_stay_in_step() -> None:
    # M3 is answered only once the planner is empty: the driver waits for the motion instead of
    # timing out, re-sending, and taking the late oks for the next line's.
    with rig(feed_deg_min=3000.0, timeout_s=0.2) as (emulator, gantry):
        gantry.move_to_deg(60.0, 0.0, wait=False)  # about 1.2 s of motion
        gantry.light_on(0.5)
        assert emulator.light.on and emulator.position_deg() == pytest.approx((60.0, 0.0))
        gantry.move_to_deg(5.0, 5.0)
        assert emulator.position_deg() == pytest.approx((5.0, 5.0))
        assert sum(line.startswith("M3") for line in emulator.lines) == 1


def test_status_is_polled_at_most_five_times_a_second_during_motion() -> None:
    with rig(feed_deg_min=3000.0) as (emulator, gantry):
        before = emulator.received.count(b"?")
        start = time.monotonic()
        gantry.move_to_deg(90.0, 0.0)  # about 1.8 s
        elapsed = time.monotonic() - start
        polls = emulator.received.count(b"?") - before
        assert elapsed > 1.5 and polls <= 5 * elapsed + 4

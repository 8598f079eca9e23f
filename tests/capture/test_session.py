from __future__ import annotations

import dataclasses
import hashlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from app.cli import main
from capture.dataset import Dataset
from capture.grid_plan import grid_plan
from capture.image_identity import strip_identity
from capture.journal import read_journal
from capture.plan import SweepPlan
from capture.session import CaptureSession, SessionResult, SessionState
from core.errors import DatasetError, DeviceError
from rig.config import RigConfig
from rig.config_cameras import CameraFaultConfig
from rig.hardware import Rig
from rig.safety import ForbiddenZone, pose_violation
from sim.dynamixel.faults import FaultConfig
from sim.grbl.emulator import GrblFaults
from sim.simulated_rig import SimulatedRig, simulated_capture_config

SIM = ["--sim", "--cameras", "2", "--lights", "5", "--size", "32", "--points", "1500",
       "--speed", "20", "--exposure-ms", "40", "--quiet"]  # fmt: skip


def _config(**camera: Any) -> RigConfig:
    config = simulated_capture_config("glossy-sphere", size=32, points=1500, speed=20.0)
    if camera:
        config = dataclasses.replace(config, camera=dataclasses.replace(config.camera, **camera))
    return config


def _plan() -> SweepPlan:
    """The plan `rig capture --sim` runs with SIM: 2 dark frames, 10 light images."""
    return grid_plan(2, 5, exposures_ms=(40.0,), layout="fibonacci")


@contextmanager
def _session(
    tmp: Path, config: RigConfig, plan: SweepPlan, name: str = "d", **faults: Any
) -> Iterator[tuple[CaptureSession, SimulatedRig, Rig]]:
    path = tmp / name
    if path.exists():
        dataset = Dataset.open(path)
    else:
        dataset = Dataset.create(
            path,
            rig_config=config.to_dict(),
            plan=plan.to_dict(),
            planned=plan.planned_keys(config),
        )
    with SimulatedRig(config, **faults) as simulated, simulated.rig() as rig:
        yield CaptureSession(rig, dataset, plan), simulated, rig


def _digests(path: Path) -> dict[str, str]:
    # The pixels' file without the identity written into it, which names its own dataset.
    return {
        f.name: hashlib.sha256(strip_identity(f.read_bytes())).hexdigest()
        for f in sorted((path / "images").iterdir())
    }


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """The images of an uninterrupted run."""
    tmp = tmp_path_factory.mktemp("reference")
    with _session(tmp, _config(), _plan()) as (session, simulated, _):
        result = session.run()
        assert not simulated.gantry.light.on
    assert result.exit_status == "success" and result.taken == len(_plan().planned_keys(_config()))
    return _digests(tmp / "d")


def test_a_clean_run_leaves_a_complete_verified_dataset(tmp_path: Path) -> None:
    with _session(tmp_path, _config(), _plan()) as (session, simulated, _):
        result = session.run()
        assert session.state == SessionState.STOPPED
        assert not simulated.gantry.light.on
    report = Dataset.open(tmp_path / "d").verify()
    assert report.ok and report.complete
    documents = read_journal(tmp_path / "d" / "journal.jsonl").documents
    kinds = [d["type"] for d in documents]
    assert kinds == ["start"] + ["event"] * result.taken + ["stop"]
    assert documents[-1]["exit_status"] == "success"
    assert set(result.seconds) == {"move", "light", "capture", "store", "total"}


def test_two_runs_of_a_plan_give_identical_images(
    tmp_path: Path, reference: dict[str, str]
) -> None:
    with _session(tmp_path, _config(), _plan()) as (session, _, _):
        session.run()
    assert _digests(tmp_path / "d") == reference


def test_pause_parks_and_resume_completes_the_same_dataset(
    tmp_path: Path, reference: dict[str, str]
) -> None:
    with _session(tmp_path, _config(), _plan()) as (session, simulated, rig):
        capture = rig.capture

        def capture_then_pause(exposure_ms: float) -> Any:
            if len(list((tmp_path / "d" / "images").iterdir())) == 3:
                session.request_pause()  # Ctrl-C during the fourth image
            return capture(exposure_ms)

        rig.capture = capture_then_pause  # type: ignore[method-assign]
        paused = session.run()
        assert paused.exit_status == "paused" and paused.taken == 4
        park = rig.config.park
        assert simulated.gantry.position_deg()[0] == pytest.approx(park.light_azimuth_deg)
        assert not simulated.gantry.light.on
    with _session(tmp_path, _config(), _plan()) as (session, _, _):
        resumed = session.run()
    assert resumed.exit_status == "success" and resumed.already_done == 4
    assert _digests(tmp_path / "d") == reference
    statuses = [
        d.get("exit_status") for d in read_journal(tmp_path / "d" / "journal.jsonl").documents
    ]
    assert [s for s in statuses if s] == ["paused", "success"]


FAULT_CASES = {
    "servo stops answering: failed, named": (
        {"servo_faults": FaultConfig(silent_ids=frozenset({2}), silent_after=30)},
        "failed",
        "servo 2",
    ),
    # A fault a reset clears pauses the run (a suspender), for a resume once it is fixed.
    "gantry alarm mid-move: paused, named": (
        {"gantry_faults": GrblFaults(hard_limit_after_moves=3)},
        "paused",
        "ALARM:1",
    ),
}


@pytest.mark.parametrize("case", FAULT_CASES)
def test_device_faults_are_retried_or_stop_cleanly(tmp_path: Path, case: str) -> None:
    options, status, words = FAULT_CASES[case]
    config = _config()
    try:
        with _session(tmp_path, config, _plan(), **options) as (session, simulated, _):
            result: SessionResult = session.run()
            assert not simulated.gantry.light.on  # off on every exit path
    except DeviceError as error:  # closing a rig with a silent servo says so
        assert "servo 2" in str(error) and status == "failed"
        result = _last_result(tmp_path / "d")
    assert result.exit_status == status and words in result.reason
    stop = read_journal(tmp_path / "d" / "journal.jsonl").documents[-1]
    assert stop["type"] == "stop" and stop["exit_status"] == status and words in stop["reason"]


def test_a_fault_the_operator_fixes_is_cleared_and_the_run_goes_on(
    tmp_path: Path, reference: dict[str, str]
) -> None:
    told: list[str] = []

    def operator(reason: str) -> bool:
        told.append(reason)
        return True  # "fixed it": the session unlocks the gantry and takes the image again

    with _session(
        tmp_path, _config(), _plan(), gantry_faults=GrblFaults(hard_limit_after_moves=3)
    ) as (
        session,
        simulated,
        _,
    ):
        session.on_fault = operator
        result = session.run()
        assert not simulated.gantry.light.on
    assert result.exit_status == "success", result.reason
    assert len(told) == 1 and "ALARM:1" in told[0]
    assert _digests(tmp_path / "d") == reference


def test_a_paused_fault_resumes_to_the_same_dataset(
    tmp_path: Path, reference: dict[str, str]
) -> None:
    faults = GrblFaults(hard_limit_after_moves=3)
    with _session(tmp_path, _config(), _plan(), gantry_faults=faults) as (session, _, _):
        assert session.run().exit_status == "paused"
    with _session(tmp_path, _config(), _plan()) as (session, _, _):
        assert session.run().exit_status == "success"
    assert _digests(tmp_path / "d") == reference


def _last_result(path: Path) -> SessionResult:
    stop = read_journal(path / "journal.jsonl").documents[-1]
    return SessionResult(stop["exit_status"], stop["reason"], 0, 0, 0)


def test_a_camera_timeout_is_retried(tmp_path: Path, reference: dict[str, str]) -> None:
    with _session(tmp_path, _config(), _plan()) as (session, _, rig):
        rig.camera.fail_next(2)  # type: ignore[union-attr]
        result = session.run()
    assert result.exit_status == "success"
    assert _digests(tmp_path / "d") == reference


def test_a_camera_that_never_answers_fails_the_run(tmp_path: Path) -> None:
    config = _config(faults=CameraFaultConfig(timeout_after=1, stall_s=0.0))
    with _session(tmp_path, config, _plan()) as (session, _, _):
        result = session.run()
    assert result.exit_status == "failed" and "no frame" in result.reason
    assert result.taken == 1


def test_a_corrupt_image_is_named_and_retaken(
    tmp_path: Path, reference: dict[str, str], capsys: pytest.CaptureFixture[str]
) -> None:
    with _session(tmp_path, _config(), _plan()) as (session, _, _):
        session.run()
    victim = sorted((tmp_path / "d" / "images").iterdir())[2]
    victim.write_bytes(victim.read_bytes()[:-10] + b"0123456789")
    assert main(["verify", str(tmp_path / "d")]) == 1
    assert victim.name in capsys.readouterr().out
    with _session(tmp_path, _config(), _plan()) as (session, _, _):
        result = session.run()
    assert result.retaken == 1 and result.taken == 1
    assert _digests(tmp_path / "d") == reference
    assert main(["verify", str(tmp_path / "d")]) == 0


def _kill_at(tmp: Path, events: int) -> Path:
    """Run `rig capture --sim` in a child and SIGKILL it once ``events`` images are journaled."""
    path = tmp / f"killed-{events}"
    child = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "capture", *SIM, "-o", str(path)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    journal = path / "journal.jsonl"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and child.poll() is None:
        if journal.exists() and journal.read_bytes().count(b'"type":"event"') >= events:
            break
        time.sleep(0.005)
    os.kill(child.pid, signal.SIGKILL)
    child.wait()
    return path


@pytest.mark.parametrize("events", [1, 4, 7])
def test_sigkill_then_resume_equals_an_uninterrupted_run(
    tmp_path: Path, reference: dict[str, str], events: int
) -> None:
    path = _kill_at(tmp_path, events)
    assert main(["capture", "--resume", str(path), "--quiet"]) == 0
    assert _digests(path) == reference
    dataset = Dataset.open(path)
    report = dataset.verify()
    assert report.ok and report.complete and not report.unexpected
    assert len(dataset.records) == len(reference)  # nothing duplicated


def test_resume_removes_what_a_kill_mid_write_left(
    tmp_path: Path, reference: dict[str, str]
) -> None:
    with _session(tmp_path, _config(), _plan()) as (session, _, rig):
        capture = rig.capture

        def capture_then_pause(exposure_ms: float) -> Any:
            session.request_pause()
            return capture(exposure_ms)

        rig.capture = capture_then_pause  # type: ignore[method-assign]
        assert session.run().exit_status == "paused"
    # A process killed between writing an image's temporary file and renaming it.
    stray = tmp_path / "d" / "images" / ".light_c001_l002_e0.4242.partial.png"
    stray.write_bytes(b"half an image")
    with _session(tmp_path, _config(), _plan()) as (session, _, _):
        assert session.run().exit_status == "success"
    assert not stray.exists()
    assert _digests(tmp_path / "d") == reference


def test_a_capture_from_an_unsafe_start_parks_first(tmp_path: Path) -> None:
    # The light was left at the camera (0 deg apart): the first move of the plan would start
    # unsafe; the executor leaves it by the park route, then captures as usual.
    config = _config()
    dataset = Dataset.create(
        tmp_path / "d", rig_config=config.to_dict(), plan=_plan().to_dict(),
        planned=_plan().planned_keys(config),
    )  # fmt: skip
    with SimulatedRig(config, light_start_deg=(0.0, 5.0)) as simulated, simulated.rig() as rig:
        assert pose_violation(config, rig.pose()) is not None
        result = CaptureSession(rig, dataset, _plan()).run()
    assert result.exit_status == "success", result.reason
    assert Dataset.open(tmp_path / "d").verify().complete


def test_a_capture_from_an_unsafe_start_without_a_way_out_says_what_to_do(
    tmp_path: Path,
) -> None:
    # The light starts too close to the camera, and a forbidden band lies between it and the
    # park pose: every route out crosses the band.
    config = _config()
    box = ForbiddenZone("band", light_inclination_deg=(20.0, 30.0))
    config = dataclasses.replace(
        config, safety=dataclasses.replace(config.safety, forbidden=(box,))
    )
    dataset = Dataset.create(
        tmp_path / "d", rig_config=config.to_dict(), plan=_plan().to_dict(),
        planned=_plan().planned_keys(config),
    )  # fmt: skip
    with SimulatedRig(config, light_start_deg=(0.0, 5.0)) as simulated, simulated.rig() as rig:
        result = CaptureSession(rig, dataset, _plan()).run()
        moves = sum("G1" in line for line in simulated.gantry.lines)
    assert result.exit_status == "failed"
    assert "which is unsafe" in result.reason and "by hand" in result.reason
    assert moves == 0


def test_a_second_capture_of_a_running_dataset_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A slow capture runs in a child; a resume of the same dataset must not start beside it
    # (it would drive the same ports and interleave its run in the journal).
    path = tmp_path / "busy"
    slow = [*SIM[:-2], "1", "--quiet"]  # real-time axes: the child takes seconds
    child = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "capture", *slow, "-o", str(path)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        journal = path / "journal.jsonl"
        deadline = time.monotonic() + 120
        while not (journal.exists() and b'"type":"start"' in journal.read_bytes()):
            assert time.monotonic() < deadline and child.poll() is None
            time.sleep(0.01)
        assert main(["capture", "--resume", str(path), "--quiet"]) == 2
        err = capsys.readouterr().err
        assert f"in use by process {child.pid}" in err and "one capture at a time" in err
    finally:
        child.kill()
        child.wait()
    # The holder is gone (killed): its lock went with it, and the resume completes the run.
    assert main(["capture", "--resume", str(path), "--quiet"]) == 0
    assert Dataset.open(path).verify().complete


def test_a_resume_with_another_rig_config_is_refused(tmp_path: Path) -> None:
    # The images of another object (another camera section) would mix into this dataset.
    with _session(tmp_path, _config(), _plan()) as (session, _, rig):
        capture = rig.capture

        def capture_then_pause(exposure_ms: float) -> Any:
            session.request_pause()
            return capture(exposure_ms)

        rig.capture = capture_then_pause  # type: ignore[method-assign]
        assert session.run().exit_status == "paused"
    other = simulated_capture_config("textured-torus", size=32, points=1500, speed=20.0)
    with _session(tmp_path, other, _plan()) as (session, simulated, _):
        with pytest.raises(DatasetError, match=r"captured with rig config sha256:.*camera differ"):
            session.run()
        assert not any("G1" in line for line in simulated.gantry.lines)
    # Its own config (on other ports: they may move between sessions) resumes it.
    with _session(tmp_path, _config(), _plan()) as (session, _, _):
        assert session.run().exit_status == "success"


@pytest.mark.parametrize("damage", ["deleted", "emptied"])
def test_a_dataset_whose_journal_is_gone_is_refused_not_retaken(
    tmp_path: Path, reference: dict[str, str], damage: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with _session(tmp_path, _config(), _plan()) as (session, _, _):
        assert session.run().exit_status == "success"
    journal = tmp_path / "d" / "journal.jsonl"
    if damage == "deleted":
        journal.unlink()
    else:
        journal.write_text("", encoding="utf-8")
    assert main(["verify", str(tmp_path / "d")]) == 1
    out = capsys.readouterr().out
    assert "NOT OK" in out and out.count("not journaled") == 1
    with _session(tmp_path, _config(), _plan()) as (session, simulated, _):
        with pytest.raises(DatasetError, match="journal does not vouch for 12 of its 12 images"):
            session.run()
        assert not any("G1" in line for line in simulated.gantry.lines)
    assert _digests(tmp_path / "d") == reference  # nothing was taken again over them


def test_an_interrupted_capture_is_processed_only_when_told_and_says_what_it_lacks(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with _session(tmp_path, _config(), _plan()) as (session, _, rig):
        capture = rig.capture
        taken = []

        def capture_then_pause(exposure_ms: float) -> Any:
            taken.append(exposure_ms)
            if len(taken) == 4:  # camera 0's dark frame and its first lights
                session.request_pause()
            return capture(exposure_ms)

        rig.capture = capture_then_pause  # type: ignore[method-assign]
        assert session.run().exit_status == "paused"
    argv = ["process", str(tmp_path / "d"), "-o", str(tmp_path / "f.zarr")]
    assert main(argv) == 2
    assert "were not taken" in capsys.readouterr().err
    assert main([*argv, "--allow-missing"]) == 0
    out = capsys.readouterr().out
    assert "planned images left out" in out and "the field lacks cameras [1]" in out

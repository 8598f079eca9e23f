"""The session's target hook and the simulated camera's calibration targets."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from capture.calibration_plan import with_calibration_captures
from capture.dataset import Dataset
from capture.grid_plan import grid_plan
from capture.plan import CaptureEvent, SweepPlan
from capture.session import CaptureSession
from core.errors import InputError
from rig.config import RigConfig
from rig.devices import Frame, LightState, frame_metadata
from rig.pose import RigPose
from sim.simulated_camera import TARGETS, SimulatedCamera
from sim.simulated_rig import simulated_capture_config


class FakeRig:
    """A rig that stands where it is told and returns tiny frames; logs what happens."""

    def __init__(self, config: RigConfig, log: list[object], *, stop_after: int = 0) -> None:
        self.config = config
        self.log = log
        self.session: CaptureSession | None = None
        self.stop_after = stop_after

    def move_to(self, pose: RigPose, *, wait: bool = True) -> RigPose | None:
        return pose

    def light_on(self, intensity: float = 1.0) -> None: ...

    def light_off(self) -> None: ...

    def capture(self, exposure_ms: float) -> Frame:
        self.log.append("image")
        if self.stop_after and self.log.count("image") == self.stop_after and self.session:
            self.session.request_pause()
        pixels = np.zeros((4, 4, 3), dtype=np.uint16)
        return Frame(pixels=pixels, metadata=frame_metadata(exposure_ms, "fake", "fake"))

    def park(self) -> RigPose | None:
        return None

    def pose(self) -> RigPose:
        return self.config.park

    def clear_faults(self) -> str:
        return ""

    def stop(self) -> None: ...


def _setup(tmp_path: Path) -> tuple[RigConfig, SweepPlan, Dataset]:
    config = simulated_capture_config("glossy-sphere", size=32, points=500, speed=20.0)
    plan = with_calibration_captures(grid_plan(2, 5, layout="grid"), config)
    dataset = Dataset.create(
        tmp_path / "d",
        rig_config=config.to_dict(),
        plan=plan.to_dict(),
        planned=plan.planned_keys(config),
    )
    return config, plan, dataset


def _expected(events: tuple[CaptureEvent, ...], plan: SweepPlan) -> list[object]:
    """Every image, with the target each one needs announced when it changes."""
    log: list[object] = []
    current: str | None = None
    for event in events:
        index = event.key.light_index
        needed = plan.calibration[index].name if event.key.kind == "calibration" else None
        if needed != current:
            log.append(("place", needed))
            current = needed
        log.append("image")
    return log


def test_the_placer_is_called_when_the_target_changes(tmp_path: Path) -> None:
    config, plan, dataset = _setup(tmp_path)
    names = [c.name for c in plan.calibration]
    assert names[:2] == ["charuco", "charuco"]
    assert set(names[2:]) == {"mirror-sphere", "white-target"} and len(names) == 12
    log: list[object] = []
    session = CaptureSession(
        FakeRig(config, log),
        dataset,
        plan,
        targets=lambda n: log.append(("place", n)),
    )
    assert session.run().exit_status == "success"
    events = plan.events(config)
    assert log == _expected(events, plan)
    # Calibration first, the object back before the first dark or light image.
    first_object = next(i for i, e in enumerate(events) if e.key.kind != "calibration")
    assert log.count(("place", None)) == 1
    assert log[: log.index(("place", None))].count("image") == first_object


def test_a_resumed_run_places_the_first_target_again(tmp_path: Path) -> None:
    config, plan, dataset = _setup(tmp_path)
    log: list[object] = []
    rig = FakeRig(config, log, stop_after=3)
    session = CaptureSession(rig, dataset, plan, targets=lambda n: log.append(n))
    rig.session = session
    assert session.run().exit_status == "paused"
    assert log == ["charuco", "image", "image", "mirror-sphere", "image"]
    log.clear()
    session = CaptureSession(
        FakeRig(config, log), Dataset.open(dataset.path), plan,
        targets=lambda n: log.append(n),
    )  # fmt: skip
    assert session.run().exit_status == "success"
    # The person may have left anything in place: the first pending image's target is asked for.
    assert log[0] == plan.calibration[3].name and log[1] == "image"
    assert log.count(None) == 1


def test_without_a_placer_calibration_plans_still_run(tmp_path: Path) -> None:
    config, plan, dataset = _setup(tmp_path)
    result = CaptureSession(FakeRig(config, []), dataset, plan).run()
    assert result.exit_status == "success" and result.taken == len(plan.events(config))


def _camera(pose: RigPose) -> SimulatedCamera:
    return SimulatedCamera(lambda: (pose, LightState(True, 1.0)), width=48, height=48, points=500)


POSE = RigPose(30.0, 40.0, 200.0, 50.0)


def test_simulated_targets_render_and_repeat_byte_for_byte() -> None:
    camera = _camera(POSE)
    scene = camera.capture(40.0).pixels
    images = {}
    for name in TARGETS:
        camera.place_target(name)
        first = camera.capture(40.0)
        assert first.metadata["target"] == name
        again = _camera(POSE)
        again.place_target(name)
        assert first.pixels is not None and again.capture(40.0).pixels is not None
        np.testing.assert_array_equal(first.pixels, again.capture(40.0).pixels)
        images[name] = first.pixels
    camera.place_target(None)
    np.testing.assert_array_equal(camera.capture(40.0).pixels, scene)
    assert len({img.tobytes() for img in images.values()} | {scene.tobytes()}) == 4
    # The chrome ball shows the light as a saturated highlight; the white target no highlight.
    assert images["mirror-sphere"].max() == 65535
    assert images["white-target"].max() < 65535


def test_an_unknown_target_lists_the_known_ones() -> None:
    with pytest.raises(InputError, match="charuco, mirror-sphere, white-target"):
        _camera(POSE).place_target("chessboard")

"""The capture executor: runs a sweep plan on a rig, one checkpoint per image, resumable.

A :class:`CaptureSession` is an explicit state machine (``SessionState``; allowed transitions
in ``TRANSITIONS``) in the manner of bluesky's run engine. Each image is a checkpoint: the file
is written atomically into the dataset, then one event is appended (and fsynced) to the journal.
Whatever happened before, a new session over the same dataset takes exactly the planned images
the journal does not record as done, plus any whose file is missing or corrupt (checksums are
re-verified), so a run stopped by Ctrl-C, a device error, SIGKILL or a power loss resumes where
it stopped, nothing lost and nothing duplicated.

Pause (:meth:`CaptureSession.request_pause`, what Ctrl-C asks for) takes effect between
images: the current image is finished, the rig parks, the run stops with status ``paused``.
Device errors are retried within bounds (a move after ``stop``, a capture after a camera
timeout); then the rig parks and the run stops ``failed`` with the reason. On every exit path
the light is switched off and motion stopped before the stop document is written.
"""

from __future__ import annotations

import contextlib
import enum
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from capture.dataset import Dataset
from capture.frame_files import frame_file
from capture.journal import (
    ExitStatus,
    ImageKey,
    capture_identity,
    completed_images,
    config_digest,
    read_journal,
    runs,
)
from capture.plan import CaptureEvent, SweepPlan
from core.errors import DatasetError, DeviceError, DeviceFault, RigError, SafetyError
from core.progress import progress_bar
from rig.config import RigConfig
from rig.devices import Frame
from rig.pose import RigPose
from rig.safety import describe_pose, pose_violation

__all__ = [
    "TRANSITIONS",
    "CaptureRig",
    "CaptureSession",
    "FaultHandler",
    "SessionResult",
    "SessionState",
    "TargetPlacer",
    "require_same_rig",
]

#: Puts a calibration target (a :class:`capture.plan.CalibrationCapture` name such as
#: "charuco", "mirror-sphere", "white-target") at the object's place, or the object back (None);
#: returns when it is there (a console prompt on a real rig, a scene switch on the simulated one).
TargetPlacer = Callable[[str | None], None]
#: Told a device fault in words; True once the operator has fixed its cause.
FaultHandler = Callable[[str], bool]


class SessionState(enum.StrEnum):
    """Where a session is."""

    IDLE = "idle"
    RUNNING = "running"
    PAUSING = "pausing"  # a pause was asked for; the current image is being finished
    PARKING = "parking"
    STOPPED = "stopped"


#: Allowed transitions; anything else is a bug and raises.
TRANSITIONS: Mapping[SessionState, frozenset[SessionState]] = {
    SessionState.IDLE: frozenset({SessionState.RUNNING}),
    SessionState.RUNNING: frozenset({SessionState.PAUSING, SessionState.PARKING}),
    SessionState.PAUSING: frozenset({SessionState.PARKING}),
    SessionState.PARKING: frozenset({SessionState.STOPPED}),
    SessionState.STOPPED: frozenset(),
}


class CaptureRig(Protocol):
    """What the executor needs of a rig (:class:`rig.hardware.Rig` is one)."""

    config: RigConfig

    def move_to(self, pose: RigPose, *, wait: bool = True) -> RigPose | None:
        """Move every axis to ``pose``; the measured pose when ``wait``, else None.

        Raises :class:`~core.errors.SafetyError` before moving when the pose or the path to it
        is unsafe.
        """
        ...

    def light_on(self, intensity: float = 1.0) -> None:
        """Switch the light on at ``intensity`` in (0, 1]."""
        ...

    def light_off(self) -> None:
        """Switch the light off."""
        ...

    def capture(self, exposure_ms: float) -> Frame:
        """Take one frame exposed for ``exposure_ms`` milliseconds."""
        ...

    def park(self) -> RigPose | None:
        """Light off, then move to the config's park pose; the pose reached."""
        ...

    def pose(self) -> RigPose:
        """The measured pose of every axis."""
        ...

    def clear_faults(self) -> str:
        """Clear the devices' own faults (unlock or home, reboot); what was done, in words."""
        ...

    def stop(self) -> None:
        """Stop every axis now."""
        ...


@dataclass(frozen=True)
class SessionResult:
    """How a run ended.

    Attributes
    ----------
    exit_status : "success", "paused", "aborted" or "failed"
    reason : str, why (empty on success)
    taken : int, images taken by this run
    already_done : int, planned images an earlier run had taken (verified)
    retaken : int, images of earlier runs taken again (missing or corrupt files)
    seconds : dict, wall time by phase: move, light, capture, store, total
    """

    exit_status: ExitStatus
    reason: str
    taken: int
    already_done: int
    retaken: int
    seconds: dict[str, float] = field(default_factory=dict)


def require_same_rig(dataset: Dataset, config: RigConfig) -> None:
    """Refuse to add images made with another rig config to a dataset.

    Checked by the session before it takes an image, and by ``rig capture --resume`` before
    it opens a port (the other config's devices may not even be there).

    Raises
    ------
    DatasetError
        Naming both configs' digests and the sections that differ.
    """
    have = capture_identity(dataset.rig_config)
    now = capture_identity(config.to_dict())
    if config_digest(have) == config_digest(now):
        return
    differ = sorted(k for k in set(have) | set(now) if have.get(k) != now.get(k))
    raise DatasetError(
        f"{dataset.path} was captured with rig config {config_digest(have)[:19]}, this rig's "
        f"is {config_digest(now)[:19]} ({', '.join(differ)} differ): its images would mix two "
        "set-ups. Resume with the dataset's own config (drop --config), or capture into a new "
        "dataset"
    )


class CaptureSession:
    """Run ``plan`` on ``rig`` into ``dataset``.

    Parameters
    ----------
    rig : CaptureRig, connected
    dataset : Dataset, created with this plan (or opened to resume)
    plan : SweepPlan
    move_retries, capture_retries : attempts after a failed move or capture
    targets : TargetPlacer, optional
        Called before an image whose target (a calibration capture's name, None for the object)
        differs from the one in place; a fresh run starts with the object in place.
    on_fault : FaultHandler, optional
        A device reported a fault of its own (a GRBL alarm, a servo's hardware error): called
        with the reason; True means the operator has fixed the cause, and the session clears
        the fault (unlock or home, reboot) and takes the image again; False (or no handler)
        pauses the run with the reason, for ``rig capture --resume`` once it is fixed. Like a
        suspender: a fault a reset clears need not fail the run.
    """

    def __init__(
        self,
        rig: CaptureRig,
        dataset: Dataset,
        plan: SweepPlan,
        *,
        move_retries: int = 2,
        capture_retries: int = 2,
        targets: TargetPlacer | None = None,
        on_fault: FaultHandler | None = None,
    ) -> None:
        self.rig = rig
        self.dataset = dataset
        self.plan = plan
        self.move_retries = move_retries
        self.capture_retries = capture_retries
        self.targets = targets
        self.on_fault = on_fault
        self._target: str | None = None  # what stands at the object's place
        self._target_known = True
        self.state = SessionState.IDLE
        self._lock = threading.Lock()
        self._pause = threading.Event()
        self._pose: RigPose | None = None  # commanded pose the rig stands at
        self._measured: RigPose | None = None
        self._light = False
        self._seconds = dict.fromkeys(("move", "light", "capture", "store"), 0.0)

    def _to(self, state: SessionState) -> None:
        with self._lock:
            if state not in TRANSITIONS[self.state]:
                raise RuntimeError(f"capture session cannot go from {self.state} to {state}")
            self.state = state

    def request_pause(self) -> None:
        """Finish the current image, park, stop with status ``paused`` (thread- and signal-safe)."""
        self._pause.set()

    # -- the run ----------------------------------------------------------------------------

    def _pending(self) -> tuple[list[CaptureEvent], int, int, str | None]:
        """Events still to take, images done before, images to re-take, the last run's uid."""
        events = list(self.plan.events(self.rig.config))
        done: set[ImageKey] = set()
        previous = None
        if self.dataset.journal_path.exists():
            documents = read_journal(self.dataset.journal_path).documents
            done = completed_images(documents)
            history = runs(documents)
            previous = history[-1].uid if history else None
        # A process killed mid-write leaves a temporary file (never under a final name).
        self.dataset.remove_partials()
        retake = self.dataset.verify().retake & done
        done -= retake
        pending = [e for e in events if e.key not in done]
        return pending, len(events) - len(pending), len(retake), previous

    def run(self) -> SessionResult:
        """Take every pending image; returns how the run ended.

        Raises
        ------
        DatasetError
            Another process captures into the dataset (its lock is held), the rig's config or
            the plan is not the one the dataset was captured with, or the dataset's manifest,
            journal and images are not of one capture; nothing was done.
        InputError
            A pose of the plan lies outside the rig's limits; nothing was moved.
            Every other failure ends the run, with its reason, in the result.
        """
        with self.dataset.lock:
            return self._run()

    def _check_same_rig(self) -> None:
        require_same_rig(self.dataset, self.rig.config)

    def _check_one_capture(self) -> None:
        """Refuse a dataset not of one capture (``capture.origin``), or another plan than its own.

        Another dataset's journal or manifest would have its images taken again over the files;
        another plan would be taken as done (images are keyed by index) at other poses.
        """
        if self.dataset.origin.problems:
            raise DatasetError(self.dataset.origin.problems[0])
        if self.plan.to_dict() != self.dataset.plan:
            raise DatasetError(
                f"{self.dataset.path} was made with another plan than the one given: resume it "
                "with its own (rig capture --resume DATASET), or capture this one into a new "
                "dataset"
            )

    def _check_journal_vouches(self) -> None:
        """Refuse a dataset whose images the journal does not vouch for.

        A resume would take them again over their files, as if they had never been taken.
        """
        if not self.dataset.journaled:
            return
        report = self.dataset.verify()
        if report.unvouched:
            raise DatasetError(
                f"{self.dataset.path}: the journal does not vouch for {len(report.unvouched)} "
                f"of its {report.checked} images (first {report.unvouched[0].file}): "
                "journal.jsonl was deleted, emptied or cut short, and resuming would take "
                "them again over the files. Restore journal.jsonl from a backup, or capture "
                "into a new dataset"
            )

    def _run(self) -> SessionResult:
        self._check_same_rig()
        self._check_one_capture()
        self.plan.require_within_limits(self.rig.config)
        self._check_journal_vouches()
        if not self.dataset.journaled:
            # From now on the journal must vouch for every image (a deleted journal shows).
            self.dataset.journaled = True
            self.dataset.save()
        self._to(SessionState.RUNNING)
        start = time.perf_counter()
        pending, already, retaken, previous = self._pending()
        # A resumed run may have stopped with a calibration target in place.
        self._target_known = already == 0 or not self.plan.calibration
        config = self.rig.config
        journal = self.dataset.open_journal()
        journal.start(
            plan=self.plan.to_dict(),
            rig_config_digest=config_digest(config.to_dict()),
            resumed_from=previous,
        )
        status: ExitStatus = "success"
        reason = ""
        taken = 0
        bar = progress_bar(
            total=already + len(pending),
            initial=already,
            desc="capture",
            unit="image",
        )
        try:
            if pending:
                self._leave_unsafe_start()
            index = 0
            while index < len(pending):
                if self._pause.is_set():
                    self._to(SessionState.PAUSING)
                    status, reason = "paused", "pause requested (Ctrl-C); resume to continue"
                    break
                try:
                    self._take(pending[index], journal)
                except DeviceFault as fault:
                    if self._suspend(fault):
                        continue  # cleared: the same image again
                    self._to(SessionState.PAUSING)
                    status = "paused"
                    reason = (
                        f"{fault}; a reset or reboot clears this fault: fix its cause, then "
                        "resume the capture (rig capture --resume DATASET)"
                    )
                    break
                index += 1
                taken += 1
                bar.update(1)
        except KeyboardInterrupt:
            status, reason = "aborted", "interrupted during an image (a second Ctrl-C)"
        except RigError as error:
            status, reason = "failed", str(error)
        finally:
            bar.close()
            reason = self._park(reason)
            self._seconds["total"] = time.perf_counter() - start
            journal.stop(
                status,
                reason=reason,
                counts={"taken": taken, "already_done": already, "retaken": retaken},
            )
            journal.close()
            self.dataset.save()
            self._to(SessionState.STOPPED)
        return SessionResult(status, reason, taken, already, retaken, dict(self._seconds))

    def _park(self, reason: str) -> str:
        """Light off, motion stopped, park; failures are added to the reason, never raised."""
        self._to(SessionState.PARKING)
        problems = []
        for step in (self.rig.light_off, self.rig.stop, self.rig.park):
            try:
                step()
            except RigError as error:
                problems.append(f"{step.__name__}: {error}")
        self._light = False
        if problems:
            reason = "; ".join(filter(None, [reason, "parking failed: " + "; ".join(problems)]))
        return reason

    # -- one image --------------------------------------------------------------------------

    def _take(self, event: CaptureEvent, journal: Any) -> None:
        self._place(event)
        self._move(event.pose)
        started = time.perf_counter()
        if event.light_on and not self._light:
            self.rig.light_on(1.0)
            self._light = True
        elif not event.light_on and self._light:
            self.rig.light_off()
            self._light = False
        self._seconds["light"] += time.perf_counter() - started
        time_start = time.time()
        frame = self._capture(event.exposure_ms)
        time_end = time.time()
        started = time.perf_counter()
        suffix, data = frame_file(frame)
        assert self._measured is not None
        record = self.dataset.write_image(
            event.name + suffix,
            data,
            key=event.key,
            exposure_ms=event.exposure_ms,
            commanded_pose=event.pose.to_dict(),
            measured_pose=self._measured.to_dict(),
        )
        journal.event(record, time_start=time_start, time_end=time_end)
        self._seconds["store"] += time.perf_counter() - started

    def _suspend(self, fault: DeviceFault) -> bool:
        """Ask the operator (if anyone is asked) and clear the fault; True to go on."""
        if self.on_fault is None or not self.on_fault(str(fault)):
            return False
        self._pose = None  # where the fault left the rig is not where it was sent
        self.rig.clear_faults()
        return True

    def _leave_unsafe_start(self) -> None:
        """Park first when the rig stands where it may not be.

        A controller that powered up at machine zero, say: the park route leads out of it, or
        nothing moves and the reason says what to do.
        """
        here = self.rig.pose()
        problem = pose_violation(self.rig.config, here)
        if problem is None:
            return
        try:
            self.rig.park()
        except SafetyError as error:
            raise SafetyError(
                f"the rig starts at {describe_pose(here)}, which is unsafe ({problem}), and no "
                f"route to the park pose leads out of it ({error}); move the camera and the light "
                "apart by hand (or home the gantry), then resume the capture"
            ) from error

    def _place(self, event: CaptureEvent) -> None:
        """Have the event's target (a calibration capture's, or the object) put in place."""
        needed = None
        if event.key.kind == "calibration" and event.key.light_index is not None:
            needed = self.plan.calibration[event.key.light_index].name
        if self.targets is not None and (needed != self._target or not self._target_known):
            self.targets(needed)
        self._target, self._target_known = needed, True

    def _move(self, pose: RigPose) -> None:
        if pose == self._pose:
            return
        started = time.perf_counter()
        first: DeviceError | None = None
        for attempt in range(self.move_retries + 1):
            try:
                measured = self.rig.move_to(pose)
                break
            except (SafetyError, DeviceFault) as error:
                # Unsafe, or a fault a person must look at (a GRBL alarm locks the gantry until
                # it is homed or unlocked; an overload drops a servo's torque until a reboot).
                raise error from first
            except DeviceError as error:
                # The device refused or lost the move: stop everything, then try again.
                first = first or error
                self._pose = None
                with contextlib.suppress(RigError):
                    self.rig.stop()
                if attempt == self.move_retries:
                    if error is not first:
                        error.add_note(f"first attempt: {first}")
                    raise
        assert measured is not None
        self._pose, self._measured = pose, measured
        self._seconds["move"] += time.perf_counter() - started

    def _capture(self, exposure_ms: float) -> Frame:
        started = time.perf_counter()
        try:
            for attempt in range(self.capture_retries + 1):
                try:
                    return self.rig.capture(exposure_ms)
                except DeviceError:
                    if attempt == self.capture_retries:
                        raise
            raise AssertionError("unreachable")
        finally:
            self._seconds["capture"] += time.perf_counter() - started

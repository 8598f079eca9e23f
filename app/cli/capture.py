"""The capture commands of ``rig``: ``rig capture``, ``rig verify``, ``rig export-lp``."""

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path
from typing import Any

from app.cli.args import between, count, image_size, output_directory
from core.errors import InputError

__all__ = ["add_capture", "console_fault_handler", "console_placer"]

#: What a person is asked to put at the object's place, by calibration capture name.
TARGET_WORDS = {
    "charuco": "the ChArUco board (flat, printed side up)",
    "mirror-sphere": "the mirror sphere",
    "white-target": "the white target (flat, face up)",
}

#: Exit status of a paused or aborted capture (the shell's convention for Ctrl-C).
INTERRUPTED = 130

#: The options of ``rig capture --sim`` (what builds the simulated rig and its grid plan), by
#: flag: the attribute and its default.
SIM_DEFAULTS: dict[str, tuple[str, object]] = {
    "--cameras": ("cameras", 6),
    "--lights": ("lights", 8),
    "--scene": ("scene", "glossy-sphere"),
    "--layout": ("layout", "fibonacci"),
    "--size": ("size", (128, 128)),
    "--points": ("points", 20_000),
    "--exposure-ms": ("exposure_ms", 10.0),
    "--speed": ("speed", 1.0),
    "--calibrate": ("calibrate", False),
}


def add_capture(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig capture``, ``rig verify`` and ``rig export-lp`` on the ``rig`` parser."""
    p = commands.add_parser(
        "capture",
        help="run a sweep plan on a rig (real or simulated) into a dataset",
        description="Run a capture: --config and --plan on a rig; --sim with a grid plan on the "
        "simulated rig started in this process; --resume DATASET continues a stopped capture "
        "(files already taken are verified by checksum, missing or corrupt ones re-taken). "
        "Ctrl-C (or SIGTERM) finishes the current image, parks and stops with status paused.",
    )
    p.add_argument("-o", "--output", type=output_directory, help="new dataset directory")
    p.add_argument("--resume", type=Path, metavar="DATASET", help="continue this dataset")
    p.add_argument("--config", type=Path, help="rig config (TOML)")
    p.add_argument("--plan", type=Path, help="sweep plan (TOML)")
    p.add_argument("--sim", action="store_true", help="the simulated rig, in this process")
    # The --sim options default to None, so a flag given where it does nothing is told apart
    # from one left out (SIM_DEFAULTS fills them in).
    p.add_argument("--cameras", type=count, help="--sim: camera poses (default 6)")
    p.add_argument("--lights", type=count, help="--sim: light poses (default 8)")
    p.add_argument("--scene", help="--sim: scene (default glossy-sphere)")
    p.add_argument("--layout", choices=("fibonacci", "grid"),
                   help="--sim: camera and light layout (default fibonacci)")  # fmt: skip
    p.add_argument("--size", type=image_size, help="--sim: image WIDTHxHEIGHT (default 128x128)")
    p.add_argument("--points", type=count, help="--sim: scene points (default 20k)")
    p.add_argument(
        "--exposure-ms",
        type=between(0.001, 3_600_000.0, " ms (an hour)"),
        help="--sim: exposure (default 10: the glossy sphere's highlights do not clip)",
    )
    p.add_argument(
        "--speed",
        type=between(0.01, 1000.0),
        help="--sim: axis speed factor (default 1: real time)",
    )
    p.add_argument(
        "--calibrate",
        action="store_true",
        default=None,
        help="--sim: take calibration captures first (ChArUco per camera, mirror sphere and "
        "white target per light; docs/calibration.md)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(handler=_run_capture)

    v = commands.add_parser(
        "verify",
        help="check a dataset's or a field store's completeness and integrity",
        description="A dataset: check every image's size and SHA-256 against the manifest and "
        "journal, list missing, corrupt and unexpected files. A field store (rig process, rig "
        "sim field): read every chunk, check none is missing or damaged, every value is "
        "finite and the radiance matches the digest recorded when it was written. Exits 1 "
        "when anything is wrong.",
    )
    v.add_argument("dataset", type=Path, help="a dataset folder or a field store (.zarr)")
    v.add_argument("--quiet", action="store_true", help="no progress bar")
    v.set_defaults(handler=_run_verify)

    e = commands.add_parser(
        "export-lp",
        help="write an RTI .lp file per camera pose of a dataset",
        description="Write camera_NNN.lp (light directions in each camera's frame) for RTI tools.",
    )
    e.add_argument("dataset", type=Path)
    e.add_argument("-o", "--output", type=output_directory, required=True, help="output directory")
    e.set_defaults(handler=_run_export_lp)


def console_fault_handler(reason: str) -> bool:
    """Tell the person at the rig what faulted; True once they say it is fixed."""
    print(f"\ndevice fault: {reason}")
    answer = input("fix its cause, then press Enter to clear it and go on (or q to pause) ")
    return answer.strip().lower() not in ("q", "quit")


def console_placer(name: str | None) -> None:
    """Ask the person at the rig to put ``name`` (None: the object) in place; waits for Enter."""
    what = "the object" if name is None else TARGET_WORDS.get(name, f"the {name} target")
    input(f"place {what} at the object's place and press Enter ")


def _run_capture(args: argparse.Namespace) -> int:
    from capture.calibration_plan import with_calibration_captures
    from capture.dataset import Dataset
    from capture.grid_plan import grid_plan
    from capture.plan import SweepPlan
    from capture.plan_file import load_plan
    from capture.session import require_same_rig
    from rig.config import load_config, parse_config
    from sim.simulated_rig import simulated_capture_config

    _refuse_conflicting_flags(args)
    for name, default in SIM_DEFAULTS.values():
        if getattr(args, name) is None:
            setattr(args, name, default)
    if args.resume is not None:
        dataset = Dataset.open(args.resume)
        config = load_config(args.config) if args.config else parse_config(dataset.rig_config)
        require_same_rig(dataset, config)  # before any port is opened
        plan = SweepPlan.from_dict(dataset.plan)
    else:
        if args.output is None:
            raise InputError("say where the new dataset goes: -o DATASET (or --resume DATASET)")
        if args.sim:
            config = simulated_capture_config(
                args.scene, size=args.size, points=args.points, speed=args.speed
            )
            plan = grid_plan(
                args.cameras, args.lights, exposures_ms=(args.exposure_ms,), layout=args.layout
            )
            if args.calibrate:
                plan = with_calibration_captures(plan, config)
        else:
            if args.config is None or args.plan is None:
                raise InputError("a capture needs --config and --plan (or --sim)")
            config, plan = load_config(args.config), load_plan(args.plan)
        plan.require_within_limits(config)  # before a dataset folder exists
        dataset = Dataset.create(
            args.output,
            rig_config=config.to_dict(),
            plan=plan.to_dict(),
            planned=plan.planned_keys(config),
        )
    _say_what_is_left_out(plan, config)
    with dataset.lock:  # before the rig's ports are opened: one capture per dataset
        result = _capture(config, dataset, plan)
    print(
        f"{result.exit_status}: {result.taken} images taken, {result.already_done} already "
        f"there, {result.retaken} re-taken -> {dataset.path}"
    )
    if result.reason:
        print(f"reason: {result.reason}")
    return {"success": 0, "paused": INTERRUPTED, "aborted": INTERRUPTED}.get(result.exit_status, 1)


def _refuse_conflicting_flags(args: argparse.Namespace) -> None:
    """Refuse flags of which one would be ignored, naming both (nothing is opened yet).

    ``--resume`` runs the dataset's own plan on its own rig; ``--sim`` builds both from its
    options; ``--config`` and ``--plan`` name them. Which side a person meant cannot be guessed.

    Raises
    ------
    InputError
        Naming the flags that conflict and what each does.
    """
    given = [flag for flag, (name, _) in SIM_DEFAULTS.items() if getattr(args, name) is not None]
    if args.resume is not None:
        ignored = [f for f, on in (("-o", args.output), ("--plan", args.plan)) if on is not None]
        ignored += ["--sim"] * bool(args.sim) + given
        if ignored:
            raise InputError(
                f"--resume {args.resume} continues that dataset with its own plan and rig; "
                f"{' '.join(ignored)} would be ignored: drop {'them' if len(ignored) > 1 else 'it'}"
                " (to capture another plan, start a new dataset with -o)"
            )
    elif args.sim:
        named = [f for f, on in (("--config", args.config), ("--plan", args.plan)) if on]
        if named:
            raise InputError(
                f"--sim makes its own rig and grid plan (--cameras, --lights, ...), so "
                f"{' and '.join(named)} would be ignored: give --sim, or --config and --plan "
                "for a rig and a plan of your own, not both"
            )
    elif given:
        raise InputError(
            f"{' '.join(given)}: for --sim only; with --config and --plan the plan file says "
            "what to take (list [[calibration]] in it for calibration captures)"
        )


def _say_what_is_left_out(plan: Any, config: Any, listed: int = 3) -> None:
    """Print the captures the plan leaves out on this rig (unsafe pairs, unreachable stops)."""
    left_out = plan.unplaced(config)
    if not left_out:
        return
    pairs = sum(u.kind == "light" for u in left_out)
    print(
        f"left out: {pairs} (camera, light) pairs and {len(left_out) - pairs} other captures "
        "the rig's limits or forbidden zones do not allow (rig plan lists every one):"
    )
    for u in left_out[:listed]:
        light = "" if u.light_index is None else f", light {u.light_index}"
        kind = "" if u.kind == "light" else f"{u.kind}: "
        print(f"  {kind}camera {u.camera_index}{light}: {u.reason}")
    if len(left_out) > listed:
        print(f"  ... and {len(left_out) - listed} more")


def _capture(config: Any, dataset: Any, plan: Any) -> Any:
    """Run the plan on the devices the config names.

    A config whose ports are :data:`rig.config.IN_PROCESS_PORT` (``rig capture --sim``) gets
    the simulated rig started here; any other config drives the ports it names, with the
    simulated camera when that is its camera (a rig of ``rig sim start``, or real controllers).
    """
    import contextlib

    from capture.session import CaptureSession
    from rig.cameras import open_camera
    from rig.config import IN_PROCESS_PORT
    from rig.hardware import Rig
    from sim.simulated_rig import SimulatedRig, simulated_camera

    with contextlib.ExitStack() as stack:
        placer: Any = console_placer
        ports = {p.port for p in (config.servos, config.gantry) if p is not None}
        if ports == {IN_PROCESS_PORT}:
            simulated = stack.enter_context(SimulatedRig(config))
            rig = simulated.rig()
        elif IN_PROCESS_PORT in ports:
            raise InputError(
                f"the rig config names {IN_PROCESS_PORT} for some devices and real ports for "
                "others; name every device's port, or none (--sim)"
            )
        else:
            rig = Rig(config)
            if config.camera.backend == "simulated":
                rig.camera = simulated_camera(rig)
            else:
                rig.camera = open_camera(config)
        if config.camera.backend == "simulated":
            placer = rig.camera.place_target  # type: ignore[union-attr]
        stack.enter_context(rig)
        # A person at the terminal can fix a fault and go on; unattended, the run pauses.
        handler = console_fault_handler if sys.stdin.isatty() else None
        session = CaptureSession(rig, dataset, plan, targets=placer, on_fault=handler)
        stops = (signal.SIGINT, signal.SIGTERM)
        previous = {number: signal.getsignal(number) for number in stops}

        def on_stop(number: int, frame: Any) -> None:
            # First Ctrl-C or SIGTERM: finish the image and park (the dataset resumes where it
            # stopped); a second one interrupts at once, through rig's own handlers.
            session.request_pause()
            signal.signal(signal.SIGINT, signal.default_int_handler)
            signal.signal(signal.SIGTERM, previous[signal.SIGTERM])

        for number in stops:
            signal.signal(number, on_stop)
        try:
            return session.run()
        finally:
            for number, before in previous.items():
                signal.signal(number, before)


def _run_verify(args: argparse.Namespace) -> int:
    from capture.dataset import Dataset
    from core.field_store import is_field_store
    from core.store.integrity import check_store

    if is_field_store(args.dataset):
        check = check_store(args.dataset)
        print(check.summary())
        return 0 if check.ok else 1
    # Not strict: a journal or manifest of another dataset is damage to report, not a refusal.
    report = Dataset.open(args.dataset, strict=False).verify()
    print(report.summary())  # the verdict and each problem, once
    return 0 if report.ok and report.complete else 1


def _run_export_lp(args: argparse.Namespace) -> int:
    from capture.dataset import Dataset
    from capture.lp_export import export_lp

    written = export_lp(Dataset.open(args.dataset), args.output)
    for path in written:
        print(path)
    return 0

"""The hardware commands of ``rig``: ``rig sim start`` and ``rig doctor``."""

from __future__ import annotations

import argparse
import signal
import threading
from pathlib import Path
from typing import Any

from app.cli.args import output_file, positive

__all__ = ["add_doctor", "add_sim_start"]


def add_sim_start(sim_commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig sim start`` on the ``rig sim`` sub-command parser."""
    p = sim_commands.add_parser(
        "start",
        help="run the simulated rig: servo and GRBL emulators on pseudo-terminals",
        description="Start the Dynamixel servo chain and the GRBL gantry emulators on "
        "pseudo-terminals, print their serial devices, and (with --write-config) write a rig "
        "config that points at them once both answer. Runs until Ctrl-C or SIGTERM, then "
        "removes the ptys.",
    )
    p.add_argument("--config", type=Path, help="rig config to emulate (default: a simulated rig)")
    p.add_argument("--write-config", type=output_file, help="write the ready-to-use config here")
    p.set_defaults(handler=_run_sim_start)


def add_doctor(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig doctor`` on the ``rig`` sub-command parser."""
    p = commands.add_parser(
        "doctor",
        help="check every device of a rig config",
        description="Connect to every device of a rig config (real or simulated), move each "
        "axis a little and back, blink the light, take a frame, and print a table. Exits "
        "non-zero when a device is missing or faulty.",
    )
    p.add_argument("--config", type=Path, required=True, help="rig config (TOML)")
    p.add_argument("--exposure-ms", type=positive, default=10.0, help="test frame exposure")
    p.set_defaults(handler=_run_doctor)


#: First line of a config written by ``rig sim start``: such a file may be replaced by the
#: next start (its ports change every time); any other file at the path is refused.
SIM_CONFIG_MARK = "# written by rig sim start; replaced by the next start"


def _check_write_config(path: Path) -> None:
    from core.errors import InputError

    if not path.is_file():
        return
    with open(path, encoding="utf-8", errors="replace") as existing:
        first = existing.readline().rstrip("\n")
    if first != SIM_CONFIG_MARK:
        raise InputError(
            f"{path}: exists and was not written by rig sim start; choose another path for "
            "the simulated rig's config, or remove that file"
        )


def _run_sim_start(args: argparse.Namespace) -> int:
    from core.atomic import atomic_path
    from rig.config import load_config
    from rig.hardware import Rig
    from sim.simulated_rig import SimulatedRig

    if args.write_config:
        _check_write_config(args.write_config)
    stop = threading.Event()
    previous = {s: signal.signal(s, lambda *_: stop.set()) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with SimulatedRig(load_config(args.config) if args.config else None) as simulated:
            for name, port in simulated.ports.items():
                print(f"{name}: {port}", flush=True)
            with Rig(simulated.config):  # both emulators answer the real drivers
                pass
            if args.write_config:
                with atomic_path(args.write_config) as temporary:
                    text = f"{SIM_CONFIG_MARK}\n{simulated.config.to_toml()}"
                    temporary.write_text(text, encoding="utf-8")
                print(f"config: {args.write_config}", flush=True)
            print("simulated rig running; Ctrl-C to stop", flush=True)
            stop.wait()
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
    print("simulated rig stopped")
    return 0


def _run_doctor(args: argparse.Namespace) -> int:
    from core.errors import RigError
    from rig.cameras import open_camera
    from rig.config import load_config
    from rig.doctor import DoctorCheck, format_checks, run_doctor
    from rig.hardware import Rig

    config = load_config(args.config)
    rig = Rig(config)
    camera: Any = None
    problems: list[DoctorCheck] = []
    if config.camera.backend == "simulated":
        from sim.simulated_rig import simulated_camera

        camera = simulated_camera(rig)
    elif config.camera.backend != "replay":  # a replay camera serves a dataset: nothing to check
        try:
            camera = open_camera(config)
        except RigError as error:
            problems.append(
                DoctorCheck(f"camera ({config.camera.backend})", "open", False, str(error))
            )
    rig.camera = camera
    checks = problems + run_doctor(rig, exposure_ms=args.exposure_ms)
    print(format_checks(checks))
    failed = [c for c in checks if not c.ok]
    if failed:
        print(f"{len(failed)} check(s) failed")
        return 1
    print("every device answered")
    return 0

"""``rig view``: relight a field live in the browser.

Application layer (like the rest of :mod:`app.cli`): it opens the field, chooses its best mode,
builds the session (:class:`render.live_session.LiveSession`, with the simulator's ground truth
for a simulated field) and serves it (:mod:`app.live_server`) until interrupted.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from app.cli.args import image_size, whole
from app.cli.evaluate import add_below_horizon_option, add_transfer_option

__all__ = ["add_view", "open_session", "read_panoramas"]


def add_view(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig view`` on the ``rig`` sub-command parser."""
    p = commands.add_parser(
        "view",
        help="relight a field live in the browser",
        description="Serve a page where a field is relit live: choose or drop a panorama, drag "
        "it to rotate it, orbit and zoom the view, set exposure, K and the sampler, paint or "
        "load a modulation map, switch between the paper's configuration and the best mode, "
        "see the sampled lights, the frame time, the guards' warnings and (simulated fields) the "
        "ground truth and error; save the frame (PNG, EXR) and the settings. Prints the URL to "
        "open; Ctrl-C stops it.",
    )
    p.add_argument(
        "field", type=Path, help="reflectance field store, or an RTI .lp file (or its folder)"
    )
    p.add_argument("--env", type=Path, action="append", help="a panorama to offer (repeat for "
                   "more; default: the bundled courtyard and studio)")  # fmt: skip
    p.add_argument("--models", type=Path, help="saved fit of the field (default: beside it)")
    p.add_argument("--size", type=image_size, default=(512, 512),
                   help="view size of a field of points (default 512x512)")  # fmt: skip
    p.add_argument("--host", default="127.0.0.1", help="address to serve on (default "
                   "127.0.0.1: this machine only; the viewer has no login)")  # fmt: skip
    p.add_argument("--port", type=_port, default=0, help="port (default: a free one)")
    add_transfer_option(p)
    add_below_horizon_option(p)
    p.set_defaults(handler=_run_view)


def _port(text: str) -> int:
    value = whole(text)
    if value > 65535:
        raise argparse.ArgumentTypeError(f"a port is 0..65535, got {text!r}")
    return value


def read_panoramas(paths: list[Path] | None) -> dict[str, Any]:
    """The panoramas to offer by name (default: the bundled ones), their notes printed."""
    from core.sample_data import PANORAMA_NAMES, panorama_path
    from processing.panorama import read_panorama

    loaded = {}
    for path in paths or [panorama_path(name) for name in PANORAMA_NAMES]:
        panorama = read_panorama(path)
        if panorama.note:
            print(panorama.note)
        loaded[path.name] = panorama
    return loaded


def open_session(
    field: Any,
    panoramas: list[Path] | dict[str, Any] | None,
    *,
    size: tuple[int, int],
    models: Path | None,
    source: Path | None = None,
    report: Any = None,
) -> Any:
    """The live session of ``field`` under the given panoramas (default: the bundled ones).

    ``report(status)``, when given, is told each stage as it starts (the viewer's page shows it).
    """
    from render.engines.modes import most_accurate_mode
    from render.live_session import LiveSession
    from sim.ground_truth import field_truth

    def stage(status: str) -> None:
        if report is not None:
            report(status)

    loaded = panoramas if isinstance(panoramas, dict) else read_panoramas(panoramas)
    stage("choosing the most accurate mode (fitting the models once; a saved fit is reused)")
    choice = most_accurate_mode(field, models_path=models)
    session = LiveSession(
        field, choice, loaded, size=size, truth=field_truth(field.provenance), source=source
    )
    first = next(iter(session.panoramas))
    if session.field.sample_kind == "pixels":
        stage(f"choosing the rung that relights under {first} best (held-out lights)")
        session.environment_choice(first)
    print(f"best mode: {session.best_reason(first)}")
    return session


def _run_view(args: argparse.Namespace) -> int:
    from functools import partial

    from app.live_server import PendingSession
    from app.viewer_server import start_viewer
    from processing.rti import open_field_or_rti

    with open_field_or_rti(
        args.field, transfer=args.transfer, below_horizon=args.below_horizon, print_assumed=True
    ) as field:
        # The page is served at once and says what is being prepared (the best mode's fit
        # takes seconds to minutes); a panorama that cannot be read fails the command first.
        panoramas = read_panoramas(args.env)
        opening = partial(
            open_session, field, panoramas, size=args.size, models=args.models, source=args.field
        )
        pending = PendingSession(field, lambda report: opening(report=report), args.field)
        server = start_viewer(pending, host=args.host, port=args.port)
        try:
            # Inside the try: a signal just after the URL still stops the server cleanly.
            print(f"rig view: open {server.url} in a browser (Ctrl-C stops)", flush=True)
            server.wait()
        except KeyboardInterrupt:
            print("stopped", file=sys.stderr)
        finally:
            server.stop()
    return 0

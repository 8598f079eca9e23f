"""Frame times of the browser viewer's session, per mode: what a person waits for.

``python -m bench.live_view -o DIR [--points 50000] [--grid 16] [--size 512]`` simulates a glossy
sphere (``--grid`` lights x cameras), opens :class:`render.live_session.LiveSession` on it and
times, for the paper's configuration and the field's best mode, a new lighting (a yaw change:
lighting, relight and display), a new view (an orbit) with its splat plan and camera blend
timed apart, the JPEG encoding of a frame and the guards' warnings; medians of five changes
each. Writes ``live_view.json`` and prints it.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from core.field_store import ReflectanceField
from core.image_io import encode_picture
from core.point_spacing import point_spacing
from core.sample_data import panorama_path
from processing.panorama import read_panorama
from render.engines.interpolated import RelightSettings
from render.engines.modes import most_accurate_mode
from render.engines.paper_sums import blend_cameras
from render.field_view import FieldView
from render.live_session import LIVE_MODES, LiveFrame, LiveSession
from sim.field import field_cameras, simulate_field

__all__ = ["main", "time_session"]

#: Changes timed per figure (the median is reported).
REPEATS = 5
#: JPEG quality of the viewer's frames (app.live_server.FRAME_JPEG_QUALITY).
JPEG_QUALITY = 90


def time_session(session: LiveSession) -> dict[str, dict[str, Any]]:
    """Median milliseconds of a new lighting and a new view, per live mode, and their parts."""
    figures: dict[str, dict[str, Any]] = {}
    for mode in LIVE_MODES:
        controls = session.initial.updated({"mode": mode})
        frame = session.render(controls)
        lighting, view = [], []
        for i in range(REPEATS):
            controls = controls.updated({"yaw_deg": 10.0 * (i + 1)})
            start = time.perf_counter()
            frame = session.render(controls)
            lighting.append(time.perf_counter() - start)
        for _ in range(REPEATS):
            controls = controls.updated({"azimuth_deg": controls.azimuth_deg + 5.0})
            start = time.perf_counter()
            frame = session.render(controls)
            view.append(time.perf_counter() - start)
        start = time.perf_counter()
        _, jpeg = encode_picture(frame.picture, ".jpg", quality=JPEG_QUALITY)
        encode = time.perf_counter() - start
        start = time.perf_counter()
        session.warnings()
        warnings = time.perf_counter() - start
        plan, blend = view_parts(session, frame)
        figures[mode] = {
            "mode": frame.mode,
            "new_lighting_ms": 1000.0 * float(np.median(lighting)),
            "new_view_ms": 1000.0 * float(np.median(view)),
            "parts_of_last_view_ms": {k: 1000.0 * v for k, v in frame.seconds.items()},
            "splat_plan_ms": plan,
            "camera_blend_ms": blend,
            "jpeg_ms": 1000.0 * encode,
            "jpeg_kib": len(jpeg) / 1024.0,
            "warnings_ms": 1000.0 * warnings,
            "points_shown": int(frame.image.needed.sum()),
        }
    return figures


def view_parts(session: LiveSession, frame: LiveFrame) -> tuple[float, float | None]:
    """Median milliseconds of the splat plan and the camera blend of the frame's view.

    The two parts of a new view that do not depend on the lighting; the blend only for modes
    that interpolate the cameras (the models hold the view in their lobes).
    """
    field, camera = session.field, frame.camera
    assert field.points is not None and field.normals is not None
    spacing = point_spacing(field.points)
    plans, blends = [], []
    for _ in range(REPEATS):
        start = time.perf_counter()
        view = FieldView(field, camera, spacing=spacing)
        plans.append(time.perf_counter() - start)
        if isinstance(frame.relight_mode, RelightSettings):
            start = time.perf_counter()
            mode = frame.relight_mode
            blend_cameras(field, camera, mode.view_interpolation, n=mode.n, needed=view.needed)
            blends.append(time.perf_counter() - start)
    return 1000.0 * float(np.median(plans)), (1000.0 * float(np.median(blends)) if blends else None)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", type=Path, required=True, help="output directory")
    parser.add_argument("--points", type=int, default=50_000, help="points (default 50000)")
    parser.add_argument("--grid", type=int, default=16, help="lights = cameras (default 16)")
    parser.add_argument("--size", type=int, default=512, help="view side in pixels (512)")
    args = parser.parse_args(argv)
    args.output.mkdir(parents=True, exist_ok=True)
    store = args.output / "live_view.zarr"
    cameras = field_cameras(args.grid, width=128, height=128)
    simulate_field(
        store,
        "glossy-sphere",
        lights=args.grid,
        cameras=cameras,
        points=args.points,
        overwrite=True,
    )
    field = ReflectanceField.open(store)
    panorama = read_panorama(panorama_path("courtyard"))
    session = LiveSession(
        field, most_accurate_mode(field), {"courtyard": panorama},
        size=(args.size, args.size),
    )  # fmt: skip
    result = {
        "points": args.points,
        "lights": args.grid,
        "cameras": args.grid,
        "size": args.size,
        "modes": time_session(session),
    }
    (args.output / "live_view.json").write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    from core.progress import drawing_bars

    with drawing_bars():  # the library's bars on stderr, as ``rig`` draws them
        status = main()
    raise SystemExit(status)

"""What a turning panorama costs an RTI capture's relighting, per mode: time per new yaw.

``python -m bench.turning -o DIR [--repeats 11] [--capture FILE.lp]`` relights a capture
(default the bundled lion, :func:`core.sample_data.rti_capture_path`) under each bundled
panorama through each environment mode (:data:`MODES`), turning the panorama by a new yaw
before every frame: the panorama rotated, its light split or gathered anew, the frame
rendered. The figure is the median time of a new yaw after a warm-up frame
(:func:`bench.timing.median_ms`); the first frame (fits, numba compilation) is not timed.
The rungs that predict each light of the panorama run whole (``whole``: every grid block
predicted) and split (``split``: only the sharp light predicted, the light-stage sum
relighting the rest; what ``rig relight --env`` uses). Writes ``DIR/turning.json`` and
``DIR/turning.png``; compare the times as ratios within one run.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from bench.suite import machine
from bench.timing import median_ms
from core.errors import RigError
from core.sample_data import PANORAMA_NAMES, panorama_path, rti_capture_path
from processing.panorama import Panorama, read_panorama
from processing.rti import open_field_or_rti
from render.engines.modes import RelightMode
from render.engines.predicted import PredictorRelightSettings
from render.environment_choice import LIGHT_STAGE, environment_mode
from render.relighting import PanoramaControls, RelightingCache, RelightRequest

__all__ = ["MODES", "main", "measure", "new_yaw_ms"]

#: (label, mode): the light-stage sum, interpolation, the fitted model, and the predicting
#: rungs whole and split.
MODES: tuple[tuple[str, RelightMode], ...] = (
    (LIGHT_STAGE, environment_mode(LIGHT_STAGE)),
    ("barycentric", environment_mode("barycentric")),
    ("lambert+ggx", environment_mode("lambert+ggx")),
    *(
        (f"{name} {'split' if split else 'whole'}", PredictorRelightSettings(name, split=split))
        for name in ("hsh3", "lambert+ggx+residual", "adaptive")
        for split in (False, True)
    ),
)


def new_yaw_ms(
    cache: RelightingCache, panorama: Panorama, mode: RelightMode, repeats: int
) -> float:
    """Median ms of turning ``panorama`` to a new yaw and rendering ``mode``'s frame."""
    yaws = iter(np.linspace(0.0, 360.0, repeats + 2))
    camera = cache.field.cameras[0]

    def frame() -> None:
        lighting = PanoramaControls(yaw_deg=float(next(yaws)))
        request = RelightRequest(panorama=panorama, camera=camera, lighting=lighting, mode=mode)
        cache.prepare(request).engine.render()

    return median_ms(frame, repeats)


def measure(capture: Path, repeats: int) -> list[dict[str, object]]:
    """Median ms per new yaw for every mode and bundled panorama."""
    rows: list[dict[str, object]] = []
    with open_field_or_rti(capture) as field:
        cache = RelightingCache(field)
        for panorama_name in PANORAMA_NAMES:
            panorama = read_panorama(panorama_path(panorama_name))
            for label, mode in MODES:
                ms = new_yaw_ms(cache, panorama, mode, repeats)
                rows.append({"panorama": panorama_name, "mode": label, "new_yaw_ms": ms})
                print(f"{panorama_name:10s} {label:30s} {ms:8.1f} ms", flush=True)
    return rows


def chart(rows: Sequence[dict[str, object]], path: Path) -> None:
    """Horizontal bars: ms per new yaw, one bar per mode and panorama."""
    labels = [label for label, _ in MODES]
    figure, axis = plt.subplots(figsize=(8, 0.45 * len(labels) + 1.5))
    height = 0.8 / len(PANORAMA_NAMES)
    for k, panorama_name in enumerate(PANORAMA_NAMES):
        times = {
            r["mode"]: float(str(r["new_yaw_ms"])) for r in rows if r["panorama"] == panorama_name
        }
        axis.barh(
            np.arange(len(labels)) + k * height,
            [times[label] for label in labels],
            height=height,
            label=panorama_name,
        )
    axis.set_yticks(np.arange(len(labels)) + 0.4 - height / 2, labels)
    axis.invert_yaxis()
    axis.set_xlabel("ms per new yaw (median)")
    axis.legend()
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark; see the module docstring."""
    parser = argparse.ArgumentParser(prog="python -m bench.turning", description=__doc__)
    parser.add_argument("-o", "--out", type=Path, required=True, help="output folder")
    parser.add_argument("--repeats", type=int, default=11, help="timed yaws per mode (11)")
    parser.add_argument(
        "--capture", type=Path, default=rti_capture_path(), help="an RTI capture's .lp file"
    )
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error(f"--repeats must be at least 1, got {args.repeats}")
    try:
        args.out.mkdir(parents=True, exist_ok=True)
        rows = measure(args.capture, args.repeats)
    except (RigError, OSError) as error:  # a capture or panorama that cannot be read
        print(f"python -m bench.turning: {error}", file=sys.stderr)
        return 2
    document = {"capture": str(args.capture), "machine": machine(), "rows": rows}
    (args.out / "turning.json").write_text(json.dumps(document, indent=2) + "\n")
    chart(rows, args.out / "turning.png")
    print(f"wrote {args.out / 'turning.json'} and {args.out / 'turning.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

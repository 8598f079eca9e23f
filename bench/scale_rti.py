"""The RTI scale benchmark: a full-resolution capture through import, fit, evaluate, export, view.

``python -m bench.scale_rti -o DIR [--megapixels 1,6,24] [--lights 60]`` makes, for each size,
an RTI capture of 8-bit JPEGs (:func:`make_rti_capture`: the bundled capture upscaled, with a
fixed surface texture and sensor noise, so that the files and the store compress as a real
capture's do), then runs each stage as its own process, the way a user runs it:

- ``import``: :func:`processing.rti.import_rti` of the ``.lp`` file into a field store (what
  every command given an ``.lp`` file does first);
- ``fit``: ``rig fit STORE`` (every model a pixel field has: lambert, lambert+ggx, ptm, hsh2,
  hsh3), written to the fit file beside the store;
- ``evaluate``: ``rig evaluate STORE --split every-other`` (the methods of ``--methods``);
- ``export-web``: ``rig export-web STORE -o DIR --models ptm``;
- ``view``: ``rig view STORE``, stopped once its light view (the page's GPU relighting: the
  HSH and PTM fits exported for the page) answers ready on ``/api/light``, or at
  ``--view-wait``.

For each it records the wall time, seconds per megapixel and the stage's peak resident memory
(each process's own peak, ``VmHWM``: see :func:`bench.process_watch.run_watched`). A stage
whose resident memory passes ``--stop-above`` (default 8 GiB, twice the bound the issue sets)
is stopped and recorded as such, so a stage that does not stream cannot take the machine
down. Writes ``scale_rti.json`` and ``scale_rti.png`` and prints the table. Not a test: nothing
is asserted about time.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bench.process_watch import run_watched
from bench.scale import cost_and_memory_chart
from core.errors import InputError
from core.memory_budget import format_size, parse_size

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["ASPECT", "capture_size", "main", "make_rti_capture"]

#: Width over height of the captures made (a DSLR's 3:2; 6000 x 4000 at 24 megapixels).
ASPECT = 1.5
#: Relative amplitude of the surface texture multiplied into every image.
TEXTURE = 0.15
#: Pixels over which the texture varies (its Gaussian blur's sigma at full size).
TEXTURE_SCALE = 1.5
#: Standard deviation of the sensor noise added to every image, in 8-bit code values.
NOISE = 1.0
#: The stages, in the order they run.
STAGES = ("import", "fit", "evaluate", "export-web", "view")


def capture_size(megapixels: float) -> tuple[int, int]:
    """(width, height) of a :data:`ASPECT` image of about ``megapixels`` million pixels.

    Both sides are multiples of 8 (JPEG blocks): 24 gives 6000 x 4000, 6 gives 3000 x 2000.
    """
    if not megapixels > 0:
        raise InputError(f"megapixels must be positive, got {megapixels}")
    height = max(8, 8 * round(math.sqrt(megapixels * 1e6 / ASPECT) / 8))
    width = max(8, 8 * round(height * ASPECT / 8))
    return width, height


def make_rti_capture(
    folder: str | os.PathLike[str],
    megapixels: float,
    lights: int = 60,
    *,
    seed: int = 0,
    workers: int = 2,
    quality: int = 95,
) -> Path:
    """Write an RTI capture of ``lights`` 8-bit JPEGs of about ``megapixels`` million pixels.

    The bundled capture (:func:`core.sample_data.rti_capture_path`, 240 lights of 64 x 43) is
    the source: ``lights`` of its lights, evenly spaced in its order, each image decoded to
    linear light and upscaled (bicubic) to :func:`capture_size`, multiplied by one fixed
    surface texture (1 + :data:`TEXTURE` times a unit-variance noise blurred over
    :data:`TEXTURE_SCALE` pixels: the same for every light, as an albedo is), encoded to
    sRGB, given sensor noise (:data:`NOISE` code values, a fresh draw per image) and written
    as a JPEG of ``quality``. Without the texture and the noise an upscaled image is so smooth
    that its JPEG and the store compress tens of times better than a photograph's, and the
    benchmark would time a file system that holds nothing.

    Parameters
    ----------
    folder : the capture's folder (created; an existing capture there is overwritten)
    megapixels : float, image size in millions of pixels
    lights : int, 3..240, images (and ``.lp`` lines)
    seed : int, the texture's and the noise's seed (the same seed writes the same files)
    workers : int, images made at once (threads: the decoding, resizing and encoding release
        the GIL)
    quality : int, JPEG quality

    The images written are counted with a bar (:mod:`core.progress`), shown by the caller's
    hook.

    Returns
    -------
    Path of ``folder/dirs.lp`` (images ``images/light_NNN.jpg``; directions in the camera
    frame, as the bundled ``.lp`` gives them).
    """
    import cv2

    from core.colour import linear_to_srgb
    from core.image_io import linear_from_pixels, read_pixels, write_srgb8
    from core.lp_format import read_lp, write_lp
    from core.progress import progress_bar
    from core.sample_data import rti_capture_path

    source = read_lp(rti_capture_path())
    if not 3 <= lights <= len(source):
        raise InputError(f"lights must be 3..{len(source)}, got {lights}")
    width, height = capture_size(megapixels)
    chosen = np.unique(np.round(np.linspace(0, len(source) - 1, lights)).astype(int))
    root = Path(folder)
    (root / "images").mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng([seed, 0])
    grain = cv2.GaussianBlur(
        rng.standard_normal((height, width), dtype=np.float32), (0, 0), TEXTURE_SCALE
    )
    texture = np.clip(1.0 + TEXTURE * grain / max(float(grain.std()), 1e-6), 0.0, None)
    del grain
    names = [f"images/light_{t:03d}.jpg" for t in range(len(chosen))]
    encode = linear_to_srgb(np.arange(65536, dtype=np.float32) / np.float32(65535.0)) * 255.0

    def one(index: int) -> None:
        small = linear_from_pixels(
            read_pixels(rti_capture_path().parent / source.files[chosen[index]]), transfer="srgb"
        )
        large = cv2.resize(small, (width, height), interpolation=cv2.INTER_CUBIC)
        large = np.clip(large, 0.0, None) * texture[:, :, None]
        noise = np.random.default_rng([seed, 1, index]).standard_normal(large.shape, np.float32)
        # Through a table of 16-bit linear steps: the curve's powers cost seconds an image at
        # 24 megapixels, the table's step is at most 0.05 code values (at black)
        steps = np.round(np.clip(large, 0.0, 1.0) * np.float32(65535.0)).astype(np.uint16)
        codes = encode[steps] + np.float32(NOISE) * noise
        write_srgb8(root / names[index], np.clip(np.round(codes), 0, 255).astype(np.uint8),
                    quality=quality)  # fmt: skip

    with ThreadPoolExecutor(max(1, workers)) as pool:
        made = pool.map(one, range(len(chosen)))
        for _ in progress_bar(made, total=len(chosen), desc="capture", unit="image"):
            pass
    write_lp(root / "dirs.lp", names, source.directions[chosen])
    return root / "dirs.lp"


class _LightViewReady:
    """Whether ``rig view``'s light view (the page's GPU relighting) is ready, asked over HTTP.

    Called with the server's output: it finds the address there and asks ``/api/light``;
    true once the status is ``ready`` or ``failed``. ``seen`` keeps the last answer.
    """

    def __init__(self) -> None:
        self.seen: dict[str, Any] | None = None

    def __call__(self, output: str) -> bool:
        import re
        import urllib.request

        found = re.search(r"http://[\w.:\[\]-]+/", output)
        if found is None:
            return False
        try:
            with urllib.request.urlopen(found.group(0) + "api/light", timeout=5) as answer:
                self.seen = json.loads(answer.read())
        except (OSError, ValueError):
            return False  # not answering yet, or busy
        return self.seen is not None and self.seen.get("status") in ("ready", "failed")


def _capture_stage(args: argparse.Namespace) -> int:
    """``--stage capture``: :func:`make_rti_capture` into ``--folder``."""
    make_rti_capture(args.folder, float(args.megapixels), args.lights, workers=args.workers)
    return 0


def _import_stage(args: argparse.Namespace) -> int:
    """``--stage import``: :func:`processing.rti.import_rti` of ``--lp`` into ``--store``."""
    from processing.rti import import_rti

    import_rti(args.lp, args.store)
    return 0


def _size_of(path: Path) -> int:
    """Bytes of a file, or of every file under a folder (0 when missing)."""
    if path.is_file():
        return path.stat().st_size
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file()) if path.is_dir() else 0


def measure_size(megapixels: float, args: argparse.Namespace, work: Path) -> dict[str, Any]:
    """Make the capture of one size and run every stage on it; its figures (JSON-ready)."""
    rig = [str(Path(sys.executable).with_name("rig"))]
    width, height = capture_size(megapixels)
    pixels = width * height
    name = f"{width}x{height}"
    capture, store = work / f"capture-{name}", work / f"{name}.zarr"
    # A run without the import stage goes on from the store (and fit) an earlier run left.
    stale = (store, work / f"web-{name}") if "import" in args.stages else (work / f"web-{name}",)
    for path in stale:
        shutil.rmtree(path, ignore_errors=True)
    lp = capture / "dirs.lp"
    made: dict[str, Any] | None = None
    reused = args.reuse and lp.is_file()
    print(f"{name} ({pixels / 1e6:.1f} MP, {args.lights} lights): "
          f"{'the capture made before' if reused else 'making the capture'}",
          file=sys.stderr, flush=True)  # fmt: skip
    if not reused:
        shutil.rmtree(capture, ignore_errors=True)
        # In a process of its own: this one stays small (see run_watched on wait4).
        made = run_watched([sys.executable, "-m", "bench.scale_rti", "--stage", "capture",
                            "--folder", str(capture), "--megapixels", str(megapixels),
                            "--lights", str(args.lights), "--workers", str(args.workers)],
                           stop_above=args.stop_above, timeout=args.timeout)  # fmt: skip
        if made["returncode"] != 0:
            raise RuntimeError(f"making the capture failed:\n{made['output']}")
    watch = {"stop_above": args.stop_above, "timeout": args.timeout}
    light_view = _LightViewReady()
    commands: dict[str, tuple[list[str], dict[str, Any]]] = {
        "import": ([sys.executable, "-m", "bench.scale_rti", "--stage", "import", "--lp", str(lp),
                    "--store", str(store)], watch),
        "fit": ([*rig, "fit", str(store), "--models", args.models, "--quiet"], watch),
        "evaluate": ([*rig, "evaluate", str(store), "--split", "every-other", "--methods",
                      args.methods, "--quiet", "--json", str(work / f"evaluate-{name}.json")],
                     watch),
        "export-web": ([*rig, "export-web", str(store), "-o", str(work / f"web-{name}"),
                        "--models", "ptm", "--quiet"], watch),
        "view": ([*rig, "view", str(store)],
                 watch | {"ready": "http://", "until": light_view, "linger": args.view_linger,
                          "timeout": min(args.timeout, args.view_wait)}),
    }  # fmt: skip
    stages: dict[str, dict[str, Any]] = {}
    for stage in args.stages:
        argv, options = commands[stage]
        print(f"  {stage}: {' '.join(argv)}", file=sys.stderr, flush=True)
        result = run_watched(argv, **options)
        if stage == "view":
            result["light_view"] = light_view.seen
        result["seconds_per_megapixel"] = result["seconds"] / (pixels / 1e6)
        result["within_bound"] = result["peak_bytes"] <= args.bound
        stages[stage] = result
        said = result["stopped"] or f"exit {result['returncode']}"
        print(f"  {stage}: {result['seconds']:.0f} s, peak {format_size(result['peak_bytes'])}"
              f" ({said})", file=sys.stderr, flush=True)  # fmt: skip
        if stage == "import" and result["returncode"] != 0:
            break  # nothing to run the others on
    row = {
        "megapixels": pixels / 1e6,
        "command": " ".join(["python -m bench.scale_rti", *sys.argv[1:]]),
        "width": width,
        "height": height,
        "lights": args.lights,
        "float32_bytes": pixels * args.lights * 3 * 4,
        "make_capture_seconds": None if made is None else made["seconds"],
        "fit_models": args.models,
        "evaluate_methods": args.methods,
        "disk_bytes": {
            "capture": _size_of(capture),
            "store": _size_of(store),
            "fit": _size_of(store.with_name(store.name + ".models.npz")),
            "web": _size_of(work / f"web-{name}"),
        },
        "stages": stages,
    }
    if not args.keep:
        for path in (*(() if args.reuse else (capture,)), store, work / f"web-{name}"):
            shutil.rmtree(path, ignore_errors=True)
        store.with_name(store.name + ".models.npz").unlink(missing_ok=True)
    return row


def _table(results: list[dict[str, Any]], bound: int) -> str:
    lines = [
        "| image | float32 capture | stage | time (s) | s per MP | peak memory | within "
        f"{format_size(bound)} | note |",
        "|---|---:|---|---:|---:|---:|---|---|",
    ]
    for row in results:
        size = f"{row['width']} x {row['height']} ({row['megapixels']:.1f} MP)"
        for name, stage in row["stages"].items():
            note = stage["stopped"] or ("" if stage["returncode"] == 0 else
                                        f"failed ({stage['returncode']})")  # fmt: skip
            if stage["stopped"] == "ready":
                status = (stage.get("light_view") or {}).get("status", "?")
                note = (f"address after {stage['ready_seconds']:.0f} s, light view {status} "
                        f"after {stage['until_seconds']:.0f} s")  # fmt: skip
            elif stage["stopped"] == "memory":
                note = "stopped: memory above the stop line"
            if name == "fit" and "fit_models" in row:
                note = f"{note}; " * bool(note) + f"models {row['fit_models']}"
            if name == "evaluate" and "evaluate_methods" in row:
                count = len(row["evaluate_methods"].split(","))
                note = f"{note}; " * bool(note) + f"{count} methods"
            lines.append(
                f"| {size} | {format_size(row['float32_bytes'])} | {name} | "
                f"{stage['seconds']:.0f} | {stage['seconds_per_megapixel']:.1f} | "
                f"{format_size(stage['peak_bytes'])} | {'yes' if stage['within_bound'] else 'NO'}"
                f" | {note} |"
            )
    return "\n".join(lines)


def _chart(results: list[dict[str, Any]], path: Path, bound: int) -> None:
    sizes = [row["megapixels"] for row in results]
    names = [n for n in STAGES if any(n in row["stages"] for row in results)]

    def draw(cost: Axes, memory: Axes) -> None:
        for name in names:
            rows = [row for row in results if name in row["stages"]]
            x = [row["megapixels"] for row in rows]
            per_megapixel = [r["stages"][name]["seconds_per_megapixel"] for r in rows]
            cost.plot(x, per_megapixel, "o-", label=name)
            memory.plot(x, [r["stages"][name]["peak_bytes"] / 2**30 for r in rows], "o-",
                        label=name)  # fmt: skip
        memory.axhline(bound / 2**30, color="k", linestyle="--", label="the bound")
        memory.plot(sizes, [r["float32_bytes"] / 2**30 for r in results], "k:",
                    label="the capture in float32")  # fmt: skip

    cost_and_memory_chart(
        path,
        draw,
        "megapixels",
        cost=("seconds per megapixel", "time per megapixel"),
        memory=("peak resident (GiB)", "peak memory of each stage's process"),
    )


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m bench.scale_rti``."""
    from processing.sample_models import MODELS
    from render.evaluation import CHOSEN
    from render.light_prediction import PREDICTORS

    parser = argparse.ArgumentParser(
        prog="python -m bench.scale_rti",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("-o", "--output", type=Path, help="output directory (JSON, chart)")
    parser.add_argument(
        "--work",
        type=Path,
        help="where captures and stores go (default "
        "/tmp/rig-scale-rti; tens of GB at 24 MP, removed unless --keep)",
    )
    parser.add_argument("--megapixels", default="1,6,24", help="sizes (default 1,6,24)")
    parser.add_argument("--lights", type=int, default=60, help="lights (default 60)")
    parser.add_argument(
        "--stages", default=",".join(STAGES), help=f"stages to run (default {','.join(STAGES)})"
    )
    parser.add_argument(
        "--models",
        default=",".join(MODELS),
        help="rig fit --models (default every model a pixel field has)",
    )
    parser.add_argument(
        "--methods",
        default=",".join((*PREDICTORS, *CHOSEN)),
        help="rig evaluate --methods (default every one)",
    )
    parser.add_argument("--bound", default="4G", help="the memory bound reported (default 4G)")
    parser.add_argument(
        "--stop-above",
        default="8G",
        help="stop a stage whose resident memory passes this (default 8G)",
    )
    parser.add_argument(
        "--timeout",
        type=float,
        default=4 * 3600.0,
        help="stop a stage after this many seconds (default 4 h)",
    )
    parser.add_argument(
        "--view-wait",
        type=float,
        default=3600.0,
        help="seconds rig view may take to make its light view ready (default 3600)",
    )
    parser.add_argument(
        "--view-linger",
        type=float,
        default=5.0,
        help="seconds rig view runs on once its light view is ready (default 5)",
    )
    parser.add_argument("--workers", type=int, default=2, help="threads making a capture")
    parser.add_argument("--keep", action="store_true", help="keep the captures and stores")
    parser.add_argument("--append", action="store_true",
                        help="add the sizes to DIR/scale_rti.json rather than replace it "
                        "(sizes run with other --models or --methods)")  # fmt: skip
    parser.add_argument(
        "--from-json",
        action="store_true",
        help="redraw the chart and the table from DIR/scale_rti.json",
    )
    parser.add_argument(
        "--reuse", action="store_true",
        help="use a capture already in --work (made by an earlier run) instead of a new one",
    )  # fmt: skip
    parser.add_argument("--stage", choices=("import", "capture"), help=argparse.SUPPRESS)
    parser.add_argument("--folder", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--lp", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--store", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)  # fmt: skip
    if args.stage == "import":
        return _import_stage(args)
    if args.stage == "capture":
        return _capture_stage(args)
    if args.output is None:
        parser.error("-o DIR is required")
    args.bound, args.stop_above = parse_size(args.bound), parse_size(args.stop_above)
    args.stages = [s for s in args.stages.split(",") if s]
    unknown = sorted(set(args.stages) - set(STAGES))
    if unknown:
        parser.error(f"unknown stages {unknown}; choose among {', '.join(STAGES)}")
    out: Path = args.output
    out.mkdir(parents=True, exist_ok=True)
    saved = out / "scale_rti.json"
    results: list[dict[str, Any]] = []
    if args.from_json or args.append:
        results = json.loads(saved.read_text())["sizes"]
    if not args.from_json:
        work: Path = args.work or Path("/tmp/rig-scale-rti")
        work.mkdir(parents=True, exist_ok=True)
        for megapixels in (float(m) for m in args.megapixels.split(",")):
            results.append(measure_size(megapixels, args, work))
            results.sort(key=lambda row: row["megapixels"])
            document = {"bound_bytes": args.bound, "stop_above_bytes": args.stop_above,
                        "sizes": results}  # fmt: skip
            saved.write_text(json.dumps(document, indent=2))
    _chart(results, out / "scale_rti.png", args.bound)
    print(_table(results, args.bound))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``rig export-web``: a pixel field's models (PTM, HSH, neural) for the web RTI viewers.

Application layer: parses, opens the field (a store or an RTI capture) and calls
:func:`render.web_export.export.export_web` (the format: ``docs/web-export.md``). The parser
takes its choices and defaults from :mod:`app.cli.choices` (help answers without the library);
the library is imported when the command runs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from app.cli.args import count, names_among, output_directory, positive, quality, whole
from app.cli.evaluate import add_transfer_option

__all__ = ["add_export_web"]

#: Why single PNG planes are refused (OpenLIME's ``Layout.imageUrl`` writes the suffix).
PNG_UNTILED = (
    "--format png --no-tiles: OpenLIME's single-image layout asks for plane_N.jpg whatever "
    "info.json says, so PNG planes load only as deep-zoom tiles (their .dzi names the "
    "format): drop --no-tiles, or write --format jpg"
)


def add_export_web(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig export-web FIELD -o DIR`` on the ``rig`` sub-command parser."""
    from app.cli.choices import WEB_MODELS
    from app.cli.choices import WEB_NEURAL_SECONDS as NEURAL_SECONDS
    from app.cli.choices import WEB_TILE_SIZE as TILE_SIZE
    from app.cli.choices import WEB_TILE_THRESHOLD as TILE_THRESHOLD

    p = commands.add_parser(
        "export-web",
        help="write a pixel field's PTM/HSH/neural models for the web RTI viewers (OpenLIME, "
        "Relight)",
        description="Fit the linear light models (PTM, HSH) to the 8-bit sRGB values of one "
        "view, as the RTI tools fit them, and OpenLIME's neural model (a code of 9 values per "
        "pixel and its decoder), and write them in the web format Relight writes and OpenLIME "
        "loads: per model a folder with info.json and the quantised planes (plane_N.jpg, or "
        "deep-zoom tiles plane_N.dzi and plane_N_files/), and the normal map (photometric "
        "stereo) as normals.png (16-bit) and normals.exr (docs/web-export.md).",
    )
    p.add_argument("field", type=Path, help="field store of pixels, or RTI capture (.lp or folder)")
    p.add_argument("-o", "--output", type=output_directory, required=True, help="output directory")
    p.add_argument("--camera", type=whole, default=0, help="the view (default 0)")
    p.add_argument(
        "--models",
        type=_models,
        default=("ptm", "hsh3"),
        help=f"comma-separated models among {', '.join(WEB_MODELS)} (default ptm,hsh3)",
    )
    p.add_argument(
        "--format",
        choices=("jpg", "png"),
        default="jpg",
        help="plane images (default jpg; png is lossless and, as OpenLIME reads PNG planes "
        "only as deep-zoom tiles, tiled)",
    )
    p.add_argument("--quality", type=quality, default=95, help="JPEG quality (default 95)")
    p.add_argument(
        "--tiles",
        action=argparse.BooleanOptionalAction,
        default=None,
        help=f"deep-zoom tiles (default: when a side exceeds {TILE_THRESHOLD} pixels, or for "
        "png planes)",
    )
    p.add_argument(
        "--tile-size",
        type=count,
        default=None,
        help=f"tile side (default {TILE_SIZE}; on an image no longer than that, the largest "
        "power of two less 2 below its longest side)",
    )
    p.add_argument(
        "--neural-seconds",
        type=positive,
        default=NEURAL_SECONDS,
        help=f"time budget of the neural model's fit (default {NEURAL_SECONDS:.0f} s)",
    )
    p.add_argument(
        "--neural-holdout",
        type=_share,
        default=0.0,
        help="share of the lights the neural model is not fitted to, to measure it there "
        "(0 to 0.5; default 0)",
    )
    p.add_argument("--mask", type=Path, help="RTI captures: image whose non-zero pixels count")
    p.add_argument("--quiet", action="store_true", help="no progress while importing or fitting")
    add_transfer_option(p)
    p.set_defaults(handler=_run_export_web)


def _models(text: str) -> tuple[str, ...]:
    from app.cli.choices import WEB_MODELS

    return names_among(text, WEB_MODELS, "model")


def _share(text: str) -> float:
    """A share of the lights, 0 <= x < 0.5."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0.0 <= value < 0.5:
        raise argparse.ArgumentTypeError(f"must be at least 0 and below 0.5, got {text!r}")
    return value


def _run_export_web(args: argparse.Namespace) -> int:
    from core.errors import InputError

    if args.format == "png" and args.tiles is False:
        raise InputError(PNG_UNTILED)  # before the capture is read: nothing to wait for

    from processing.neural_rti_fit import NeuralSettings
    from processing.rti import open_field_or_rti
    from render.web_export.export import export_web

    def say(message: str) -> None:
        print(f"  {message}", file=sys.stderr, flush=True)

    with open_field_or_rti(
        args.field, transfer=args.transfer, mask=args.mask, print_assumed=not args.quiet
    ) as field:
        cameras = field.shape[0]
        if not 0 <= args.camera < cameras:
            raise InputError(f"--camera {args.camera}: {args.field} holds cameras 0..{cameras - 1}")
        result = export_web(
            field,
            args.output,
            camera=args.camera,
            models=args.models,
            image_format=args.format,
            quality=args.quality,
            tiles=args.tiles,
            tile_size=args.tile_size,
            neural=NeuralSettings(max_seconds=args.neural_seconds, holdout=args.neural_holdout),
            progress=None if args.quiet else say,
        )
    print(f"{result.width}x{result.height} pixels of camera {result.camera} -> {result.output}/")
    for note in result.notes:
        print(f"  note: {note}")
    for model in result.models:
        kind = (
            f"deep zoom, tiles of {result.tile_size} pixels, {model.levels} levels, "
            f"{len(model.files)} .dzi"
            if model.levels
            else f"{len(model.files)} images"
        )
        print(
            f"  {model.folder}/: info.json, {model.planes} planes ({kind}); quantisation "
            f"error under the measured lights: RMS {model.rms_error:.2f}, max "
            f"{model.max_error:.1f} 8-bit levels; {model.psnr:.1f} dB against the capture"
        )
        if model.network is not None:
            fitted = f"{model.fit_psnr:.1f} dB before quantisation" if model.fit_psnr else ""
            held = (
                f"; held-out lights: {model.held_psnr:.1f} dB ({model.fit_held_psnr:.1f} dB "
                "before quantisation)"
                if model.held_psnr is not None and model.fit_held_psnr is not None
                else ""
            )
            print(
                f"    neural: fitted in {model.seconds:.0f} s on {model.network.device}, "
                f"{model.network.steps} steps, {model.network.hidden} hidden units; "
                f"{fitted}{held}"
            )
    print(f"  normals: {result.normals_png} (16-bit), {result.normals_exr} (float)")
    return 0

"""``rig export-web``: a pixel field's PTM and HSH fits for the RTI web viewers.

Application layer: parses, opens the field (a store or an RTI capture) and calls
:func:`render.web_export.export_web` (the format: ``docs/web-export.md``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from app.cli_args import count, names_among, output_directory, quality, whole
from app.cli_evaluate import add_transfer_option

__all__ = ["add_export_web"]


def add_export_web(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig export-web FIELD -o DIR`` on the ``rig`` sub-command parser."""
    from render.web_export import TILE_SIZE, TILE_THRESHOLD

    p = commands.add_parser(
        "export-web",
        help="write a pixel field's PTM/HSH fits for the RTI web viewers (OpenLIME, Relight)",
        description="Fit the linear light models (PTM, HSH) to the 8-bit sRGB values of one "
        "view, as the RTI tools fit them, and write them in the web format Relight writes and "
        "OpenLIME loads: per model a folder with info.json and the quantised coefficient "
        "planes (plane_N.jpg, or deep-zoom tiles plane_N.dzi and plane_N_files/), and the "
        "normal map (photometric stereo) as normals.png (16-bit) and normals.exr "
        "(docs/web-export.md).",
    )
    p.add_argument("field", type=Path, help="field store of pixels, or RTI capture (.lp or folder)")
    p.add_argument("-o", "--output", type=output_directory, required=True, help="output directory")
    p.add_argument("--camera", type=whole, default=0, help="the view (default 0)")
    p.add_argument(
        "--models",
        type=_models,
        default=("ptm", "hsh3"),
        help="comma-separated models among ptm, hsh2, hsh3 (default ptm,hsh3)",
    )
    p.add_argument(
        "--format",
        choices=("jpg", "png"),
        default="jpg",
        help="plane images (default jpg; png is lossless and loads through deep zoom)",
    )
    p.add_argument("--quality", type=quality, default=95, help="JPEG quality (default 95)")
    p.add_argument(
        "--tiles",
        action=argparse.BooleanOptionalAction,
        default=None,
        help=f"deep-zoom tiles (default: when a side exceeds {TILE_THRESHOLD} pixels)",
    )
    p.add_argument(
        "--tile-size", type=count, default=TILE_SIZE, help=f"tile side (default {TILE_SIZE})"
    )
    p.add_argument("--mask", type=Path, help="RTI captures: image whose non-zero pixels count")
    p.add_argument("--quiet", action="store_true", help="no progress while importing")
    add_transfer_option(p)
    p.set_defaults(handler=_run_export_web)


def _models(text: str) -> tuple[str, ...]:
    from render.web_export import WEB_MODELS

    return names_among(text, WEB_MODELS, "model")


def _run_export_web(args: argparse.Namespace) -> int:
    from core.errors import InputError
    from processing.rti import open_field_or_rti
    from render.web_export import export_web

    with open_field_or_rti(
        args.field, progress=not args.quiet, transfer=args.transfer, mask=args.mask
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
        )
    print(f"{result.width}x{result.height} pixels of camera {result.camera} -> {result.output}/")
    for model in result.models:
        kind = (
            f"deep zoom, {model.levels} levels, {len(model.files)} .dzi"
            if model.levels
            else f"{len(model.files)} images"
        )
        print(
            f"  {model.folder}/: info.json, {model.planes} planes ({kind}); error under the "
            f"measured lights: RMS {model.rms_error:.2f}, max {model.max_error:.1f} 8-bit levels"
        )
    print(f"  normals: {result.normals_png} (16-bit), {result.normals_exr} (float)")
    return 0

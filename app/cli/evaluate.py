"""``rig evaluate`` (held-out lights, every method) and ``rig relight --lights`` (any light).

Application layer: parses, opens the field and calls :mod:`render.evaluation` and
:mod:`render.light_prediction`.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path
from typing import Any

from app.cli.args import (
    add_dask_options,
    cluster_for,
    names_among,
    output_file,
    require_output,
    resampled_size,
)
from app.cli.choices import CHOSEN, PREDICTORS, SPLITS
from core.errors import InputError

__all__ = [
    "add_below_horizon_option",
    "add_evaluate",
    "add_transfer_option",
    "relight_lights",
    "resample",
    "say_resampled",
]


def add_transfer_option(p: argparse.ArgumentParser) -> None:
    """``--transfer``: how an RTI capture's images are decoded (its import says what it did)."""
    p.add_argument(
        "--transfer",
        choices=("auto", "srgb", "linear"),
        default="auto",
        help="RTI captures: decode the images as sRGB or as linear values (default auto: 8-bit "
        "sRGB, 16-bit and float linear); a mask (FILE.mask.png or mask.png) and intensities "
        "(a fifth .lp column or FILE.intensities) beside the .lp are used (docs/processing.md)",
    )


def add_below_horizon_option(p: argparse.ArgumentParser) -> None:
    """``--below-horizon``: whether the environment below the object's base reaches it."""
    p.add_argument(
        "--below-horizon",
        choices=("blocked", "open"),
        help="what lies below the horizon of the object's base: blocked (a table, base or "
        "turntable hides that part of the environment: its light is dropped) or open (the "
        "object is lit from below too). Default: what the field states; an RTI capture is "
        "imported as blocked, simulated fields float (open)",
    )


def add_evaluate(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig evaluate`` on the ``rig`` sub-command parser."""
    p = commands.add_parser(
        "evaluate",
        help="score every relighting method on held-out lights (PSNR, SSIM, dE2000, RMSE)",
        description="Predict lights the methods never saw and compare with the measured "
        "images, as the RTI literature does: the test images of an .lp file (or a field "
        "store of the same views under other lights), or a split of the field's own lights. "
        "Prints a table (best PSNR first); --json and --markdown save it. Methods: "
        + ", ".join(PREDICTORS)
        + "; auto (auto-fast): what rig relight --lights chooses (among the quick rungs).",
    )
    p.add_argument("field", type=Path, help="field store or RTI capture (.lp or its folder)")
    test = p.add_mutually_exclusive_group(required=True)
    test.add_argument("--test", type=Path, help="test lights: an .lp file, or a field store")
    test.add_argument(
        "--split",
        help=f"hold out part of the field's own lights: {', '.join(SPLITS)} (random:SEED)",
    )
    p.add_argument(
        "--methods",
        type=_methods,
        default=PREDICTORS,
        help="comma-separated methods (default: every one)",
    )
    p.add_argument("--mask", type=Path, help="pixel fields: image whose non-zero pixels count")
    p.add_argument("--json", type=output_file, help="write every score here (JSON)")
    p.add_argument("--markdown", type=output_file, help="write the table here (Markdown)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_transfer_option(p)
    add_dask_options(p)
    p.set_defaults(handler=_run_evaluate)


def _methods(text: str) -> tuple[str, ...]:
    return names_among(text, (*PREDICTORS, *CHOSEN), "method")


def _read_mask(path: Path, shape: tuple[int, int] | None) -> Any:
    import numpy as np

    from core.image_io import read_pixels

    if shape is None:
        raise InputError(f"{path}: a mask applies to a field of pixels (an RTI capture)")
    pixels = np.asarray(read_pixels(path))
    mask = (pixels.reshape(*pixels.shape[:2], -1) > 0).any(axis=2)
    if mask.shape != shape:
        raise InputError(f"{path}: the mask is {mask.shape[1]}x{mask.shape[0]}, the images are "
                         f"{shape[1]}x{shape[0]}")  # fmt: skip
    if not mask.any():
        raise InputError(f"{path}: the mask selects no pixel")
    return mask


def _run_evaluate(args: argparse.Namespace) -> int:
    from core.atomic import atomic_path, write_json_atomic
    from processing.rti import open_field_or_rti
    from render.evaluation import evaluate
    from render.held_out_lights import against_test, held_out_split

    with open_field_or_rti(
        args.field, transfer=args.transfer, print_assumed=not args.quiet
    ) as field:
        mask = None if args.mask is None else _read_mask(args.mask, field.image_shape)
        # In memory: the field's lights split, or the test capture; a large view as tiles of
        # it, read band by band (render.held_out_lights.pixel_sample), never whole.
        if args.split is not None:
            pair = held_out_split(field, args.split, mask)
            assert pair.test_lights is not None
            names: list[str] | None = [f"light {int(t)}" for t in pair.test_lights]
            where = f"split {args.split}"
        else:
            pair = against_test(field, args.test, mask, transfer=args.transfer)
            names = _lp_names(args.test) if args.test.suffix.lower() == ".lp" else None
            where = str(args.test)
        if args.methods == PREDICTORS and not args.quiet:
            # Every method by default: say what that costs and how to choose fewer.
            print(f"scoring all {len(PREDICTORS)} methods one after another (the learned ones "
                  "train for up to a few minutes each); --methods NAME,... scores fewer, e.g. "
                  "--methods rbf,ptm-8bit,hsh3-8bit,adaptive", file=sys.stderr)  # fmt: skip
        with cluster_for(args) as client:
            result = evaluate(pair.fit, pair.test, args.methods, mask=pair.mask,
                              test_names=names, client=client,
                              sample=pair.sample)  # fmt: skip
    result = dataclasses.replace(result, field=str(args.field), test=where)
    table = result.markdown()
    print(table, end="")
    best = result.best()
    print(f"best: {best.name}")
    if args.json is not None:
        write_json_atomic(args.json, result.to_json())
    if args.markdown is not None:
        with atomic_path(args.markdown) as temporary:
            temporary.write_text(table, encoding="utf-8")
    return 0


def _lp_names(path: Path) -> list[str]:
    from core.lp_format import read_lp

    return list(read_lp(path).files)


def relight_lights(args: argparse.Namespace, field: Any) -> int:
    """``rig relight FIELD --lights FILE.lp -o DIR``: one image per line of the ``.lp`` file.

    The directions are in the camera frame of the field's view (a pixel field's camera, or
    ``--camera INDEX`` of a point field); each image is written as ``DIR/<entry>.png`` (8-bit
    sRGB) and, with ``--exr``, ``DIR/<entry>.exr`` (linear), ``<entry>`` the ``.lp`` file
    name without its suffix.
    """
    import numpy as np

    from core.camera_model import camera_to_rig
    from core.image_io import write_exr, write_srgb8
    from core.lp_format import read_lp
    from processing.image_quality import clipped_srgb_8bit, display_scale
    from render.field_view import FieldView
    from render.light_prediction import make_predictor
    from render.rung_choice import MIXTURE_MARGIN_DB, choose_light_rung

    directory = require_output(args.output, directory=True)
    lights = read_lp(args.lights)
    stems = [_entry_stem(directory, name, args.lights) for name in lights.files]
    _distinct(stems, tuple(lights.files), args.lights)
    if field.sample_kind == "pixels":
        camera = 0
    else:
        if args.camera is None:
            raise InputError(f"{args.field} is a field of points: name a captured --camera INDEX")
        camera = args.camera
        if not 0 <= camera < field.shape[0]:
            raise InputError(f"--camera {camera}: {args.field} has cameras 0..{field.shape[0] - 1}")
    view = field.cameras[camera]
    resample_to = resampled_size(
        args.size, (view.width, view.height), f"the view of camera {camera} of {args.field}"
    )
    directions = camera_to_rig(lights.directions, view)
    # The light-stage sum's image under one light is the nearest measured image.
    method = "nearest" if args.method == "light-stage" else args.method
    if method == "auto":
        choice = choose_light_rung(field, directions, fast=args.fast)
        for score in choice.scores:
            psnr = f"{score.psnr:6.2f} dB" if math.isfinite(score.psnr) else "   n/a   "
            note = f" {score.note}" if score.note else ""
            print(f"  {score.name:<22} {psnr}  ({score.seconds:.1f} s){note}")
        method = choice.describe()
        why = (
            "best held-out PSNR"
            if choice.scores[0].name == choice.name
            else f"best single rung: the mixture is not {MIXTURE_MARGIN_DB:g} dB better"
        )
        print(f"method: {method} ({why}, {' and '.join(choice.folds)}; chosen in "
              f"{sum(s.seconds for s in choice.scores if s.name != 'mixture'):.0f} s)")  # fmt: skip
        predictor = choice.predictor(field)
    else:
        predictor = make_predictor(field, method)
    predicted = predictor.predict(camera, directions)
    scale = (
        1.0
        if field.provenance.get("source") == "rti"
        else display_scale(field.camera_slab(camera)[:, field.visibility[camera]])
    )
    views = FieldView.captured(field, camera).image
    if resample_to is not None:
        say_resampled((view.width, view.height), resample_to)
    for stem, values in zip(stems, predicted, strict=True):
        image = views(values)
        if resample_to is not None:
            image = resample(np.asarray(image, dtype=np.float32), resample_to)
        write_srgb8(stem.with_suffix(".png"), clipped_srgb_8bit(image, scale))
        if args.exr:
            write_exr(stem.with_suffix(".exr"), np.asarray(image, dtype=np.float32))
    print(f"{len(lights)} images under {args.lights} ({method}) -> {directory}/")
    return 0


def resample(image: Any, size: tuple[int, int]) -> Any:
    """``image`` (H, W) or (H, W, C) resampled to ``size`` (width, height).

    Area averages when it shrinks, bilinear when it grows: neither overshoots, so linear
    radiance stays non-negative and a tone-mapped frame keeps its range. A boolean mask (the
    coverage) stays one: covered where at least half of it was.
    """
    import cv2
    import numpy as np

    shrinks = size[0] * size[1] < image.shape[0] * image.shape[1]
    interpolation = cv2.INTER_AREA if shrinks else cv2.INTER_LINEAR
    if image.dtype == np.bool_:
        return cv2.resize(image.astype(np.float32), size, interpolation=interpolation) >= 0.5
    return cv2.resize(np.ascontiguousarray(image), size, interpolation=interpolation)


def say_resampled(native: tuple[int, int], size: tuple[int, int]) -> None:
    """Print that a view relit at its ``native`` size (width, height) is resampled to ``size``."""
    print(
        f"note: relit at the captured view's own size, {native[0]}x{native[1]} pixels, and "
        f"resampled to {size[0]}x{size[1]} (--size)"
    )


def _entry_stem(directory: Path, name: str, lp: Path) -> Path:
    """Where the image of ``.lp`` entry ``name`` goes (no suffix); never outside ``directory``."""
    if any(ord(character) < 32 for character in name):
        raise InputError(f"{lp}: entry {name!r} holds a control character (a NUL byte?)")
    path = Path(name.replace("\\", "/"))
    if path.is_absolute() or ".." in path.parts:
        raise InputError(
            f"{lp}: entry {name!r} would be written outside {directory}; name images by "
            "relative paths inside the output folder"
        )
    if path.name in ("", ".") or not path.stem:
        raise InputError(f"{lp}: entry {name!r} names no file; give each light an image name")
    return directory / path.with_suffix("")


def _distinct(stems: list[Path], names: tuple[str, ...], lp: Path) -> None:
    """Refuse two entries written to one file (the second would replace the first)."""
    first: dict[Path, str] = {}
    for stem, name in zip(stems, names, strict=True):
        if stem in first:
            raise InputError(
                f"{lp}: entries {first[stem]!r} and {name!r} would both be written to "
                f"{stem}.png; give each light its own image name"
            )
        first[stem] = name

"""``rig relight``: a field under a panorama (or an RTI capture under any light).

Application layer: maps the flags to a relighting mode (the choice under the panorama for a
field of pixels, :mod:`render.environment_choice`; the models or interpolation for a field of
points, :mod:`render.engines.modes`), prints the guards' warnings and writes the image or the
sequence. ``--lights`` is :func:`app.cli.evaluate.relight_lights`.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from app.cli.args import (
    DEFAULT_VIEW_SIZE,
    add_camera_options,
    angles,
    count,
    finite,
    positive,
    require_output,
    resampled_size,
    whole,
)
from app.cli.choices import (
    INTERPOLATIONS,
    MODEL_GRID_HEIGHT,
    MODELS,
    PREDICTORS,
    SAMPLERS,
    SCHEMES,
)
from app.cli.evaluate import (
    add_below_horizon_option,
    add_transfer_option,
    relight_lights,
    resample,
    say_resampled,
)
from core.errors import InputError, RigError

__all__ = ["add_relight"]


def add_relight(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig relight`` on the ``rig`` sub-command parser."""
    # Spelled out call by call, like every command's parser (duplicates pairs them by shape):
    # the options read here as --help prints them; those shared are app.cli.args' add_*.
    p = commands.add_parser(
        "relight",
        help="relight a reflectance field under a panorama",
        description="Relight a reflectance field store (rig sim field, or an imported RTI "
        "capture) under an environment panorama and render a view. The suffix of -o picks the "
        "output: .exr (linear RGB + coverage alpha), .png (tone-mapped), .gif/.mp4 (a sequence: "
        "see --sequence).",
    )
    p.add_argument(
        "field", type=Path, help="reflectance field store, or an RTI .lp file (or its folder)"
    )
    p.add_argument("--env", type=Path, help="panorama file (or --lights)")
    p.add_argument("--lights", type=Path, help="an .lp file: one image per line, relit under "
                   "that directional light (camera frame), written into -o DIR")  # fmt: skip
    p.add_argument("--method", choices=("auto", "light-stage", *PREDICTORS), default="auto",
                   help="the method that predicts unmeasured lights (default auto: the best on "
                   "held-out lights of the field, chosen among every rung; --env on an RTI "
                   "capture: the light-stage sum (the images weighted by the light of their "
                   "cells) for the smooth light, the rung best under the sharp light (a sun, "
                   "lamps, light below the lowest lights) for that; a NAME: the whole panorama "
                   "through that method)")  # fmt: skip
    p.add_argument("--fast", action="store_true", help="auto: choose among the quick rungs "
                   "only (no network to train)")  # fmt: skip
    p.add_argument("--camera", type=whole, help="--lights on a field of points: the captured "
                   "camera whose view is relit")  # fmt: skip
    p.add_argument("--exr", action="store_true", help="--lights: also write linear OpenEXR")
    add_transfer_option(p)
    add_below_horizon_option(p)
    p.add_argument("--scheme", choices=(*SCHEMES, "model"), help="how the panorama lights the "
                   "field; model: through per-sample models fitted to it (default: the most "
                   "accurate, chosen by held-out lights)")  # fmt: skip
    p.add_argument("-k", type=count, help="sampled lights (default 64; scheme model: sample K "
                   "lights instead of the panorama's grid)")  # fmt: skip
    p.add_argument("--model", choices=("auto", "auto-per-sample", *MODELS), default="auto",
                   help="scheme model: the model (default: by leave-one-light-out)")  # fmt: skip
    p.add_argument("--grid", type=count, default=MODEL_GRID_HEIGHT,
                   help="scheme model: the panorama summed into GRID x 2 GRID lights (default "
                   f"{MODEL_GRID_HEIGHT})")  # fmt: skip
    p.add_argument("--models", type=Path, help="saved fit of the field (default: FIELD.models.npz "
                   "beside the store; fitted and saved there when missing)")  # fmt: skip
    p.add_argument("--sampler", choices=SAMPLERS, default="tmed", help="sampler (default tmed)")
    p.add_argument(
        "--interp", choices=INTERPOLATIONS, help="interpolation over the measured lights"
    )
    p.add_argument("--view-interp", choices=INTERPOLATIONS, help="interpolation over the cameras")
    p.add_argument("-m", type=count, help="nearest measured lights (paper, default 3)")
    p.add_argument("-n", type=count, help="nearest measured cameras (paper, default 3)")
    p.add_argument("--paper", action="store_true", help="the paper's configuration exactly")
    p.add_argument("--view", type=angles, help="camera AZ,INCL in degrees: required for a field of "
                   "points; a field of pixels (RTI) has its own view")  # fmt: skip
    add_camera_options(p, size_help="image WIDTHxHEIGHT (default 512x512; a field of pixels, "
                       "and --lights: the captured view's own size, resampled to this when "
                       "given)")  # fmt: skip
    p.add_argument("--yaw", type=finite, default=0.0, help="rotate the environment, degrees CCW")
    p.add_argument("--exposure", type=positive, default=1.0, help="radiance scale (default 1)")
    p.add_argument("--modulation", type=Path, help="image multiplying the sampling density of "
                   "sampled lights (any resolution; zero forbids samples)")  # fmt: skip
    p.add_argument(
        "--sequence",
        choices=("turntable", "environment"),
        default="environment",
        help="for .gif/.mp4: orbit the camera, or rotate the environment (default)",
    )
    p.add_argument("--frames", type=count, default=36, help="frames of a sequence (default 36)")
    p.add_argument("--fps", type=positive, default=12.0, help="frames per second (default 12)")
    p.add_argument(
        "--renderer",
        choices=("splat", "pyvista"),
        default="splat",
        help="draw the points with our splatter (default) or VTK (pyvista, .png only)",
    )
    p.add_argument("-o", "--output", type=Path, required=True,
                   help=".exr/.png/.gif/.mp4 (--lights: a directory)")  # fmt: skip
    p.set_defaults(handler=_run_relight)


def _run_relight(args: argparse.Namespace) -> int:
    from processing.environment import read_modulation_map
    from processing.panorama import read_panorama
    from processing.rti import open_field_or_rti
    from render.output import IMAGE_SUFFIXES, SEQUENCE_SUFFIXES

    if (args.env is None) == (args.lights is None):
        raise InputError("give --env PANORAMA (an environment) or --lights FILE.lp (lights)")
    if args.lights is not None:
        with open_field_or_rti(args.field, transfer=args.transfer, print_assumed=True) as field:
            return relight_lights(args, field)
    require_output(args.output)  # a file, checked before the work
    suffix = args.output.suffix.lower()
    if suffix not in IMAGE_SUFFIXES + SEQUENCE_SUFFIXES:
        raise RigError(
            f"{args.output}: write one of {', '.join(IMAGE_SUFFIXES + SEQUENCE_SUFFIXES)}"
        )
    panorama = read_panorama(args.env)
    if panorama.note:
        print(panorama.note)
    modulation = None if args.modulation is None else read_modulation_map(args.modulation)
    with open_field_or_rti(
        args.field, transfer=args.transfer, below_horizon=args.below_horizon, print_assumed=True
    ) as field:
        return _relight_field(args, field, panorama, modulation, suffix)


def _relight_field(
    args: argparse.Namespace, field: Any, panorama: Any, modulation: Any, suffix: str
) -> int:
    from core.camera_model import PinholeCamera
    from core.splat import require_outside
    from render.output import IMAGE_SUFFIXES, write_image, write_sequence
    from render.relighting import (
        PanoramaControls,
        RelightRequest,
        prepare_relighting,
        relighting_notes,
    )
    from render.sequence import relight_prepared_sequence

    resample_to, native = None, (0, 0)
    if field.sample_kind == "pixels":
        camera = field.cameras[0]
        if args.view is not None:
            raise RigError(f"{args.field} holds one fixed view; drop --view")
        # Relit at the capture's own pixels; a --size asked for is met by resampling the
        # result (said below), a size of other proportions refused before any work.
        height, width = field.image_shape
        native = (width, height)
        resample_to = resampled_size(args.size, native, f"the capture {args.field}")
    else:
        if args.view is None:
            raise RigError(f"--view AZ,INCL is needed to render the points of {args.field}")
        width, height = args.size or DEFAULT_VIEW_SIZE
        camera = PinholeCamera(args.view[0], args.view[1], args.distance, args.fov, width, height)
        require_outside(field.points, camera)  # before the mode is chosen (a fit can be slow)
    if suffix not in IMAGE_SUFFIXES:
        if args.sequence == "turntable" and field.sample_kind == "pixels":
            raise RigError(f"{args.field} holds one fixed view: use --sequence environment")
    lighting = PanoramaControls(yaw_deg=args.yaw, exposure=args.exposure, modulation=modulation)
    request = RelightRequest(
        panorama=panorama, camera=camera, lighting=lighting, mode=_mode_request(args)
    )
    prepared = prepare_relighting(field, request)
    for score in prepared.chosen.scores:
        note = f" {score.note}" if score.note else ""
        print(f"  {score.name:<22} {score.error:7.2%}  ({score.seconds:.1f} s){note}")
    if prepared.chosen.reason is not None:
        print(f"relighting mode: {prepared.chosen.reason}")
    for warning in prepared.warnings:
        print(warning)
    if suffix in IMAGE_SUFFIXES:
        image = prepared.engine.render()
        if args.renderer == "pyvista":
            _write_pyvista_picture(args, field, camera, image)
        elif resample_to is not None:
            say_resampled(native, resample_to)
            write_image(args.output, resample(image.rgb, resample_to),
                        resample(image.coverage, resample_to))  # fmt: skip
        else:
            write_image(args.output, image.rgb, image.coverage)
        print(f"{args.field} under {args.env} -> {args.output}")
        for note in relighting_notes(image, uses_models=prepared.chosen.mode.uses_models):
            print(note)
        return 0
    # Frame 0 is the engine as prepared; the frames turn the request's controls or camera.
    frames = relight_prepared_sequence(prepared, kind=args.sequence, frames=args.frames)
    if resample_to is not None:
        say_resampled(native, resample_to)
        frames = [resample(frame, resample_to) for frame in frames]
    write_sequence(args.output, frames, fps=args.fps)
    print(f"{args.frames} frames ({args.sequence}) -> {args.output}")
    return 0


def _mode_request(args: argparse.Namespace) -> Any:
    """The flags of ``rig relight`` that steer the mode, as a ``render.relighting.ModeRequest``."""
    from render.relighting import ModeRequest

    return ModeRequest(
        paper=args.paper, scheme=args.scheme, k=args.k, sampler=args.sampler,
        interpolation=args.interp, view_interpolation=args.view_interp, m=args.m, n=args.n,
        model=args.model, grid=args.grid, method=args.method, fast=args.fast,
        models_path=args.models,
    )  # fmt: skip


def _write_pyvista_picture(args: argparse.Namespace, field: Any, camera: Any, image: Any) -> None:
    import numpy as np

    from core.image_io import write_srgb8
    from core.point_spacing import point_spacing
    from render.tonemap import auto_exposure, tone_mapped_8bit
    from render.viewer import pyvista_picture

    if field.sample_kind != "points" or args.output.suffix.lower() != ".png":
        raise RigError("--renderer pyvista draws the points of a point field into a .png")
    exposure = auto_exposure(image.rgb[image.coverage]) if image.coverage.any() else 1.0
    colours = tone_mapped_8bit(image.radiance, exposure=exposure)
    spacing = point_spacing(field.points)
    write_srgb8(
        args.output,
        pyvista_picture(
            field.points, field.normals, np.ascontiguousarray(colours), camera, spacing
        ),
    )

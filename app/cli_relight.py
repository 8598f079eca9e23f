"""``rig relight``: a field under a panorama (or an RTI capture under any light).

Application layer: maps the flags to a relighting mode (the choice under the panorama for a
field of pixels, :mod:`render.environment_choice`; the models or interpolation for a field of
points, :mod:`render.relight_mode`), prints the guards' warnings and writes the image or the
sequence. ``--lights`` is :func:`app.cli_evaluate.relight_lights`.
"""

from __future__ import annotations

import argparse
import contextlib
from pathlib import Path
from typing import Any

from app.cli_args import (
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
from app.cli_choices import (
    INTERPOLATIONS,
    MODEL_GRID_HEIGHT,
    MODELS,
    PREDICTORS,
    SAMPLERS,
    SCHEMES,
)
from app.cli_evaluate import (
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
                   "capture: under this panorama, light-stage being the classic sum of the "
                   "images weighted by the light of their cells)")  # fmt: skip
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
        with open_field_or_rti(args.field, progress=True, transfer=args.transfer) as field:
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
        args.field, progress=True, transfer=args.transfer, below_horizon=args.below_horizon
    ) as field:
        return _relight_field(args, field, panorama, modulation, suffix)


def _relight_field(
    args: argparse.Namespace, field: Any, panorama: Any, modulation: Any, suffix: str
) -> int:
    from core.camera_model import PinholeCamera
    from core.splat import require_outside
    from processing.panorama import adjust_panorama, visible_environment
    from render.output import IMAGE_SUFFIXES, write_image, write_sequence
    from render.relight_mode import open_relighter
    from render.sequence import relight_sequence

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
    s_count, t_count, _ = field.shape
    for flag, value, have, what in (("-m", args.m, t_count, "lights"),
                                    ("-n", args.n, s_count, "cameras")):  # fmt: skip
        if value is not None and value > have:
            raise InputError(f"{flag} {value}: {args.field} has only {have} measured {what}")
    if suffix not in IMAGE_SUFFIXES:
        if args.sequence == "turntable" and field.sample_kind == "pixels":
            raise RigError(f"{args.field} holds one fixed view: use --sequence environment")
    # The panorama as the object sees it, for the choice and the guards (the engines apply the
    # same yaw, exposure and horizon themselves).
    relit = visible_environment(
        adjust_panorama(panorama, yaw_deg=args.yaw, exposure=args.exposure), field.below_horizon
    )
    mode, models, comparison = _relight_mode(args, field, relit)
    for warning in _relight_warnings(field, camera, relit, mode, models, comparison):
        print(warning)
    relighter = open_relighter(field, mode, models)
    lighting = {"yaw_deg": args.yaw, "exposure": args.exposure, "modulation": modulation}
    if suffix in IMAGE_SUFFIXES:
        relighter.set_lighting(panorama, **lighting)
        relighter.set_view(camera)
        image = relighter.render()
        if args.renderer == "pyvista":
            _write_pyvista_picture(args, field, camera, image)
        elif resample_to is not None:
            say_resampled(native, resample_to)
            write_image(args.output, resample(image.rgb, resample_to),
                        resample(image.coverage, resample_to))  # fmt: skip
        else:
            write_image(args.output, image.rgb, image.coverage)
        _report_relit(args, image.holes, image.outside_fraction, mode.uses_models)
        return 0
    frames = relight_sequence(
        relighter, panorama, camera, kind=args.sequence, frames=args.frames, progress=True,
        **lighting,
    )  # fmt: skip
    if resample_to is not None:
        say_resampled(native, resample_to)
        frames = [resample(frame, resample_to) for frame in frames]
    write_sequence(args.output, frames, fps=args.fps)
    print(f"{args.frames} frames ({args.sequence}) -> {args.output}")
    return 0


def _relight_warnings(
    field: Any, camera: Any, relit: Any, mode: Any, models: Any, comparison: Any
) -> list[Any]:
    """What to expect of this relighting (``render.guards.relight_warnings``).

    The guards see the panorama as relit (yaw and exposure applied). Interpolation modes
    without a fit in hand read the fit saved beside the field, if any: its lobe and
    leave-one-out error inform the ghosting, sun and noise guards. The held-out comparison
    of the default choice, when it was made, decides whether they advise the models.
    """
    from processing.sample_model_store import default_models_path, read_sample_models
    from render.guards import relight_warnings

    saved = default_models_path(field.path)
    if not mode.uses_models and models is None and saved.exists():
        with contextlib.suppress(RigError):
            models = read_sample_models(saved, field)
    return relight_warnings(field, camera, relit.rgb, mode, models, comparison)


def _relight_mode(args: argparse.Namespace, field: Any, relit: Any) -> tuple[Any, Any, Any]:
    """The relighting mode the flags ask for, and what informs it.

    Returns the mode, the field's models when it needs them, and the held-out comparison
    when the mode was chosen by it (else None). ``relit``: the panorama as the object sees it.
    """
    from dataclasses import replace

    from processing.sample_model_store import models_for_field
    from render.model_relight import ModelLightingMode, ModelRelightSettings
    from render.relight_mode import MOST_ACCURATE_MODELS, most_accurate_mode
    from render.relighter import RelightSettings

    k = 64 if args.k is None else args.k
    if args.paper:
        return RelightSettings.paper_configuration(k=k), None, None
    if args.scheme == "model":
        lighting: ModelLightingMode = "grid" if args.k is None else "sampled"
        mode = ModelRelightSettings(
            model=args.model, lighting=lighting, k=k, sampler=args.sampler, grid_height=args.grid
        )
        return mode, models_for_field(field, args.models, progress=True), None
    flags = (args.scheme, args.interp, args.view_interp, args.k, args.m, args.n)
    if args.method != "auto" or (field.sample_kind == "pixels" and all(f is None for f in flags)):
        # A saved fit (--models) serves the choice and the engine instead of a new one.
        saved = None if args.models is None else models_for_field(field, args.models)
        return _pixel_field_mode(args, field, relit, saved), saved, None
    if all(flag is None for flag in flags):
        choice = most_accurate_mode(field, models_path=args.models, progress=True)
        print(f"relighting mode: {choice.reason}")
        if choice.mode == MOST_ACCURATE_MODELS:
            mode = replace(MOST_ACCURATE_MODELS, grid_height=args.grid)
            return mode, choice.models, choice.comparison
        return choice.mode, choice.models, choice.comparison  # they inform the warnings
    settings = RelightSettings(args.scheme or "sampled", k=k, sampler=args.sampler,
                               m=args.m or 3, n=args.n or 3)  # fmt: skip
    if args.interp:
        settings = replace(settings, interpolation=args.interp)
    if args.view_interp:
        settings = replace(settings, view_interpolation=args.view_interp)
    return settings, None, None


def _pixel_field_mode(args: argparse.Namespace, field: Any, relit: Any, models: Any) -> Any:
    """``--method`` (or its automatic choice under the panorama) on a field of pixels."""
    from render.environment_choice import choose_environment_mode, environment_mode

    if field.sample_kind != "pixels":
        raise InputError(
            f"--method relights a field of pixels (an RTI capture); {args.field} is a field of "
            "points: use --scheme (model, or an interpolation scheme)"
        )
    flags = ("--scheme", "--interp", "--view-interp", "-k", "-m", "-n")
    given = [f for f, v in zip(flags, (args.scheme, args.interp, args.view_interp, args.k,
                                       args.m, args.n), strict=True) if v is not None]  # fmt: skip
    if given:
        raise InputError(f"--method {args.method} chooses the relighting; drop {', '.join(given)}")
    if args.method != "auto":
        return environment_mode(args.method, progress=True)
    choice = choose_environment_mode(field, relit, models=models, fast=args.fast, progress=True)
    for score in choice.scores:
        print(f"  {score.name:<22} {score.error:7.2%}  ({score.seconds:.1f} s)")
    print(f"relighting mode: {choice.reason}")
    return choice.mode


def _write_pyvista_picture(args: argparse.Namespace, field: Any, camera: Any, image: Any) -> None:
    import numpy as np

    from core.image_io import write_srgb8
    from core.point_spacing import point_spacing
    from render.tonemap import auto_exposure, display_8bit
    from render.viewer import pyvista_picture

    if field.sample_kind != "points" or args.output.suffix.lower() != ".png":
        raise RigError("--renderer pyvista draws the points of a point field into a .png")
    exposure = auto_exposure(image.rgb[image.coverage]) if image.coverage.any() else 1.0
    colours = display_8bit(image.radiance, exposure=exposure)
    spacing = point_spacing(field.points)
    write_srgb8(
        args.output,
        pyvista_picture(
            field.points, field.normals, np.ascontiguousarray(colours), camera, spacing
        ),
    )


def _report_relit(args: argparse.Namespace, holes: Any, outside: float, models: bool) -> None:
    print(f"{args.field} under {args.env} -> {args.output}")
    if holes.any():
        print(f"warning: {int(holes.sum())} visible samples are seen by no chosen camera (holes)")
    if outside > 0.05 and not models:
        print(
            f"warning: {outside:.0%} of the light comes from outside the measured lights "
            "(below the lowest ring, say); it is moved to the nearest measured lights"
        )
    elif outside > 0.05:
        print(
            f"note: {outside:.0%} of the light comes from outside the measured lights; the "
            "fitted models shade it, its cast shadows are extrapolated from the measured ones"
        )

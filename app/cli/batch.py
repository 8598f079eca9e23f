"""``rig batch``: a relit sequence for each of many panoramas, in-process or on Dask.

Application layer: parses, chooses the mode once (as ``rig relight`` does), makes sure the
models it needs are saved, and calls :func:`render.batch.relight_batch`; the GIFs are written
from the finished store.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from app.cli.args import (
    add_dask_options,
    add_memory_option,
    angles,
    cluster_for,
    count,
    image_size,
    output_directory,
    positive,
)
from app.cli.choices import SEQUENCES
from core.errors import InputError

__all__ = ["add_batch"]

#: The view size of a field of points' frames (``--size``).
BATCH_VIEW_SIZE = (256, 256)


def add_batch(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig batch FIELD --env ... -o OUT.zarr`` on the ``rig`` sub-command parser."""
    p = commands.add_parser(
        "batch",
        help="relight a sequence for each of many panoramas into one Zarr store (--dask)",
        description="Relight a field of points (or pixels) as a sequence (the environment "
        "turning, or a turntable) under each panorama, one task per panorama, in this process "
        "or as Dask tasks (--dask). Frames go into OUT.zarr (frames (E, F, H, W, 3) uint8), "
        "put in place when every task has finished; --gif also writes OUT/<panorama>.gif. The "
        "mode is rig relight's default choice (the models when they predict held-out lights "
        "better), or --paper.",
    )
    p.add_argument("field", type=Path, help="field store")
    p.add_argument("--env", type=Path, action="append", required=True, metavar="PANORAMA",
                   help="a panorama (repeat for each environment)")  # fmt: skip
    p.add_argument("--view", type=angles, help="first view AZ,INCL in degrees (fields of points)")
    p.add_argument("--distance", type=positive, default=4.0, help="camera distance (default 4)")
    p.add_argument("--fov", type=positive, default=40.0, help="field of view, degrees")
    p.add_argument("--size", type=image_size, help="WxH of a field of points' frames (default "
                   "256x256); a field of pixels is relit at its capture's size")  # fmt: skip
    p.add_argument("--sequence", choices=SEQUENCES, default="turntable")
    p.add_argument("--frames", type=count, default=24, help="frames per environment")
    p.add_argument("--paper", action="store_true", help="the paper's configuration")
    p.add_argument("--gif", action="store_true", help="also a GIF per panorama beside the store")
    p.add_argument("--fps", type=positive, default=12.0, help="GIF frame rate")
    p.add_argument("-o", "--output", type=output_directory, required=True, help="OUT.zarr")
    add_memory_option(p)
    add_dask_options(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(handler=_run_batch)


def _run_batch(args: argparse.Namespace) -> int:
    from core.camera_model import PinholeCamera
    from core.field_store import ReflectanceField
    from core.light_set import check_measured_lights
    from processing.panorama import read_panorama
    from processing.sample_model_store import default_models_path, models_for_field
    from render.batch import BatchPlan, read_batch_frames, relight_batch
    from render.output import write_sequence
    from render.relighting import ModeRequest, choose_mode

    if args.output.exists():
        raise InputError(f"{args.output}: exists; choose another path or remove it")
    if args.gif:  # checked before the work, as the store is
        _check_gif_folder(args.output.with_suffix(""), args.env)
    field = ReflectanceField.open(args.field)
    # Refused here as every other opener of a store refuses it (processing.rti's
    # open_field_or_rti): before, --paper relit lights all below a blocking base without a
    # word, and lights of one direction failed naming no file.
    check_measured_lights(
        args.field, field.light_directions, blocked_below=field.below_horizon == "blocked"
    )
    for path in args.env:
        read_panorama(path)  # every panorama readable before any work starts
    if field.sample_kind == "pixels":
        if args.view is not None or args.sequence == "turntable":
            raise InputError(f"{args.field} holds one fixed view: drop --view, use "
                             "--sequence environment")  # fmt: skip
        camera = field.cameras[0]
        assert field.image_shape is not None  # every field of pixels has its image's shape
        height, width = field.image_shape
        if args.size is not None and args.size != (width, height):
            # The frames are made in the batch's tasks at the capture's pixels; resampling
            # them is rig relight's (one sequence), not done here.
            raise InputError(
                f"--size {args.size[0]}x{args.size[1]}: {args.field} is a field of pixels, "
                f"relit at its capture's size ({width}x{height}); drop --size "
                "(rig relight --size resamples a relit image or sequence)"
            )
    else:
        if args.view is None:
            raise InputError(f"--view AZ,INCL is needed to render the points of {args.field}")
        camera = PinholeCamera(args.view[0], args.view[1], args.distance, args.fov,
                               *(args.size or BATCH_VIEW_SIZE))  # fmt: skip
    started = time.perf_counter()
    with cluster_for(args) as client:
        models = None
        if not args.paper:
            # Fitted once here (on the cluster), read by every task.
            models = models_for_field(field, memory_bytes=args.max_memory, client=client)
        # One mode for every environment: chosen on held-out lights, not under one panorama.
        chosen = choose_mode(field, ModeRequest(paper=args.paper), None, models=models)
        if chosen.reason is not None:
            print(f"relighting mode: {chosen.reason}", file=sys.stderr)
        mode = chosen.mode
        models_path = str(default_models_path(field.path)) if mode.uses_models else None
        plan = BatchPlan(
            field=str(field.path), mode=mode, models=models_path,
            panoramas=tuple(str(p) for p in args.env), camera=camera, sequence=args.sequence,
            frames=args.frames,
        )  # fmt: skip
        store = relight_batch(plan, args.output, client=client)
    if args.gif:
        folder = args.output.with_suffix("")
        folder.mkdir(parents=True, exist_ok=True)
        for index, path in enumerate(plan.panoramas):
            write_sequence(folder / _gif_name(index, path),
                           read_batch_frames(store, index), fps=args.fps)  # fmt: skip
    elapsed = time.perf_counter() - started
    print(f"{len(plan.panoramas)} environments x {args.frames} frames ({args.sequence}) in "
          f"{elapsed:.1f} s -> {store}")  # fmt: skip
    return 0


def _gif_name(index: int, panorama: str | Path) -> str:
    """The GIF of environment ``index`` in ``rig batch --gif``'s folder."""
    return f"{index:03d}-{Path(panorama).stem}.gif"


def _check_gif_folder(folder: Path, panoramas: list[Path]) -> None:
    """Refuse a --gif folder that is a file, or GIFs that would replace existing files."""
    if folder.exists() and not folder.is_dir():
        raise InputError(
            f"--gif writes the sequences into {folder}/, which is a file; choose another -o "
            "or move that file"
        )
    for index, panorama in enumerate(panoramas):
        target = folder / _gif_name(index, panorama)
        if target.exists():
            raise InputError(f"{target}: exists (--gif would replace it); remove it or choose "
                             "another -o")  # fmt: skip

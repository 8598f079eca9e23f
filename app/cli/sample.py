"""``rig sample``: importance-sample a panorama into K lights and write their pictures.

Application layer: parses the lighting controls and calls
:func:`render.lighting_outputs.write_lighting_outputs` into a hidden folder beside the output,
whose files are moved in only once all three are written: a full disk (or any failure) leaves
the output as it was, not a new folder holding ``lights.json`` without its pictures.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from app.cli.args import count, finite, output_directory, positive, whole
from app.cli.choices import SAMPLERS
from core.errors import InputError


def add_sample(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``rig sample`` on the ``rig`` sub-command parser."""
    p = commands.add_parser(
        "sample",
        help="importance-sample a panorama and disassemble its light into K lights",
        description="Sample an equirectangular panorama into K light directions, gather all its "
        "light into their spherical Voronoi cells, and write lights.json, overlay.png and "
        "lights.png to the output directory.",
    )
    p.add_argument("panorama", type=Path, help="panorama file (.exr, .hdr, .png, .jpg)")
    p.add_argument("-k", type=count, default=64, help="number of lights (default 64)")
    p.add_argument("--method", choices=SAMPLERS, default="tmed", help="sampler (default tmed)")
    p.add_argument("--seed", type=whole, default=0, help="random seed (default 0)")
    p.add_argument(
        "--exact",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="return exactly K samples (default on)",
    )
    p.add_argument(
        "--paper", action="store_true", help="diffuse plain pixel luminance, as the paper"
    )
    p.add_argument("--modulation", type=Path, help="image multiplying the sampling density")
    p.add_argument("--yaw", type=finite, default=0.0, help="rotate the environment, degrees CCW")
    p.add_argument("--exposure", type=positive, default=1.0, help="radiance scale (default 1)")
    p.add_argument("--resample", action="store_true", help="resize a panorama that is not 2:1")
    p.add_argument("-o", "--output", type=output_directory, required=True, help="output directory")
    p.set_defaults(handler=_run_sample)


def _run_sample(args: argparse.Namespace) -> int:
    from processing.environment import LightingControls, read_modulation_map
    from processing.panorama import read_panorama
    from render.lighting_outputs import write_lighting_outputs

    panorama = read_panorama(args.panorama, resample=args.resample)
    if panorama.note:
        print(panorama.note)
    controls = LightingControls(
        k=args.k,
        method=args.method,
        seed=args.seed,
        exact=args.exact,
        paper=args.paper,
        modulation=None if args.modulation is None else read_modulation_map(args.modulation),
        yaw_deg=args.yaw,
        exposure=args.exposure,
    )
    with _whole_folder(args.output) as folder:
        lighting = write_lighting_outputs(panorama, controls, folder)
    lights = lighting.light_set()
    print(
        f"{lights.k} lights ({controls.method}) from {panorama.source} "
        f"({panorama.width}x{panorama.height}); total light "
        f"{lights.rgb.sum(axis=0).round(4).tolist()} (RGB radiance x sr) -> {args.output}/"
    )
    return 0


@contextmanager
def _whole_folder(output: Path) -> Iterator[Path]:
    """A hidden folder beside ``output`` to write into; its files join ``output`` on success.

    A new ``output`` is the hidden folder renamed; an existing one receives the files one
    rename each (no new bytes: a rename cannot fail for space). On any failure the hidden
    folder, and the parents made for it, are removed; an error naming a file in the hidden
    folder is said of the same file in ``output``.
    """
    made = _missing_parents(output)
    try:
        output.parent.mkdir(parents=True, exist_ok=True)
        partial = Path(tempfile.mkdtemp(prefix=f".{output.name}.", suffix=".partial",
                                        dir=output.parent))  # fmt: skip
    except OSError as error:
        _remove_empty(made)
        raise InputError(f"{output}: cannot create the folder: {error.strerror or error}") from None
    try:
        try:
            yield partial
            _move_in(partial, output)
        except InputError as error:
            raise InputError(str(error).replace(str(partial), str(output))) from None
        except OSError as error:
            raise InputError(f"{output}: cannot write: {error.strerror or error}") from None
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        _remove_empty(made)
        raise


def _move_in(partial: Path, output: Path) -> None:
    """The files of ``partial`` into ``output`` (``partial`` itself when there is none)."""
    if not output.exists():
        os.replace(partial, output)
        return
    for file in sorted(partial.iterdir()):
        os.replace(file, output / file.name)
    partial.rmdir()


def _missing_parents(output: Path) -> list[Path]:
    """The parents of ``output`` that do not exist yet, deepest first."""
    return [parent for parent in output.parents if not parent.exists()]


def _remove_empty(folders: list[Path]) -> None:
    """Remove ``folders`` (deepest first) made for a write that failed, if still empty."""
    for folder in folders:
        try:
            folder.rmdir()
        except OSError:
            return

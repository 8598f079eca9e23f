"""Argument types of the ``rig`` command line: a bad value is refused as it is parsed.

Each is an ``argparse`` ``type=``: argparse turns its :class:`argparse.ArgumentTypeError`
into ``rig CMD: error: argument --NAME: MESSAGE`` and exit status 2, before any work (or
motion) starts. What only the data can tell (``-m`` against the field's lights) is checked
by the command once it has the data.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

from core.atomic import output_problem
from core.errors import InputError
from core.file_kinds import special_file_problem
from core.memory_budget import available_memory, parse_size

__all__ = [
    "DEFAULT_VIEW_SIZE",
    "IMAGE_BYTES_PER_PIXEL",
    "MAX_IMAGE_SIDE",
    "add_camera_options",
    "angles",
    "check_file_arguments",
    "count",
    "dask_spec",
    "finite",
    "image_size",
    "names_among",
    "non_negative",
    "output_directory",
    "output_file",
    "positive",
    "quality",
    "require_output",
    "resampled_size",
    "squares",
    "whole",
]

#: Longest image side accepted (pixels): beyond any camera the rig drives.
MAX_IMAGE_SIDE = 16384

#: Memory a rendered view needs per pixel, bytes: float32 RGB radiance and image, coverage,
#: depth buffer, splat lists (a few entries per pixel) and the tone-mapped copy.
IMAGE_BYTES_PER_PIXEL = 96


def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def finite(text: str) -> float:
    """A finite float (not NaN or infinity)."""
    return _number(text)


def positive(text: str) -> float:
    """A finite float > 0."""
    value = _number(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be positive, got {text!r}")
    return value


def between(low: float, high: float, unit: str = "") -> Callable[[str], float]:
    """A parser of finite floats in [low, high] (hostile numbers refused before any work)."""

    def parse(text: str) -> float:
        value = _number(text)
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(
                f"must be between {low:g} and {high:g}{unit}, got {text!r}"
            )
        return value

    return parse


def non_negative(text: str) -> float:
    """A finite float >= 0."""
    value = _number(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be zero or positive, got {text!r}")
    return value


def count(text: str) -> int:
    """An integer >= 1 (lights, cameras, points, frames)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {text!r}")
    return value


def whole(text: str) -> int:
    """An integer >= 0 (seeds, grid sizes where 0 means none)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be zero or more, got {text!r}")
    return value


def names_among(text: str, allowed: Sequence[str], what: str) -> tuple[str, ...]:
    """A comma-separated list of distinct names among ``allowed`` (the body of a list type)."""
    names = tuple(name.strip() for name in text.split(",") if name.strip())
    unknown = [name for name in names if name not in allowed]
    if unknown or not names or len(set(names)) != len(names):
        problem = f"unknown {what} {', '.join(unknown)}" if unknown else f"{text!r}"
        raise argparse.ArgumentTypeError(
            f"{problem}: give distinct {what}s among {', '.join(allowed)}"
        )
    return names


def quality(text: str) -> int:
    """A JPEG quality: an integer 1..100."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number 1..100, got {text!r}") from None
    if not 1 <= value <= 100:
        raise argparse.ArgumentTypeError(f"JPEG quality must be 1..100, got {text!r}")
    return value


def angles(text: str) -> tuple[float, float]:
    """``AZ,INCL`` in degrees, both finite."""
    parts = text.split(",")
    try:
        if len(parts) != 2:
            raise argparse.ArgumentTypeError("")
        azimuth, inclination = (_number(part) for part in parts)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"expected AZ,INCL in degrees (two finite numbers), got {text!r}"
        ) from None
    return azimuth, inclination


def image_size(text: str) -> tuple[int, int]:
    """``WIDTHxHEIGHT`` (or ``N`` for N x N) in pixels, that this machine can hold.

    Refused before anything is allocated: a side of 0 or above :data:`MAX_IMAGE_SIDE`, or
    a view whose buffers (:data:`IMAGE_BYTES_PER_PIXEL` per pixel) exceed the memory free.
    """
    parts = text.lower().split("x")
    try:
        width, height = (int(v) for v in (parts * 2 if len(parts) == 1 else parts))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected WIDTHxHEIGHT (e.g. 512x512), got {text!r}"
        ) from None
    if min(width, height) < 1:
        raise argparse.ArgumentTypeError(f"image sides must be at least 1 pixel, got {text!r}")
    if max(width, height) > MAX_IMAGE_SIDE:
        raise argparse.ArgumentTypeError(f"{text}: image sides are at most {MAX_IMAGE_SIDE} pixels")
    need = width * height * IMAGE_BYTES_PER_PIXEL
    free = available_memory()
    if need > free:
        raise argparse.ArgumentTypeError(
            f"{text}: a view this size needs about {need / 2**30:.1f} GiB, this machine has "
            f"{free / 2**30:.1f} GiB free; choose a smaller size"
        )
    return width, height


def require_output(path: Path, *, directory: bool = False) -> Path:
    """``path`` if it can be written (see :func:`core.atomic.output_problem`), else InputError.

    For outputs whose kind (file or folder) only the other arguments tell.
    """
    problem = output_problem(path, directory=directory)
    if problem is not None:
        raise InputError(problem)
    return path


def check_file_arguments(args: argparse.Namespace) -> None:
    """Refuse every argument that names a FIFO, a device or a socket, before any is opened.

    The one check where the command line reads its files: ``--config`` naming a FIFO blocked
    forever in ``open``, ``/dev/zero`` never ends, and an output there would be replaced by a
    file. Paths (and lists of them) and strings naming such a file are checked; a path that
    does not exist is left to the command, whose message says what it wanted.

    Raises
    ------
    InputError
        Naming the argument's path and what it is (:func:`core.file_kinds.special_file_problem`).
    """
    for value in vars(args).values():
        for item in value if isinstance(value, list | tuple) else (value,):
            if isinstance(item, Path | str) and item != "":
                problem = special_file_problem(item)
                if problem is not None:
                    raise InputError(problem)


def output_file(text: str) -> Path:
    """A file path that can be written: not a folder, no file where a parent folder must be."""
    problem = output_problem(text)
    if problem is not None:
        raise argparse.ArgumentTypeError(problem)
    return Path(text)


def output_directory(text: str) -> Path:
    """A folder path that can be written into: not a file, no file where a parent must be."""
    problem = output_problem(text, directory=True)
    if problem is not None:
        raise argparse.ArgumentTypeError(problem)
    return Path(text)


def squares(text: str) -> tuple[int, int]:
    """``XxY``: a ChArUco board's squares, at least 2 x 2."""
    parts = text.lower().split("x")
    try:
        x, y = (int(v) for v in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected squares XxY (e.g. 5x5), got {text!r}") from None
    if min(x, y) < 2:
        raise argparse.ArgumentTypeError(f"a ChArUco board needs 2x2 squares or more, got {text!r}")
    return x, y


def memory_size(text: str) -> int:
    """A ``--max-memory`` value (``512M``, ``2G``) in bytes; argparse refuses what is not."""
    try:
        return parse_size(text)
    except InputError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def add_memory_option(p: argparse.ArgumentParser) -> None:
    """``--max-memory``: how much radiance a stage holds at once."""
    p.add_argument(
        "--max-memory",
        type=memory_size,
        metavar="SIZE",
        help="radiance held in memory at once, per process (e.g. 2G; default: a quarter of "
        "the memory available, at most 4 GiB); the peak is about twice this plus the outputs",
    )


def dask_spec(text: str) -> str:
    """``--dask``: ``local`` or a scheduler address (:func:`core.cluster.check_dask_spec`)."""
    from core.cluster import check_dask_spec

    try:
        return check_dask_spec(text)
    except InputError as error:
        # argparse says "argument --dask:" already.
        raise argparse.ArgumentTypeError(str(error).removeprefix("--dask ")) from None


def add_dask_options(p: argparse.ArgumentParser) -> None:
    """``--dask`` and the local cluster's size: where a stage runs (:func:`cluster_for`)."""
    p.add_argument(
        "--dask",
        type=dask_spec,
        metavar="local|tcp://HOST:PORT",
        help="run the work as Dask tasks: 'local' starts a cluster of one worker per core on "
        "this machine, an address uses a running scheduler (docs/scale.md); the results are "
        "the same as without it",
    )
    p.add_argument(
        "--workers",
        type=count,
        help="--dask local: worker processes (default: one per core)",
    )
    p.add_argument(
        "--worker-memory",
        type=memory_size,
        metavar="SIZE",
        help="--dask local: memory limit of each worker (default: the available memory shared "
        "among them); Dask restarts a worker that goes over it and retries its task",
    )


def cluster_for(args: argparse.Namespace) -> AbstractContextManager[Any]:
    """The Dask client ``--dask`` asks for (None without it), as a context manager."""
    from core.cluster import dask_client

    if args.dask != "local" and (args.workers or args.worker_memory):
        raise InputError("--workers and --worker-memory size a local cluster: add --dask local")
    return dask_client(args.dask, workers=args.workers, memory_limit=args.worker_memory)


#: The view size of the commands that render one (``--size``).
DEFAULT_VIEW_SIZE = (512, 512)


def add_camera_options(p: argparse.ArgumentParser, *, size_help: str | None = None) -> None:
    """Camera flags shared by every command that renders a view (same defaults everywhere).

    ``size_help``: ``--size`` has no default (None) and this help, for a command that also
    renders what has a size of its own (a field of pixels) and must tell a size asked for
    from none; it takes :data:`DEFAULT_VIEW_SIZE` otherwise.
    """
    p.add_argument("--distance", type=positive, default=4.0, help="camera distance (default 4)")
    p.add_argument("--fov", type=positive, default=40.0, help="horizontal field of view, degrees")
    if size_help is not None:
        p.add_argument("--size", type=image_size, help=size_help)
        return
    p.add_argument(
        "--size", type=image_size, default=DEFAULT_VIEW_SIZE, help="image WIDTHxHEIGHT (512x512)"
    )


def resampled_size(
    requested: tuple[int, int] | None, native: tuple[int, int], what: str
) -> tuple[int, int] | None:
    """The ``--size`` (width, height) an image of ``native`` (width, height) is resampled to.

    None when no size was asked for or it is the native one. A size of other proportions
    is refused (InputError naming the ones that keep them, to within a pixel): stretching
    the picture is never what was meant. ``what`` names the image in the message.
    """
    if requested is None or requested == native:
        return None
    width, height = requested
    own_width, own_height = native
    # Off by at most one pixel on either side: the rounding of a scaled size.
    if abs(width * own_height - height * own_width) > max(own_width, own_height):
        keep_width = f"{width}x{max(1, round(width * own_height / own_width))}"
        keep_height = f"{max(1, round(height * own_width / own_height))}x{height}"
        raise InputError(
            f"--size {width}x{height}: {what} is {own_width}x{own_height}, of other "
            f"proportions; give a size that keeps them ({keep_width} or {keep_height}), or "
            "drop --size for its own"
        )
    return width, height

"""``rig export-web``'s library function: a pixel field's models for the web RTI viewers.

One pass over the view, a band of pixels at a time (:data:`CHUNK_BYTES` of radiance, aligned
to the store's chunks): each band's 8-bit values are fitted by every basis model (their
planes go to temporary files, :mod:`render.web_export.planes`), give their normals
(photometric stereo, when the field has none), and give the values of the pixels the neural
model is fitted on and the errors are measured on. Then each model is quantised and written
(:mod:`render.web_export.basis`, :mod:`render.web_export.neural`; an encoder, when the neural
model has one, codes every pixel in a second pass), and the normal maps. Memory holds a band,
an image of planes, the normals, and the neural model's sample: not the view's radiance.
"""

from __future__ import annotations

import contextlib
import math
import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from core.atomic import output_problem
from core.camera_model import rig_to_camera
from core.errors import InputError
from core.field_store import ReflectanceField
from core.image_io import write_exr, write_png16
from processing.image_quality import display_scale
from processing.neural_rti_fit import NeuralSettings
from processing.sample_models import photometric_stereo
from render.web_export.basis import basis_planes, terms, write_basis
from render.web_export.levels import eight_bit
from render.web_export.names import (
    ERROR_SAMPLES,
    NEURAL_SECONDS,
    PLANE_FORMATS,
    TILE_OVERLAP,
    TILE_SIZE,
    TILE_THRESHOLD,
    WEB_MODELS,
    BasisModel,
    PlaneFormat,
    WebModel,
)
from render.web_export.neural import FREE_CODE_PIXELS, NEURAL_SAMPLES, Training, write_neural
from render.web_export.planes import PlaneStore
from render.web_export.result import Probe, WebExport, WebModelExport
from render.web_export.tiles import Layout, automatic_tile_size

__all__ = ["CHUNK_BYTES", "WebExport", "WebModelExport", "export_web"]

#: Radiance read per band (bytes of float32): large views are fitted a band at a time.
CHUNK_BYTES = 1 << 26
#: Radiance values (at most) a simulated field's display scale is taken from.
WHITE_VALUES = 1 << 24


def export_web(
    field: ReflectanceField,
    output: str | os.PathLike[str],
    *,
    camera: int = 0,
    models: tuple[WebModel, ...] = ("ptm", "hsh3"),
    image_format: PlaneFormat = "jpg",
    quality: int = 95,
    tiles: bool | None = None,
    tile_size: int | None = None,
    overlap: int = TILE_OVERLAP,
    scale: float | None = None,
    neural: NeuralSettings | None = None,
    progress: Callable[[str], None] | None = None,
) -> WebExport:
    """Write a pixel field's models, and its normal map, for the web RTI viewers.

    Parameters
    ----------
    field : ReflectanceField of pixels (one view: an RTI capture)
    output : folder to write (created); ``<model>/`` per model, ``normals.png``,
        ``normals.exr``
    camera : int, the view (a pixel field has one, 0)
    models : tuple of {"ptm", "hsh2", "hsh3", "neural"}
    image_format : {"jpg", "png"}
        The planes' files. OpenLIME's single-image layout asks for ``plane_N.jpg`` whatever
        ``info.json`` says; PNG (lossless) planes load only as deep-zoom tiles, whose ``.dzi``
        names the format: with ``tiles`` None, PNG planes are tiled (and a note says so).
    quality : int, 1..100, JPEG quality (colour kept at full resolution, 4:4:4)
    tiles : bool or None, deep-zoom tiles (None: when a side exceeds :data:`TILE_THRESHOLD`,
        or for PNG planes). False with PNG writes single PNG images, which OpenLIME cannot
        load (a note says so; the command refuses it): for viewers that read them directly
    tile_size : int or None, deep-zoom tile side (pixels); None: chosen
        (:func:`render.web_export.tiles.automatic_tile_size`, said in a note when it is not
        :data:`TILE_SIZE`)
    overlap : int, deep-zoom tile overlap (pixels)
    scale : float > 0 or None
        The radiance written as 8-bit white is 1 / ``scale``. None: 1 for an RTI import (its
        images' own 8-bit values), else the field's display scale (its 99.5th percentile is
        white), as ``rig relight --lights`` shows it.
    neural : NeuralSettings or None, the neural model's fit (None: the defaults, a budget of
        :data:`NEURAL_SECONDS` s)
    progress : callable(message), optional, told each stage

    Returns
    -------
    WebExport

    Raises
    ------
    InputError
        A field of points, a camera index out of range, an unknown model or format, a
        quality, tile size or overlap out of range, too few lights for a model, an image too
        small to tile, an output that cannot be written.
    """
    height, width = _check(field, output, camera, models, image_format, quality, scale)
    say = progress or (lambda _message: None)
    layout, notes = _layout(width, height, image_format, quality, tiles, tile_size, overlap)
    visible = np.asarray(field.visibility[camera], dtype=bool)
    white = _white_scale(field, camera, visible) if scale is None else float(scale)
    lights = rig_to_camera(field.light_directions, field.cameras[camera])
    bases: list[BasisModel] = [m for m in models if m != "neural"]
    seen = np.flatnonzero(visible)
    rng = np.random.default_rng(0)
    probe_pixels = _pick(seen, ERROR_SAMPLES, rng)
    training: Training | None = None
    train_pixels = np.zeros(0, np.int64)
    if "neural" in models:
        encoder = len(seen) > FREE_CODE_PIXELS
        train_pixels = _pick(seen, NEURAL_SAMPLES, rng) if encoder else seen
    folder = Path(output)
    folder.mkdir(parents=True, exist_ok=True)
    t_count = field.shape[1]
    probe_levels = np.zeros((t_count, len(probe_pixels), 3), np.uint8)
    train_levels = np.zeros((t_count, len(train_pixels), 3), np.uint8)
    normals = _field_normals(field, camera)
    with contextlib.ExitStack() as stack:
        stores = {m: stack.enter_context(PlaneStore(folder, terms(m), visible.size)) for m in bases}
        # Photometric stereo's normals, when the field has none: a band at a time, too.
        stereo = (
            None
            if normals is not None
            else stack.enter_context(PlaneStore(folder, 1, visible.size))
        )
        say(
            f"reading {width}x{height} pixels under {t_count} lights"
            + (f", fitting {', '.join(m.upper() for m in bases)}" if bases else "")
        )
        began = time.perf_counter()
        for start, values in _bands(field, camera, say):
            stop = start + values.shape[1]
            levels = eight_bit(values, white)  # what the RTI tools fit, encoded once
            for basis in bases:
                planes = basis_planes(basis, levels, lights, visible[start:stop])
                stores[basis].write(start, planes)
            if stereo is not None:
                band_normals = photometric_stereo(values, lights, np.array([0.0, 0.0, 1.0]))
                stereo.write(start, band_normals[:, None])
            _gather(probe_levels, probe_pixels, levels, start, stop)
            _gather(train_levels, train_pixels, levels, start, stop)
        basis_seconds = time.perf_counter() - began
        probe = Probe(probe_pixels, probe_levels)
        written: list[WebModelExport] = []
        for model in models:
            if model == "neural":
                training = Training(train_pixels, train_levels, len(seen) > FREE_CODE_PIXELS)
                settings = neural or NeuralSettings(max_seconds=NEURAL_SECONDS)
                written.append(
                    write_neural(
                        folder / "neural",
                        training,
                        lambda: _level_bands(field, camera, white),
                        visible,
                        lights,
                        layout,
                        probe,
                        settings,
                        say,
                    )
                )
            else:
                say(f"writing {model.upper()} planes")
                written.append(
                    write_basis(
                        folder / model, model, stores[model], lights, layout, probe, basis_seconds
                    )
                )
                stores[model].close()  # its temporary file: no longer needed
        if stereo is not None:
            normals = stereo.image(0)
            stereo.close()
        assert normals is not None
        png, exr = _write_normals(folder, normals, visible, (height, width))
    return WebExport(
        folder,
        camera,
        width,
        height,
        white,
        tuple(written),
        png,
        exr,
        tile_size=layout.tile_size if layout.tiled else 0,
        notes=tuple(notes),
    )


def _check(
    field: ReflectanceField,
    output: str | os.PathLike[str],
    camera: int,
    models: tuple[WebModel, ...],
    image_format: str,
    quality: int,
    scale: float | None,
) -> tuple[int, int]:
    """The image's (height, width), once the request is checked."""
    if field.image_shape is None:
        raise InputError(
            f"{field.path}: a field of points (sample kind {field.sample_kind!r}); the RTI web "
            "format holds one view's pixels: export a field of pixels (an RTI capture)"
        )
    cameras = field.shape[0]
    if not 0 <= camera < cameras:
        raise InputError(f"camera index {camera} outside 0..{cameras - 1} of {field.path}")
    unknown = [m for m in models if m not in WEB_MODELS]
    if unknown or not models or len(set(models)) != len(models):
        raise InputError(
            f"models {', '.join(map(str, models)) or '(none)'}: give distinct models among "
            f"{', '.join(WEB_MODELS)}"
        )
    lights = field.shape[1]
    for model in models:
        needed = 3 if model == "neural" else terms(model) + 1
        if lights < needed:
            what = "the neural model" if model == "neural" else f"model {model!r}"
            has = "" if model == "neural" else f" has {terms(model)} terms;"
            raise InputError(
                f"{field.path}: {what}{has} needs {needed} lights or more, the field has {lights}"
            )
    if image_format not in PLANE_FORMATS:
        raise InputError(f"plane format {image_format!r}: use one of {', '.join(PLANE_FORMATS)}")
    if not 1 <= quality <= 100:
        raise InputError(f"JPEG quality {quality} outside 1..100")
    if scale is not None and not (math.isfinite(scale) and scale > 0):
        raise InputError(f"scale {scale} must be a positive number")
    problem = output_problem(output, directory=True)
    if problem is not None:
        raise InputError(problem)
    return field.image_shape


def _layout(
    width: int,
    height: int,
    image_format: PlaneFormat,
    quality: int,
    tiles: bool | None,
    tile_size: int | None,
    overlap: int,
) -> tuple[Layout, list[str]]:
    """How the planes are written, and the notes on what was chosen."""
    notes: list[str] = []
    longest = max(width, height)
    if tiles is None:
        tiled = longest > TILE_THRESHOLD or image_format == "png"
        if image_format == "png" and longest <= TILE_THRESHOLD:
            notes.append(
                "PNG planes written as deep-zoom tiles: OpenLIME's single-image layout asks "
                "for plane_N.jpg whatever info.json says; open them with layout 'deepzoom'"
            )
    else:
        tiled = tiles
        if not tiled and image_format == "png":
            notes.append(
                "single PNG planes: OpenLIME's image layout asks for plane_N.jpg, so it "
                "cannot load them (tile them, or write JPEG, for OpenLIME)"
            )
    if not tiled:
        return Layout(width, height, image_format, quality, False, 0, 0), notes
    if overlap < 0:
        raise InputError(f"tile overlap {overlap} must be 0 or more")
    if tile_size is None:
        side = automatic_tile_size(width, height, overlap)
        if side != TILE_SIZE:
            notes.append(
                f"deep-zoom tiles of {side} pixels: the image's longest side ({longest} "
                f"pixels) is not longer than the default tile of {TILE_SIZE}"
            )
    else:
        side = tile_size
        if side < 1:
            raise InputError(f"tile size {side} must be at least 1 pixel")
        if side >= longest:
            raise InputError(
                f"tile size {side} must be smaller than the image's longest side ({longest} "
                f"pixels) for deep-zoom tiles: leave the tile size out to have one chosen "
                f"({automatic_tile_size(width, height, overlap)} here)"
            )
    if overlap >= side:
        raise InputError(f"tile overlap {overlap} must be in 0..{side - 1} (tile size)")
    return Layout(width, height, image_format, quality, True, side, overlap), notes


def _pick(pixels: NDArray[np.int64], count: int, rng: np.random.Generator) -> NDArray[np.int64]:
    """At most ``count`` of ``pixels`` (sorted), at random; all of them when there are fewer."""
    if len(pixels) <= count:
        return pixels.astype(np.int64)
    return np.sort(rng.choice(pixels, count, replace=False)).astype(np.int64)


def _gather(
    into: NDArray[np.uint8],
    pixels: NDArray[np.int64],
    levels: NDArray[np.uint8],
    start: int,
    stop: int,
) -> None:
    """Copy the band's values (T, n, 3) of the sorted ``pixels`` in it into ``into`` (T, K, 3)."""
    lo, hi = np.searchsorted(pixels, [start, stop])
    if hi > lo:
        into[:, lo:hi] = levels[:, pixels[lo:hi] - start]


def _band_size(field: ReflectanceField, camera: int) -> int:
    """Pixels per band: :data:`CHUNK_BYTES` of float32 radiance, whole stored chunks."""
    _, t_count, p_count = field.shape
    step = max(1, CHUNK_BYTES // (t_count * 12))
    chunk = field.sample_chunk
    if chunk < p_count and step >= chunk:
        step -= step % chunk  # a band never reads a chunk twice
    return min(step, p_count)


def _bands(
    field: ReflectanceField, camera: int, say: Callable[[str], None] | None = None
) -> Iterator[tuple[int, NDArray[np.float32]]]:
    """(first pixel, radiance (T, n, 3) float32) of each band of the view, in order."""
    p_count = field.shape[2]
    step = _band_size(field, camera)
    count = -(-p_count // step)
    for index, start in enumerate(range(0, p_count, step)):
        if say is not None and count > 1 and index % max(1, count // 10) == 0:
            say(f"band {index + 1} of {count}")
        band = slice(start, min(start + step, p_count))
        yield start, np.asarray(field.camera_radiance(camera, band), dtype=np.float32)


def _level_bands(
    field: ReflectanceField, camera: int, white: float
) -> Iterator[tuple[int, NDArray[np.uint8]]]:
    """(first pixel, 8-bit values (T, n, 3)) of each band: the neural encoder's pass."""
    for start, values in _bands(field, camera):
        yield start, eight_bit(values, white)


def _white_scale(field: ReflectanceField, camera: int, visible: NDArray[np.bool_]) -> float:
    """1 for an RTI import (its 8-bit values), else the display scale of the visible pixels.

    Taken from every visible pixel of a small view, and from evenly spaced ones (up to
    :data:`WHITE_VALUES` values) of a large one, read a band at a time.
    """
    if field.provenance.get("source") == "rti":
        return 1.0
    seen = np.flatnonzero(visible)
    cap = max(1, WHITE_VALUES // (3 * field.shape[1]))
    picked = seen[:: max(1, -(-len(seen) // cap))]
    parts = []
    for start, values in _bands(field, camera):
        lo, hi = np.searchsorted(picked, [start, start + values.shape[1]])
        parts.append(values[:, picked[lo:hi] - start])
    return display_scale(np.concatenate(parts, axis=1)) if parts else 1.0


def _field_normals(field: ReflectanceField, camera: int) -> NDArray[np.float32] | None:
    """The field's own normals (P, 3) in the camera frame, or None (photometric stereo)."""
    if field.normals is None:
        return None
    turned = rig_to_camera(np.asarray(field.normals, dtype=np.float64), field.cameras[camera])
    return np.asarray(turned, dtype=np.float32)


def _write_normals(
    folder: Path,
    normals: NDArray[np.floating],
    visible: NDArray[np.bool_],
    shape: tuple[int, int],
) -> tuple[Path, Path]:
    """``normals.png`` (16-bit, (n + 1) / 2) and ``normals.exr`` (float, alpha = visible)."""
    n = np.asarray(normals, dtype=np.float32).copy()
    n[~visible] = (0.0, 0.0, 1.0)
    image = n.reshape(*shape, 3)
    png, exr = folder / "normals.png", folder / "normals.exr"
    encoded = np.empty(image.shape, np.uint16)
    for row in range(0, shape[0], 256):  # float temporaries of 256 rows, not of the image
        rows = image[row : row + 256]
        encoded[row : row + 256] = np.clip(np.rint((rows * 0.5 + 0.5) * 65535.0), 0, 65535)
    write_png16(png, encoded)
    del encoded
    write_exr(exr, image, alpha=visible.reshape(shape).astype(np.float32))
    return png, exr

"""A pixel field's linear light models in the RTI web format (Relight and OpenLIME).

``rig export-web`` writes what the web RTI viewers load: per model a folder with ``info.json``
and the quantised coefficient planes, and beside them the field's normal map. Format facts, as
the tools' sources define them (cnr-isti-vclab/relight ``src/cli/rtibuilder.cpp``
``RtiBuilder::saveJSON``, ``save``, ``processLine``, ``finalizeMaterial``; ``src/material.h``
``Material::Plane::quantize``; ``src/deepzoom.cpp``; cnr-isti-vclab/openlime
``src/ShaderRTI.js`` (``init``, ``RGB.render``, ``PTM``/``HSH.lightWeights``),
``src/LayerRTI.js`` (``loadJson``) and ``src/LayoutTiles.js`` (``initDeepzoom``,
``initBoxes``, ``tileCoords``)):

- ``info.json``: ``width``, ``height``, ``format`` (the planes' suffix, ``"jpg"`` or
  ``"png"``), ``type`` (``"ptm"``, ``"hsh"``; ``"rbf"``, ``"bilinear"`` not written here),
  ``colorspace`` (``"rgb"`` here: every coefficient of every colour channel), ``lights`` (the
  measured directions, x y z flattened, in the camera frame), ``nplanes`` (3 per basis term:
  18 for the 6-term PTM, 12 and 27 for HSH of order 2 and 3), ``quality`` and ``materials``:
  one entry with ``scale`` and ``bias``, one number per plane. The viewer copies every key onto
  its shader object, so no other key is written.
- Plane p is colour channel ``p % 3`` of basis term ``p // 3``; ``plane_j.jpg`` (or ``.png``)
  holds planes 3j, 3j + 1, 3j + 2 as its R, G and B.
- Dequantisation (ShaderRTI's GLSL): ``value = (byte / 255 - bias[p]) * scale[p]``; the
  rendered colour is ``sum_j base_j(light) value[3j + c]`` for channel c, displayed as it is:
  8-bit sRGB values over 255. Relight quantises a coefficient ``a`` (of values 0..1) as
  ``255 (a / scale + bias)`` truncated, with ``scale = max - min`` and
  ``bias = -min / (max - min)`` per plane; here the range is each plane's minimum and maximum
  (no pixel clipped) and the byte is rounded, so a coefficient errs by half a step at most.
- The bases, of the light ``(x, y, z)`` in the camera frame of ``.lp`` files (x right, y up,
  z toward the camera; :mod:`processing.rti`): PTM ``1, x, y, x^2, x y, y^2`` (the project's
  order is ``x^2, y^2, x y, x, y, 1``); HSH with ``phi = atan2(y, x)``, ``theta = acos(z)``
  and terms 0..8 the project's hemispherical harmonics reordered and with the
  Condon-Shortley sign dropped (:data:`VIEWER_TERMS`). The viewer's HSH differs from the
  exact basis in two details: it holds theta at ``pi/2 - 0.15`` (lights below 8.6 degrees of
  elevation render as at 8.6 degrees) and takes pi as 3.1415 (the terms' scale errs by
  1.5e-5 relative, and phi by 1.9e-4 rad where y < 0).
- Deep zoom (OpenLIME layout ``"deepzoom"``): ``plane_j.dzi`` (``Image`` with ``Format``,
  ``Overlap``, ``TileSize``, and ``Size`` with ``Width`` and ``Height``) and tiles
  ``plane_j_files/LEVEL/COL_ROW.FORMAT``. Level 0 is the coarsest, a single tile: there are
  ``ceil(log2(max(W, H) / TileSize)) + 1`` levels and level L is the image halved
  ``levels - 1 - L`` times (sizes floored, 2 x 2 means). Tile (c, r) spans pixels
  ``max(0, c T - overlap) .. min(W_L, (c + 1) T + overlap)`` (and so in y).

The coefficients are the ``-8bit`` fit of :mod:`render.light_prediction` (the RTI tools'
fit, to the images' 8-bit sRGB values) of the camera's view: the exported model renders what
``make_predictor(field, "ptm-8bit")`` predicts (before that predictor's bound), up to the
quantisation and, in JPEG, the compression (measured: ``docs/web-export.md``).

RBF (Relight's ``rbf`` type: a PCA basis of the measured images stored in ``info.json`` as
8-bit integers, per-pixel projections as planes, ``mrgb`` colour) is not written: its error
is that of the PCA truncation, not of a quantisation, and it interpolates 8-bit sRGB values
where the project's ``rbf`` interpolates linear radiance.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, get_args

import numpy as np
from numpy.typing import NDArray

from core.atomic import atomic_path, output_problem, write_json_atomic
from core.camera_model import rig_to_camera
from core.errors import InputError
from core.field_store import ReflectanceField
from core.image_io import read_pixels, write_exr, write_png16, write_uint8
from processing.image_quality import display_scale
from processing.sample_models import evaluate_basis, photometric_stereo
from processing.sample_models.bases import fit_basis
from render.light_prediction import eight_bit_levels

__all__ = [
    "ERROR_SAMPLES",
    "PLANE_FORMATS",
    "TILE_OVERLAP",
    "TILE_SIZE",
    "TILE_THRESHOLD",
    "VIEWER_TERMS",
    "WEB_MODELS",
    "PlaneFormat",
    "WebExport",
    "WebModel",
    "WebModelExport",
    "deepzoom_levels",
    "export_web",
    "viewer_coefficients",
]

#: The models written: the project's bases (``rig export-web --models``).
WebModel = Literal["ptm", "hsh2", "hsh3"]
WEB_MODELS: tuple[WebModel, ...] = get_args(WebModel)
#: The planes' image format.
PlaneFormat = Literal["jpg", "png"]
PLANE_FORMATS: tuple[PlaneFormat, ...] = get_args(PlaneFormat)

#: Images with a side longer than this (pixels) are tiled unless told otherwise.
TILE_THRESHOLD = 2048
#: Deep-zoom tile side (pixels); with the overlap an inner tile is 256 pixels wide.
TILE_SIZE = 254
#: Pixels each tile repeats of its neighbours (hides the seams of bilinear filtering).
TILE_OVERLAP = 1
#: Visible pixels (at most) the reported error is measured on.
ERROR_SAMPLES = 4096
#: Radiance read per step (bytes): large views are fitted a band of pixels at a time.
CHUNK_BYTES = 1 << 26
#: Smallest plane range written: a constant plane still has a finite bias.
MIN_SPAN = 1e-6

#: The viewer's term i is ``sign`` times the project's term ``index`` (``(index, sign)``):
#: PTM reordered; HSH reordered and with the Condon-Shortley phase (-1)^m dropped.
VIEWER_TERMS: dict[WebModel, tuple[tuple[int, float], ...]] = {
    "ptm": ((5, 1.0), (3, 1.0), (4, 1.0), (0, 1.0), (2, 1.0), (1, 1.0)),
    "hsh2": ((0, 1.0), (3, -1.0), (2, 1.0), (1, -1.0)),
    "hsh3": (
        (0, 1.0), (3, -1.0), (2, 1.0), (1, -1.0), (8, -1.0), (7, -1.0), (6, 1.0), (5, -1.0),
        (4, -1.0),
    ),
}  # fmt: skip
#: ``type`` of ``info.json`` per model.
_INFO_TYPE: dict[WebModel, str] = {"ptm": "ptm", "hsh2": "hsh", "hsh3": "hsh"}


@dataclass(frozen=True)
class WebModelExport:
    """One model as written.

    Attributes
    ----------
    model : WebModel
    folder : Path holding ``info.json`` and the planes
    planes : int, coefficient planes (``nplanes``; three per image)
    files : tuple of Path, the planes' images (``plane_j.jpg``) or, tiled, their ``.dzi``
    levels : int, deep-zoom levels (0: not tiled)
    rms_error, max_error : float
        The written planes, read back and decoded as the viewer decodes them, against the
        fitted coefficients: rendered under the field's measured lights on up to
        :data:`ERROR_SAMPLES` visible pixels, in 8-bit levels (quantisation, and JPEG loss).
    """

    model: WebModel
    folder: Path
    planes: int
    files: tuple[Path, ...]
    levels: int
    rms_error: float
    max_error: float


@dataclass(frozen=True)
class WebExport:
    """What :func:`export_web` wrote.

    Attributes
    ----------
    output : Path, the export's folder
    camera : int, the view exported
    width, height : int, the image size (pixels)
    scale : float, the radiance written as 8-bit white is 1 / ``scale``
    models : tuple of WebModelExport, one folder per model (``output/<model>``)
    normals_png : Path, 16-bit normal map, ``round((n + 1) / 2 * 65535)``
    normals_exr : Path, float32 normals (RGB) and the visible pixels (A)
    """

    output: Path
    camera: int
    width: int
    height: int
    scale: float
    models: tuple[WebModelExport, ...]
    normals_png: Path
    normals_exr: Path


def viewer_coefficients(model: WebModel, coefficients: NDArray[np.floating]) -> NDArray[np.float64]:
    """The project's basis coefficients in the viewer's order and signs.

    Parameters
    ----------
    model : {"ptm", "hsh2", "hsh3"}
    coefficients : ndarray, shape (..., B, 3), of :func:`processing.sample_models.evaluate_basis`

    Returns
    -------
    ndarray, shape (..., B, 3), float64: term i is the viewer's term i (:data:`VIEWER_TERMS`)
    """
    order, signs = _viewer_order(model)
    return np.asarray(coefficients, dtype=np.float64)[..., order, :] * signs[:, None]


def _viewer_order(model: WebModel) -> tuple[list[int], NDArray[np.float64]]:
    """The project's term of each viewer term, and its sign (:data:`VIEWER_TERMS`)."""
    return [index for index, _ in VIEWER_TERMS[model]], np.array(
        [sign for _, sign in VIEWER_TERMS[model]]
    )


def deepzoom_levels(width: int, height: int, tile_size: int) -> int:
    """Deep-zoom levels as OpenLIME counts them: ``ceil(log2(max(W, H) / T)) + 1``.

    The smallest n with ``max(W, H) <= T 2^(n - 1)`` (exact in integers).
    """
    levels = 1
    while max(width, height) > tile_size << (levels - 1):
        levels += 1
    return levels


def export_web(
    field: ReflectanceField,
    output: str | os.PathLike[str],
    *,
    camera: int = 0,
    models: tuple[WebModel, ...] = ("ptm", "hsh3"),
    image_format: PlaneFormat = "jpg",
    quality: int = 95,
    tiles: bool | None = None,
    tile_size: int = TILE_SIZE,
    overlap: int = TILE_OVERLAP,
    scale: float | None = None,
) -> WebExport:
    """Write a pixel field's PTM and HSH fits, and its normal map, for the RTI web viewers.

    Parameters
    ----------
    field : ReflectanceField of pixels (one view: an RTI capture)
    output : folder to write (created); ``<model>/`` per model, ``normals.png``,
        ``normals.exr``
    camera : int, the view (a pixel field has one, 0)
    models : tuple of {"ptm", "hsh2", "hsh3"}
    image_format : {"jpg", "png"}
        The planes' files. OpenLIME's single-image layout asks for ``plane_j.jpg``; PNG
        (lossless) planes load through the deep-zoom layout (the ``.dzi`` names the format).
    quality : int, 1..100, JPEG quality (colour kept at full resolution, 4:4:4)
    tiles : bool or None, deep-zoom tiles (None: when a side exceeds :data:`TILE_THRESHOLD`)
    tile_size, overlap : int, deep-zoom tile side and overlap (pixels)
    scale : float > 0 or None
        The radiance written as 8-bit white is 1 / ``scale``. None: 1 for an RTI import (its
        images' own 8-bit values), else the field's display scale (its 99.5th percentile is
        white), as ``rig relight --lights`` shows it.

    Returns
    -------
    WebExport

    Raises
    ------
    InputError
        A field of points, a camera index out of range, an unknown model or format, a
        quality, tile size or overlap out of range, too few lights for a model, an output
        that cannot be written.
    """
    height, width = _check(field, output, camera, models, image_format, quality, scale)
    tiled = max(width, height) > TILE_THRESHOLD if tiles is None else tiles
    if tiled:
        if tile_size < 1:
            raise InputError(f"tile size {tile_size} must be at least 1 pixel")
        if not 0 <= overlap < tile_size:
            raise InputError(f"tile overlap {overlap} must be in 0..{tile_size - 1} (tile size)")
        if tile_size >= max(width, height):
            raise InputError(
                f"tile size {tile_size} must be smaller than the image's longest side "
                f"({max(width, height)} pixels) for deep-zoom tiles"
            )
    white = _white_scale(field, camera) if scale is None else float(scale)
    lights = rig_to_camera(field.light_directions, field.cameras[camera])
    fitted, normals = _fit(field, camera, models, lights, white)
    visible = np.asarray(field.visibility[camera], dtype=bool)
    folder = Path(output)
    written = []
    for model in models:
        layout = _Layout(width, height, image_format, quality, tiled, tile_size, overlap)
        written.append(_write_model(folder / model, model, fitted[model], visible, lights, layout))
    png, exr = _write_normals(folder, normals, visible, (height, width))
    return WebExport(folder, camera, width, height, white, tuple(written), png, exr)


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


def _white_scale(field: ReflectanceField, camera: int) -> float:
    """1 for an RTI import (its 8-bit values), else the display scale of the visible pixels."""
    if field.provenance.get("source") == "rti":
        return 1.0
    return display_scale(field.camera_slab(camera)[:, field.visibility[camera]])


def _fit(
    field: ReflectanceField,
    camera: int,
    models: tuple[WebModel, ...],
    lights: NDArray[np.float64],
    white: float,
) -> tuple[dict[WebModel, NDArray[np.float32]], NDArray[np.float64]]:
    """Coefficients (P, B, 3) of each model (8-bit units) and normals (P, 3), camera frame.

    The coefficients are :func:`render.light_prediction.fit_basis_8bit`'s. A band of pixels
    at a time (:data:`CHUNK_BYTES` of radiance): every pixel is fitted on its
    own, so the bands give what one fit of the whole view would. Normals: the field's own
    (rotated into the camera frame), else photometric stereo.
    """
    _, t_count, p_count = field.shape
    terms = {model: evaluate_basis(model, lights[:1]).shape[1] for model in models}
    fitted = {model: np.zeros((p_count, terms[model], 3), np.float32) for model in models}
    if field.normals is not None:
        normals = rig_to_camera(field.normals.astype(np.float64), field.cameras[camera])
    else:
        normals = np.zeros((p_count, 3))
    view = np.array([0.0, 0.0, 1.0])
    step = max(1, CHUNK_BYTES // (t_count * 12))
    for start in range(0, p_count, step):
        band = slice(start, min(start + step, p_count))
        values = np.asarray(field.camera_radiance(camera, band), dtype=np.float32)
        levels = eight_bit_levels(values, white)  # what fit_basis_8bit fits, encoded once
        for model in models:
            fitted[model][band] = fit_basis(model, levels, lights).coefficients
        if field.normals is None:
            normals[band] = photometric_stereo(values, lights, view)
    return fitted, normals


@dataclass(frozen=True)
class _Layout:
    """How the planes are written."""

    width: int
    height: int
    image_format: PlaneFormat
    quality: int
    tiled: bool
    tile_size: int
    overlap: int

    @property
    def levels(self) -> int:
        """Deep-zoom levels (0: a single image per plane)."""
        return deepzoom_levels(self.width, self.height, self.tile_size) if self.tiled else 0


def _write_model(
    folder: Path,
    model: WebModel,
    coefficients: NDArray[np.float32],
    visible: NDArray[np.bool_],
    lights: NDArray[np.float64],
    layout: _Layout,
) -> WebModelExport:
    """Quantise one model's planes, write them and then ``info.json``; measure the error."""
    p_count, terms, _ = coefficients.shape
    # Values 0..1 (the viewer's units), plane 3 i + c = term i, channel c.
    viewer = viewer_coefficients(model, coefficients).reshape(p_count, terms * 3)
    planes = (viewer / 255.0).astype(np.float32)
    planes[~visible] = 0.0  # pixels that are not the object are black
    seen = planes[visible] if visible.any() else np.zeros((1, terms * 3))
    low, high = seen.min(axis=0).astype(np.float64), seen.max(axis=0).astype(np.float64)
    if not visible.all():
        low, high = np.minimum(low, 0.0), np.maximum(high, 0.0)
    span = np.maximum(high - low, MIN_SPAN)
    levels = np.clip(np.rint((planes - low) / span * 255.0), 0, 255).astype(np.uint8)
    files = []
    for j in range(terms):
        picture = np.ascontiguousarray(
            levels[:, 3 * j : 3 * j + 3].reshape(layout.height, layout.width, 3)
        )
        files.append(_write_plane(folder, f"plane_{j}", picture, layout))
    info = {
        "width": layout.width,
        "height": layout.height,
        "format": layout.image_format,
        "type": _INFO_TYPE[model],
        "colorspace": "rgb",
        "lights": [round(float(v), 6) for v in lights.reshape(-1)],
        "nplanes": terms * 3,
        "quality": layout.quality,
        "materials": [{"scale": [float(s) for s in span], "bias": [float(b) for b in -low / span]}],
    }
    write_json_atomic(folder / "info.json", info)  # last: a viewer never sees a partial model
    rms, largest = _render_error(folder, model, planes, low, span, visible, lights, layout)
    return WebModelExport(model, folder, terms * 3, tuple(files), layout.levels, rms, largest)


def _write_plane(folder: Path, stem: str, picture: NDArray[np.uint8], layout: _Layout) -> Path:
    """One image of three planes: ``stem.FORMAT``, or its ``.dzi`` and tiles."""
    suffix = f".{layout.image_format}"
    if not layout.tiled:
        path = folder / f"{stem}{suffix}"
        write_uint8(path, picture, quality=layout.quality, full_chroma=True)
        return path
    level_picture = picture
    count = layout.levels
    for level in range(count - 1, -1, -1):
        if level < count - 1:
            level_picture = _halved(level_picture)
        for col, row, xs, ys in _tiles(level_picture.shape[1], level_picture.shape[0], layout):
            tile = np.ascontiguousarray(level_picture[ys, xs])
            path = folder / f"{stem}_files" / str(level) / f"{col}_{row}{suffix}"
            write_uint8(path, tile, quality=layout.quality, full_chroma=True)
    dzi = folder / f"{stem}.dzi"
    with atomic_path(dzi) as temporary:
        temporary.write_text(
            '<?xml version="1.0" encoding="UTF-8"?>\n'
            '<Image xmlns="http://schemas.microsoft.com/deepzoom/2008"\n'
            f'  Format="{layout.image_format}" Overlap="{layout.overlap}" '
            f'TileSize="{layout.tile_size}">\n'
            f'  <Size Width="{layout.width}" Height="{layout.height}"/>\n'
            "</Image>\n",
            encoding="utf-8",
        )
    return dzi


def _halved(picture: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """The next coarser level: 2 x 2 means, sides halved and floored (a side of 1 is kept)."""
    values = picture.astype(np.float64)
    h, w = values.shape[:2]
    if h >= 2:
        values = values[: h // 2 * 2].reshape(h // 2, 2, w, -1).mean(axis=1)
    if w >= 2:
        values = values[:, : w // 2 * 2].reshape(values.shape[0], w // 2, 2, -1).mean(axis=2)
    return np.clip(np.rint(values), 0, 255).astype(np.uint8)


def _tiles(width: int, height: int, layout: _Layout) -> list[tuple[int, int, slice, slice]]:
    """(column, row, x span, y span) of the tiles of a level ``width`` x ``height``."""
    side, over = layout.tile_size, layout.overlap
    out = []
    for row in range(-(-height // side)):
        ys = slice(max(0, row * side - over), min(height, (row + 1) * side + over))
        for col in range(-(-width // side)):
            xs = slice(max(0, col * side - over), min(width, (col + 1) * side + over))
            out.append((col, row, xs, ys))
    return out


def _stored(folder: Path, stem: str, layout: _Layout) -> NDArray[np.uint8]:
    """The bytes (H, W, 3) of a written image as they read back (the finest level, tiled)."""
    suffix = f".{layout.image_format}"
    if not layout.tiled:
        return np.asarray(read_pixels(folder / f"{stem}{suffix}"), dtype=np.uint8)
    picture = np.zeros((layout.height, layout.width, 3), np.uint8)
    side = layout.tile_size
    for col, row, xs, ys in _tiles(layout.width, layout.height, layout):
        tile = read_pixels(
            folder / f"{stem}_files" / str(layout.levels - 1) / f"{col}_{row}{suffix}"
        )
        x0, y0 = col * side - xs.start, row * side - ys.start  # the overlap before the tile
        inner_x = slice(col * side, min(layout.width, (col + 1) * side))
        inner_y = slice(row * side, min(layout.height, (row + 1) * side))
        h, w = inner_y.stop - inner_y.start, inner_x.stop - inner_x.start
        picture[inner_y, inner_x] = tile[y0 : y0 + h, x0 : x0 + w]
    return picture


def _render_error(
    folder: Path,
    model: WebModel,
    planes: NDArray[np.float32],
    low: NDArray[np.float64],
    span: NDArray[np.float64],
    visible: NDArray[np.bool_],
    lights: NDArray[np.float64],
    layout: _Layout,
) -> tuple[float, float]:
    """RMS and largest error (8-bit levels) of the written planes under the measured lights."""
    seen = np.flatnonzero(visible)
    if seen.size == 0:
        return 0.0, 0.0
    if seen.size > ERROR_SAMPLES:
        seen = np.sort(np.random.default_rng(0).choice(seen, ERROR_SAMPLES, replace=False))
    terms = planes.shape[1] // 3
    stored = np.concatenate(
        [_stored(folder, f"plane_{j}", layout).reshape(-1, 3)[seen] for j in range(terms)],
        axis=1,
    )
    decoded = (stored / 255.0 + low / span) * span  # the viewer's (byte / 255 - bias) * scale
    difference = (decoded - planes[seen]).reshape(-1, terms, 3)
    order, signs = _viewer_order(model)
    design = evaluate_basis(model, lights)[:, order] * signs  # (T, B): the viewer's terms
    error = np.einsum("tb,pbc->tpc", design, difference) * 255.0
    return float(np.sqrt(np.mean(error**2))), float(np.abs(error).max())


def _write_normals(
    folder: Path,
    normals: NDArray[np.float64],
    visible: NDArray[np.bool_],
    shape: tuple[int, int],
) -> tuple[Path, Path]:
    """``normals.png`` (16-bit, (n + 1) / 2) and ``normals.exr`` (float, alpha = visible)."""
    n = np.array(normals, dtype=np.float64)
    n[~visible] = (0.0, 0.0, 1.0)
    image = n.reshape(*shape, 3)
    png, exr = folder / "normals.png", folder / "normals.exr"
    encoded = np.clip(np.rint((image * 0.5 + 0.5) * 65535.0), 0, 65535).astype(np.uint16)
    write_png16(png, encoded)
    write_exr(exr, image.astype(np.float32), alpha=visible.reshape(shape).astype(np.float32))
    return png, exr

"""An RTI capture's files as :func:`processing.rti.import_rti` reads them.

The photographs an ``.lp`` file names (a Windows separator accepted): their stored values (grey
repeated to RGB, alpha dropped), their bit depth and the transfer curve applied to them (with
its provenance record and words), the table of every level's linear value and the look-up
through it, and the images decoded ahead on a thread while the one before is written (at most
:data:`DECODE_AHEAD`). Beside the ``.lp`` file, the sidecars (:mod:`core.lp_format`): the mask
(its non-zero pixels are the object) and the lights' intensities, each with its record. Every
problem is a :class:`~core.errors.DatasetError` naming the file and the ``.lp`` line.
"""

from __future__ import annotations

import hashlib
import os
from collections import deque
from collections.abc import Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.errors import DatasetError
from core.image_io import (
    ImageFileError,
    PixelDepth,
    Transfer,
    TransferChoice,
    auto_transfer,
    linear_from_pixels,
    pixel_depth,
    read_pixels,
)
from core.lp_format import INTENSITY_SIDECARS, MASK_SIDECARS, LightPositions, read_intensity_sidecar

__all__ = ["DECODE_AHEAD"]

#: Images decoded ahead of the one being written (each an 8-bit 24-megapixel image is 72 MB).
DECODE_AHEAD = 2
#: What ``transfer="auto"`` assumes, as the import reports it.
_AUTO_RULE = "auto: 8-bit is sRGB, 16-bit and float are linear"


def _image_path(folder: Path, name: str) -> Path:
    """The image ``name`` of an ``.lp`` file in ``folder``; Windows separators are accepted."""
    path = folder / name
    if not path.exists() and "\\" in name:
        path = folder / name.replace("\\", "/")
    return path


def _read_rti_pixels(path: Path, where: str) -> NDArray[Any]:
    """The stored values (H, W, 3) of one RTI photograph; grey is repeated, alpha dropped."""
    try:
        pixels = read_pixels(path)
    except ImageFileError as error:
        raise DatasetError(f"{where}: {error}") from error
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    if pixels.ndim != 3 or pixels.shape[2] not in (1, 3, 4):
        raise DatasetError(f"{where}: {path}: expected a grey or RGB image, got {pixels.shape}")
    if pixels.shape[2] == 1:
        pixels = np.repeat(pixels, 3, axis=2)
    return pixels[:, :, :3]


def _linear_rti_image(
    pixels: NDArray[Any], transfer: Transfer, path: Path, where: str
) -> NDArray[np.float32]:
    """Linear float32 (H, W, 3) of one photograph's stored values; non-finite values refused."""
    try:
        image = linear_from_pixels(pixels, transfer=transfer, where=str(path))
    except ImageFileError as error:
        raise DatasetError(f"{where}: {error}") from error
    if not np.all(np.isfinite(image)):
        raise DatasetError(f"{where}: {path}: NaN or infinite pixel values")
    return np.ascontiguousarray(image, dtype=np.float32)


def _depth(pixels: NDArray[Any], path: Path, where: str) -> PixelDepth:
    try:
        return pixel_depth(pixels, where=str(path))
    except ImageFileError as error:
        raise DatasetError(f"{where}: {error}") from error


def _transfer_record(
    requested: TransferChoice, first: NDArray[Any], depth: PixelDepth, first_name: str
) -> tuple[Transfer, dict[str, Any], str]:
    """The curve applied to every image, its provenance record and its words for the report."""
    applied: Transfer = auto_transfer(first) if requested == "auto" else requested
    if depth == "float":
        applied = "linear"  # floats are linear as stored, whatever was asked
        said = "taken as stored (float: linear"
        said += "; transfer 'srgb' does not apply to floats)" if requested == "srgb" else ")"
    else:
        curve = "sRGB" if applied == "srgb" else "linear"
        said = f"decoded as {curve} (" + (
            f"{_AUTO_RULE}; transfer 'srgb' or 'linear' overrides)"
            if requested == "auto"
            else f"transfer {requested!r} as asked)"
        )
    record = {
        "requested": requested,
        "applied": applied,
        "bit_depth": depth,
        "first_image": first_name,
        "rule": _AUTO_RULE,
    }
    return applied, record, said


def _level_table(
    transfer: Transfer, depth: PixelDepth, dtype: type[np.floating] | str
) -> NDArray[np.floating] | None:
    """The linear value (in ``dtype``) of every stored level of 8- or 16-bit images; None for float.

    ``table[pixels]`` is :func:`core.image_io.linear_from_pixels` of ``pixels`` bit for bit
    (the same function of the same levels), then cast to ``dtype`` as the store would.
    """
    if depth == "float":
        return None
    levels = np.arange(256 if depth == "8-bit" else 65536).astype(
        np.uint8 if depth == "8-bit" else np.uint16
    )
    return linear_from_pixels(levels, transfer=transfer).astype(dtype)


def _look_up(
    table: NDArray[np.floating], pixels: NDArray[Any], out: NDArray[np.floating]
) -> NDArray[np.floating]:
    """``table[pixels]`` into ``out`` (same shape as ``pixels``, the table's dtype)."""
    if pixels.dtype == np.uint8:
        import cv2

        # OpenCV's table look-up is 3x numpy's (which widens every index to 64 bits first);
        # it knows no float16, whose values it moves as their 16-bit patterns.
        carried = table.view(np.uint16) if table.dtype == np.float16 else table
        cv2.LUT(pixels, carried, dst=out.view(carried.dtype))
        return out
    return np.take(table, pixels, out=out)


def _decoded(
    paths: Sequence[Path], first: NDArray[Any], lp_file: Path, lights: LightPositions
) -> Iterator[NDArray[Any]]:
    """The stored values of each image in order, the next ones decoded on a thread meanwhile.

    Decoding (OpenCV releases the GIL) overlaps converting and writing the image before: at
    most :data:`DECODE_AHEAD` images wait decoded, so the import holds a few images whatever
    the capture's length.
    """
    yield first
    with ThreadPoolExecutor(1, thread_name_prefix="rti-decode") as pool:
        waiting: deque[Future[NDArray[Any]]] = deque()
        following = iter(range(1, len(paths)))
        try:
            for index in following:
                where = f"{lp_file}, line {lights.line(index)}"
                waiting.append(pool.submit(_read_rti_pixels, paths[index], where))
                if len(waiting) > DECODE_AHEAD:
                    yield waiting.popleft().result()
            while waiting:
                yield waiting.popleft().result()
        finally:
            for future in waiting:
                future.cancel()


def _sidecar(folder: Path, stem: str, patterns: Sequence[str]) -> Path | None:
    """The first of ``patterns`` (``{stem}`` filled in) that is a file in ``folder``."""
    for pattern in patterns:
        candidate = folder / pattern.format(stem=stem)
        if candidate.is_file():
            return candidate
    return None


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _read_mask(path: Path, how: str, height: int, width: int) -> NDArray[np.bool_]:
    """Which of the H W pixels (row-major, (P,) bool) a mask image marks: its non-zero ones.

    ``how`` says where the mask came from (``"mask argument"``, ``"mask sidecar"``), for the
    messages.
    """
    try:
        pixels = read_pixels(path)
    except ImageFileError as error:
        raise DatasetError(f"{how}: {error}") from error
    if pixels.ndim not in (2, 3):
        raise DatasetError(f"{how} {path}: expected a grey or RGB image, got {pixels.shape}")
    if pixels.shape[:2] != (height, width):
        raise DatasetError(
            f"{how} {path}: {pixels.shape[1]}x{pixels.shape[0]} pixels, the images are "
            f"{width}x{height} (width x height); give a mask of the images' size"
        )
    if pixels.dtype.kind == "f" and not np.all(np.isfinite(pixels)):
        raise DatasetError(f"{how} {path}: NaN or infinite values; a mask is 0 or non-zero")
    selected = pixels != 0 if pixels.ndim == 2 else np.any(pixels != 0, axis=2)
    if not selected.any():
        raise DatasetError(
            f"{how} {path}: every pixel is zero, so no pixel would count; non-zero pixels mark "
            "the object"
        )
    return np.ascontiguousarray(selected.reshape(-1))


def _mask(
    lp_file: Path, mask: str | os.PathLike[str] | None, height: int, width: int
) -> tuple[NDArray[np.bool_], dict[str, Any] | None]:
    """The visibility (H W,) of the import and its provenance record (None: no mask)."""
    if mask is not None:
        path, found = Path(mask), "mask argument"
    else:
        sidecar = _sidecar(lp_file.parent, lp_file.stem, MASK_SIDECARS)
        if sidecar is None:
            return np.ones(height * width, dtype=bool), None
        path, found = sidecar, "mask sidecar"
    visible = _read_mask(path, found, height, width)
    record = {
        "file": str(path.resolve()),
        "sha256": _sha256(path),
        "found": found,
        "pixels": int(visible.sum()),
        "rule": "non-zero pixels count; the others are not samples (visibility False)",
    }
    return visible, record


def _intensities(
    lp_file: Path, lights: LightPositions
) -> tuple[NDArray[np.float64] | None, dict[str, Any] | None]:
    """The lights' intensities (fifth column or sidecar) and their provenance record."""
    sidecar = _sidecar(lp_file.parent, lp_file.stem, INTENSITY_SIDECARS)
    if lights.intensities is not None:
        if sidecar is not None:
            raise DatasetError(
                f"{lp_file}: gives intensities in a fifth column and {sidecar} gives them too; "
                "keep one of the two"
            )
        values = lights.intensities
        record: dict[str, Any] = {"source": f"{lp_file.name} fifth column"}
    elif sidecar is not None:
        values = read_intensity_sidecar(sidecar, lights)
        record = {"source": str(sidecar.resolve()), "sha256": _sha256(sidecar)}
    else:
        return None, None
    record["values"] = [float(value) for value in values]
    record["rule"] = "each image divided by its light's intensity"
    return values, record

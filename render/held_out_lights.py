"""What held-out-light evaluation scores: fit and test lights, and the tiles of a large view.

The lights a method may use (the fit lights) and the lights it must predict (the test lights)
come from a split of one capture's own lights (:func:`held_out_split`, the splits of
:mod:`render.light_splits`) or from a second capture of other lights (:func:`against_test`: an
``.lp`` file, :func:`test_field_from_lp`, or a field store of the same view). A view of more
than :data:`EVALUATE_PIXELS` pixels (a DSLR capture) is scored on tiles spread evenly over it
(:func:`pixel_sample`), read from the store band by band: the scores say so
(:meth:`PixelSample.note`), and the memory is that of the tiles whatever the view's size. The
scoring itself is :func:`render.evaluation.evaluate`.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from core.field_store import ReflectanceField, is_field_store
from core.image_io import TransferChoice
from processing.image_quality import SSIM_WINDOW
from processing.rti import import_rti
from render.light_splits import split_lights

__all__ = [
    "EVALUATE_PIXELS",
    "TILE_SIDE",
    "HeldOut",
    "PixelSample",
    "against_test",
    "held_out_split",
    "pixel_sample",
    "test_field_from_lp",
]

#: Pixels of a view the evaluation scores at most: a larger view (a DSLR capture of 24
#: megapixels) is scored on :data:`TILE_SIDE` tiles spread evenly over it
#: (:func:`pixel_sample`), so that every method's fit and predictions of every test image stay
#: within memory (at 60 lights a 24-megapixel view is 17 GB of float32; its predictions under
#: 30 test lights 8.6 GB more). Measured with 60 lights (bench.scale_rti): the learned rung
#: alone peaked at 3.7 GB on 262,144 pixels and 1.2 GB on 131,072, every method together at
#: 5.3 GB on 262,144. 131,072 pixels x 30 test images is 3.9 million scored pixels.
EVALUATE_PIXELS = 8 * 128 * 128
#: Side (pixels) of the tiles a large view is scored on: square, so SSIM's 11 x 11 windows see
#: the neighbourhoods the view has.
TILE_SIDE = 128


def test_field_from_lp(
    lp_path: str | Path, *, transfer: TransferChoice = "auto", sample: PixelSample | None = None
) -> ReflectanceField:
    """The test images of an ``.lp`` file (and its images) as a field held in memory.

    ``transfer`` decodes them as :func:`processing.rti.import_rti` does the field's; with a
    ``sample``, only its tiles are kept (the import streams, the tiles are read from it).
    """
    with tempfile.TemporaryDirectory(prefix="rig-evaluate-") as scratch:
        store = import_rti(lp_path, Path(scratch) / "test.zarr", transfer=transfer)
        # In memory: the temporary store goes.
        return store.subset() if sample is None else sample.take(store)


@dataclass(frozen=True)
class PixelSample:
    """The tiles of a large view that the evaluation scores (:func:`pixel_sample`).

    Attributes
    ----------
    view : (height, width) of the whole view, pixels
    side : int, the tiles' side, pixels
    columns : int, tiles per row (of the view's grid of tiles, and of the mosaic scored)
    origins : tuple of (row, column), each tile's top-left pixel in the view, row by row
    """

    view: tuple[int, int]
    side: int
    columns: int
    origins: tuple[tuple[int, int], ...]

    @property
    def pixels(self) -> int:
        """Pixels of the tiles (those scored: less the seams, see :meth:`mask`)."""
        return len(self.origins) * self.side * self.side

    def note(self) -> str:
        """What was scored, in a sentence for the table and the JSON."""
        height, width = self.view
        rows = len(self.origins) // self.columns
        share = self.pixels / (height * width)
        return (
            f"pixels: scored on {len(self.origins)} tiles of {self.side} x {self.side} (a "
            f"{self.columns} x {rows} grid spread evenly over the {width} x {height} view; "
            f"{self.pixels:,} of its {height * width:,} pixels, {share:.1%}), the "
            f"{_SEAM} pixels beside each seam between two tiles left out"
        )

    def take(self, field: ReflectanceField) -> ReflectanceField:
        """The tiles of ``field`` (this view) side by side, held in memory (every light).

        Raises InputError when ``field`` is not a field of pixels of this view's size.
        """
        if field.image_shape != self.view:
            raise InputError(
                f"{field.path}: images {field.image_shape}, the tiles are of a view of {self.view}"
            )
        return field.tiles(self.origins, self.side, self.columns)

    def mask(self, mask: NDArray[np.bool_] | None) -> NDArray[np.bool_]:
        """The pixels of the mosaic that count: ``mask`` (H, W) of the view on the tiles.

        Less :data:`_SEAM` pixels on each side of every seam between two tiles: an SSIM window
        there would mix two places of the view (the view's own border is left out by SSIM
        itself, as for a whole view).
        """
        rows = len(self.origins) // self.columns
        out = np.ones((rows * self.side, self.columns * self.side), dtype=bool)
        if mask is not None:
            for index, (row, column) in enumerate(self.origins):
                y, x = index // self.columns * self.side, index % self.columns * self.side
                out[y : y + self.side, x : x + self.side] = mask[
                    row : row + self.side, column : column + self.side
                ]
        for seam in range(1, self.columns):
            out[:, seam * self.side - _SEAM : seam * self.side + _SEAM] = False
        for seam in range(1, rows):
            out[seam * self.side - _SEAM : seam * self.side + _SEAM] = False
        return out

    def to_json(self) -> dict[str, Any]:
        """The tiles, for the evaluation's JSON."""
        return {
            "note": self.note(),
            "view": list(self.view),
            "side": self.side,
            "columns": self.columns,
            "origins": [list(o) for o in self.origins],
        }


#: Pixels left out beside each seam of a mosaic of tiles: half an SSIM window.
_SEAM = SSIM_WINDOW // 2


def pixel_sample(
    image_shape: tuple[int, int] | None,
    max_pixels: int | None = None,
    side: int | None = None,
) -> PixelSample | None:
    """The tiles a view of ``image_shape`` is scored on, or None when it is scored whole.

    A view of more than ``max_pixels`` pixels is scored on up to ``max_pixels // side^2``
    tiles (at least one) of ``side`` x ``side`` pixels, in the grid of the most such tiles
    whose aspect is nearest the view's, each cell holding one tile at its centre: evenly
    spread, the same for every method and every test image, and reproducible (no random
    draw).

    Parameters
    ----------
    image_shape : (height, width), or None (a field of points: scored whole)
    max_pixels : int, the most pixels scored whole (default :data:`EVALUATE_PIXELS`)
    side : int, the tiles' side (default :data:`TILE_SIDE`; smaller when the view or
        ``max_pixels`` is)
    """
    max_pixels = EVALUATE_PIXELS if max_pixels is None else max_pixels
    side = min(TILE_SIDE if side is None else side, math.isqrt(max_pixels))
    if image_shape is None or image_shape[0] * image_shape[1] <= max_pixels:
        return None
    height, width = image_shape
    count = max(1, max_pixels // (side * side))
    aspect = width / height
    columns = max(
        range(1, count + 1), key=lambda c: (count // c * c, -abs(math.log(c * c / count / aspect)))
    )
    rows = count // columns
    side = min(side, height // rows, width // columns)
    if side < SSIM_WINDOW:
        raise InputError(
            f"{max_pixels} pixels in {rows} x {columns} tiles of a {width} x {height} view "
            f"leave tiles under {SSIM_WINDOW} pixels; score more pixels"
        )

    def starts(cells: int, length: int) -> list[int]:
        return [min(max(0, round((c + 0.5) * length / cells - side / 2)), length - side)
                for c in range(cells)]  # fmt: skip

    origins = tuple((r, c) for r in starts(rows, height) for c in starts(columns, width))
    return PixelSample(view=(height, width), side=side, columns=columns, origins=origins)


@dataclass(frozen=True)
class HeldOut:
    """What the evaluation scores: the fit lights, the test lights, the pixels that count.

    Attributes
    ----------
    fit, test : ReflectanceField, the same view(s) under the fit and the test lights (the
        tiles of ``sample`` when a large view is sampled)
    mask : ndarray (H, W) of bool or None, the pixels that count (of ``fit``'s images)
    sample : PixelSample or None, the tiles scored (None: every pixel)
    test_lights : ndarray of int or None, the field's lights held out (a split)
    """

    fit: ReflectanceField
    test: ReflectanceField
    mask: NDArray[np.bool_] | None
    sample: PixelSample | None
    test_lights: NDArray[np.int64] | None = None


def held_out_split(
    field: ReflectanceField,
    split: str,
    mask: NDArray[np.bool_] | None = None,
    *,
    max_pixels: int | None = None,
    side: int | None = None,
) -> HeldOut:
    """A split of ``field``'s own lights (:func:`render.light_splits.split_lights`), in memory.

    A view of more than ``max_pixels`` pixels is read as the ``side`` tiles of
    :func:`pixel_sample` (band by band of the store: never whole), then split.
    """
    fit_index, test_index = split_lights(field, split)
    sample = pixel_sample(field.image_shape, max_pixels, side)
    base = field if sample is None else sample.take(field)
    return HeldOut(
        fit=base.subset(lights=fit_index),
        test=base.subset(lights=test_index),
        mask=mask if sample is None else sample.mask(mask),
        sample=sample,
        test_lights=test_index,
    )


def against_test(
    field: ReflectanceField,
    test: str | Path,
    mask: NDArray[np.bool_] | None = None,
    *,
    transfer: TransferChoice = "auto",
    max_pixels: int | None = None,
    side: int | None = None,
) -> HeldOut:
    """``field`` against the test lights of an ``.lp`` capture or a field store of its view.

    A view of more than ``max_pixels`` pixels is scored on the ``side`` tiles of
    :func:`pixel_sample`, of both.

    Raises
    ------
    InputError
        ``test`` is neither an ``.lp`` file nor a field store.
    """
    where = Path(test)
    sample = pixel_sample(field.image_shape, max_pixels, side)
    if is_field_store(where):
        opened = ReflectanceField.open(where)
        tested = opened if sample is None else sample.take(opened)
    elif where.suffix.lower() == ".lp":
        tested = test_field_from_lp(where, transfer=transfer, sample=sample)
    else:
        raise InputError(f"{where}: give an .lp file or a field store")
    return HeldOut(
        fit=field if sample is None else sample.take(field),
        test=tested,
        mask=mask if sample is None else sample.mask(mask),
        sample=sample,
    )

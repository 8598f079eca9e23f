"""Plane images as OpenLIME loads them: one image, or deep-zoom tiles.

Which file a layer asks for is the layout's (cnr-isti-vclab/openlime ``src/Layout.js`` and
``src/LayoutTiles.js`` ``imageUrl``; ``src/LayerRTI.js`` ``imageUrl``): the ``image`` layout
asks for ``plane_j.jpg`` whatever ``info.json`` says (the suffix is written into the code),
and the ``deepzoom`` layout for ``plane_j.dzi``, then for tiles in the format its ``Format``
attribute names (``LayoutTiles.initDeepzoom``). So PNG planes load only as deep-zoom tiles.

Deep zoom as ``LayoutTiles`` reads it (``initDeepzoom``, ``initBoxes``, ``tileCoords``):
``plane_j.dzi`` (``Image`` with ``Format``, ``Overlap``, ``TileSize``, and ``Size`` with
``Width`` and ``Height``) and tiles ``plane_j_files/LEVEL/COL_ROW.FORMAT``. Level 0 is the
coarsest, a single tile: there are ``ceil(log2(max(W, H) / TileSize)) + 1`` levels and level
L is the image halved ``levels - 1 - L`` times (sizes floored, 2 x 2 means). Tile (c, r)
spans pixels ``max(0, c T - overlap) .. min(W_L, (c + 1) T + overlap)`` (and so in y).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from core.atomic import atomic_path
from core.errors import InputError
from core.image_io import read_pixels, write_uint8
from render.web_export.names import TILE_SIZE, PlaneFormat

__all__ = ["Layout", "automatic_tile_size", "deepzoom_levels", "stored", "write_plane"]


def deepzoom_levels(width: int, height: int, tile_size: int) -> int:
    """Deep-zoom levels as OpenLIME counts them: ``ceil(log2(max(W, H) / T)) + 1``.

    The smallest n with ``max(W, H) <= T 2^(n - 1)`` (exact in integers).
    """
    levels = 1
    while max(width, height) > tile_size << (levels - 1):
        levels += 1
    return levels


def automatic_tile_size(width: int, height: int, overlap: int) -> int:
    """The deep-zoom tile side (pixels) for an image ``width`` x ``height``.

    :data:`render.web_export.TILE_SIZE` when the longest side is longer; else the largest
    power of two less twice the overlap (an inner tile with its overlap is then a power of
    two wide, as 254 + 2 is) that is shorter than the longest side, so that there are at
    least two levels.

    Raises
    ------
    InputError
        An image too small to tile (a longest side of 2 pixels or less with overlap 0).
    """
    longest = max(width, height)
    if longest > TILE_SIZE:
        return TILE_SIZE
    side = 0
    power = 1
    while (power << 1) - 2 * overlap < longest:
        power <<= 1
        side = power - 2 * overlap
    if side < 1:
        raise InputError(
            f"an image of {width} x {height} pixels is too small for deep-zoom tiles of "
            f"overlap {overlap}: write it as single images (--no-tiles, JPEG)"
        )
    return side


@dataclass(frozen=True)
class Layout:
    """How planes are written.

    Attributes
    ----------
    width, height : int, the image's size (pixels)
    image_format : "jpg" or "png"
    quality : int, JPEG quality (colour kept at full resolution, 4:4:4)
    tiled : bool, deep-zoom tiles rather than one image per plane
    tile_size, overlap : int, the tiles' side and overlap (pixels)
    """

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


def write_plane(folder: Path, stem: str, picture: NDArray[np.uint8], layout: Layout) -> Path:
    """One image of three planes (H, W, 3) uint8: ``stem.FORMAT``, or its ``.dzi`` and tiles.

    Returns the image, or the ``.dzi``. The ``.dzi`` is written after its tiles: a viewer
    never finds one whose tiles are missing.
    """
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
    """The next coarser level: 2 x 2 means, sides halved and floored (a side of 1 is kept).

    Sums in 16 bits, rounded half up: a quarter of the memory of floats, for planes of tens
    of megapixels.
    """
    h, w = picture.shape[:2]
    sums = picture.astype(np.uint16)
    count = 1
    if h >= 2:
        sums = sums[: h // 2 * 2].reshape(h // 2, 2, w, -1).sum(axis=1, dtype=np.uint16)
        count *= 2
    if w >= 2:
        rows = sums.shape[0]
        sums = sums[:, : w // 2 * 2].reshape(rows, w // 2, 2, -1).sum(axis=2, dtype=np.uint16)
        count *= 2
    return ((sums + count // 2) // count).astype(np.uint8)


def _tiles(width: int, height: int, layout: Layout) -> list[tuple[int, int, slice, slice]]:
    """(column, row, x span, y span) of the tiles of a level ``width`` x ``height``."""
    side, over = layout.tile_size, layout.overlap
    out = []
    for row in range(-(-height // side)):
        ys = slice(max(0, row * side - over), min(height, (row + 1) * side + over))
        for col in range(-(-width // side)):
            xs = slice(max(0, col * side - over), min(width, (col + 1) * side + over))
            out.append((col, row, xs, ys))
    return out


def stored(folder: Path, stem: str, layout: Layout) -> NDArray[np.uint8]:
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

"""The web export's names and numbers: its models, plane formats and tile sizes.

Kept apart from the package's functions so that the command line's parser (and every submodule)
reads them without importing numpy or the rest of the export.
"""

from __future__ import annotations

from typing import Literal, get_args

#: The linear bases written (Relight's ``ptm`` and ``hsh`` types).
BasisModel = Literal["ptm", "hsh2", "hsh3"]
BASIS_MODELS: tuple[BasisModel, ...] = get_args(BasisModel)
#: Every model ``rig export-web --models`` writes: the bases and OpenLIME's ``neural``.
WebModel = Literal["ptm", "hsh2", "hsh3", "neural"]
WEB_MODELS: tuple[WebModel, ...] = get_args(WebModel)
#: The planes' image format.
PlaneFormat = Literal["jpg", "png"]
PLANE_FORMATS: tuple[PlaneFormat, ...] = get_args(PlaneFormat)

#: Images with a side longer than this (pixels) are tiled unless told otherwise.
TILE_THRESHOLD = 2048
#: Deep-zoom tile side (pixels) of images longer than it; with the overlap an inner tile is
#: 256 pixels wide. Shorter images get a smaller side (:func:`automatic_tile_size`).
TILE_SIZE = 254
#: Pixels each tile repeats of its neighbours (hides the seams of bilinear filtering).
TILE_OVERLAP = 1
#: Visible pixels (at most) the reported errors are measured on.
ERROR_SAMPLES = 4096
#: Default time budget (s) of the neural model's fit (the decoder's tuning included).
NEURAL_SECONDS = 120.0

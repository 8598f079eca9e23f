"""A pixel field's light models in the web RTI formats (Relight and OpenLIME).

``rig export-web`` writes what the web RTI viewers load: per model a folder with ``info.json``
and the quantised planes, and beside them the field's normal map. The models: the linear
bases PTM and HSH (Relight's ``ptm`` and ``hsh`` types, OpenLIME's ``rti`` layer;
:mod:`render.web_export.basis`) and OpenLIME's ``neural`` layer (a code of 9 values per pixel
and a small decoder; :mod:`render.web_export.neural`, fitted by :mod:`processing.neural_rti`).
Planes are single images or deep-zoom tiles (:mod:`render.web_export.tiles`); what OpenLIME's
display does to the colours is :mod:`render.web_export.display`; the whole export is
:func:`render.web_export.export.export_web`. The format facts are pinned to the tools'
sources, named in each module, and stated in ``docs/web-export.md``.

This module holds only names and numbers (the command line's parser reads them without
importing numpy); the functions and result types load on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Literal, get_args

if TYPE_CHECKING:
    from render.web_export.basis import VIEWER_TERMS, viewer_coefficients
    from render.web_export.display import openlime_display
    from render.web_export.export import export_web
    from render.web_export.result import WebExport, WebModelExport
    from render.web_export.tiles import automatic_tile_size, deepzoom_levels

__all__ = [
    "BASIS_MODELS",
    "ERROR_SAMPLES",
    "NEURAL_SECONDS",
    "PLANE_FORMATS",
    "TILE_OVERLAP",
    "TILE_SIZE",
    "TILE_THRESHOLD",
    "VIEWER_TERMS",
    "WEB_MODELS",
    "BasisModel",
    "PlaneFormat",
    "WebExport",
    "WebModel",
    "WebModelExport",
    "automatic_tile_size",
    "deepzoom_levels",
    "export_web",
    "openlime_display",
    "viewer_coefficients",
]

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

# What loads on first use, and from where (PEP 562).
_LAZY = {
    "VIEWER_TERMS": "basis",
    "viewer_coefficients": "basis",
    "openlime_display": "display",
    "WebExport": "result",
    "WebModelExport": "result",
    "export_web": "export",
    "automatic_tile_size": "tiles",
    "deepzoom_levels": "tiles",
}


def __getattr__(name: str) -> Any:
    """The functions and types of the submodules, imported when first asked for."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(f"{__name__}.{module}"), name)

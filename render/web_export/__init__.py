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

The names and numbers are :mod:`render.web_export.names` (read without importing numpy); the
functions and result types load on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

# The same names as export.py imports, on purpose: this is the package's face re-exporting
# them, their one home is names.py (duplicates lists the pair; it restates no logic).
from render.web_export.names import (
    BASIS_MODELS,
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

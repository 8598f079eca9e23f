"""What OpenLIME's display does to a layer's colours: an 8-bit buffer of gamma-2.2 values.

OpenLIME (cnr-isti-vclab/openlime) draws every layer into an offscreen RGBA texture of 8
bits per channel (``src/Canvas.js``: ``setupOffscreenFramebuffer``, ``gl.RGBA`` /
``gl.UNSIGNED_BYTE``), in linear values: the shaders' ``srgb2linear`` is ``pow(c, 2.2)``
(``src/Shader.js`` ``completeFragShaderSrc``, ``isSrgbSimplified`` true by default). The
canvas then shows that texture through ``linear2srgb``, ``pow(c, 1 / 2.2)``, clamped
(``Canvas.drawOffscreenToCanvas``), into an 8-bit canvas. So a colour ``v`` (an 8-bit sRGB
value over 255, what RTI planes and the neural decoder give) is shown as

    round(255 * (round(255 * v^2.2) / 255)^(1 / 2.2))

Below 15/255 the linear value rounds to 0 and the channel is black; above, the 8-bit linear
steps are coarse in the shadows (15..24 show as 21, 25..31 as 28, 32..36 as 34).
Measured on the bundled capture: ``docs/web-export.md``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["DISPLAY_GAMMA", "openlime_display"]

#: The exponent of OpenLIME's simplified sRGB conversions (``isSrgbSimplified``).
DISPLAY_GAMMA = 2.2


def openlime_display(levels: NDArray[np.integer] | NDArray[np.floating]) -> NDArray[np.uint8]:
    """The 8-bit values OpenLIME's canvas shows for colours of 8-bit sRGB values 0..255.

    Parameters
    ----------
    levels : ndarray, any shape, 8-bit sRGB values 0..255 (integers, or floats, clamped)

    Returns
    -------
    ndarray, same shape, uint8
    """
    v = np.clip(np.asarray(levels, dtype=np.float64), 0.0, 255.0) / 255.0
    linear = np.rint(255.0 * v**DISPLAY_GAMMA) / 255.0  # the 8-bit offscreen texture
    shown = np.clip(linear ** (1.0 / DISPLAY_GAMMA), 0.0, 1.0)
    return np.rint(255.0 * shown).astype(np.uint8)

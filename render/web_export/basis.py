"""PTM and HSH in the RTI web format: Relight's ``ptm`` and ``hsh`` types, OpenLIME's ``rti``.

Format facts, as the tools' sources define them (cnr-isti-vclab/relight
``src/cli/rtibuilder.cpp`` ``RtiBuilder::saveJSON``, ``save``, ``processLine``,
``finalizeMaterial``; ``src/material.h`` ``Material::Plane::quantize``; cnr-isti-vclab/openlime
``src/ShaderRTI.js`` (``init``, ``RGB.render``, ``PTM``/``HSH.lightWeights``) and
``src/LayerRTI.js`` (``loadJson``)):

- ``info.json``: ``width``, ``height``, ``format`` (the planes' suffix, ``"jpg"`` or
  ``"png"``), ``type`` (``"ptm"``, ``"hsh"``), ``colorspace`` (``"rgb"`` here: every
  coefficient of every colour channel), ``lights`` (the measured directions, x y z flattened,
  in the camera frame), ``nplanes`` (3 per basis term: 18 for the 6-term PTM, 12 and 27 for
  HSH of order 2 and 3), ``quality`` and ``materials``: one entry with ``scale`` and
  ``bias``, one number per plane. The viewer copies every key onto its shader object, so no
  other key is written.
- Plane p is colour channel ``p % 3`` of basis term ``p // 3``; ``plane_j.jpg`` (or ``.png``)
  holds planes 3j, 3j + 1, 3j + 2 as its R, G and B.
- Dequantisation (ShaderRTI's GLSL): ``value = (byte / 255 - bias[p]) * scale[p]``; the
  rendered colour is ``sum_j base_j(light) value[3j + c]`` for channel c: 8-bit sRGB values
  over 255. Relight quantises a coefficient ``a`` (of values 0..1) as ``255 (a / scale +
  bias)`` truncated, with ``scale = max - min`` and ``bias = -min / (max - min)`` per plane;
  here the range is each plane's minimum and maximum (no pixel clipped) and the byte is
  rounded, so a coefficient errs by half a step at most.
- The bases, of the light ``(x, y, z)`` in the camera frame of ``.lp`` files (x right, y up,
  z toward the camera; :mod:`processing.rti`): PTM ``1, x, y, x^2, x y, y^2`` (the project's
  order is ``x^2, y^2, x y, x, y, 1``); HSH with ``phi = atan2(y, x)``, ``theta = acos(z)``
  and terms 0..8 the project's hemispherical harmonics reordered and with the
  Condon-Shortley sign dropped (:data:`VIEWER_TERMS`). The viewer's HSH differs from the
  exact basis in two details: it holds theta at ``pi/2 - 0.15`` (lights below 8.6 degrees of
  elevation render as at 8.6 degrees) and takes pi as 3.1415 (the terms' scale errs by
  1.5e-5 relative, and phi by 1.9e-4 rad where y < 0).

The coefficients are the ``-8bit`` fit of :mod:`render.light_prediction` (the RTI tools' fit,
to the images' 8-bit sRGB values) of the camera's view: the exported model renders what
``make_predictor(field, "ptm-8bit")`` predicts (before that predictor's bound), up to the
quantisation and, in JPEG, the compression (measured: ``docs/web-export.md``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from core.atomic import write_json_atomic
from processing.sample_models import evaluate_basis
from render.web_export.names import BasisModel
from render.web_export.planes import PlaneStore, quantise
from render.web_export.result import Probe, WebModelExport, psnr_levels
from render.web_export.tiles import Layout, stored, write_plane

__all__ = ["VIEWER_TERMS", "basis_planes", "terms", "viewer_coefficients", "write_basis"]

#: The viewer's term i is ``sign`` times the project's term ``index`` (``(index, sign)``):
#: PTM reordered; HSH reordered and with the Condon-Shortley phase (-1)^m dropped.
VIEWER_TERMS: dict[BasisModel, tuple[tuple[int, float], ...]] = {
    "ptm": ((5, 1.0), (3, 1.0), (4, 1.0), (0, 1.0), (2, 1.0), (1, 1.0)),
    "hsh2": ((0, 1.0), (3, -1.0), (2, 1.0), (1, -1.0)),
    "hsh3": (
        (0, 1.0), (3, -1.0), (2, 1.0), (1, -1.0), (8, -1.0), (7, -1.0), (6, 1.0), (5, -1.0),
        (4, -1.0),
    ),
}  # fmt: skip
#: ``type`` of ``info.json`` per model.
_INFO_TYPE: dict[BasisModel, str] = {"ptm": "ptm", "hsh2": "hsh", "hsh3": "hsh"}


def terms(model: BasisModel) -> int:
    """Basis terms of a model (each an image of three planes)."""
    return len(VIEWER_TERMS[model])


def viewer_coefficients(
    model: BasisModel, coefficients: NDArray[np.floating]
) -> NDArray[np.float64]:
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


def _viewer_order(model: BasisModel) -> tuple[list[int], NDArray[np.float64]]:
    """The project's term of each viewer term, and its sign (:data:`VIEWER_TERMS`)."""
    return [index for index, _ in VIEWER_TERMS[model]], np.array(
        [sign for _, sign in VIEWER_TERMS[model]]
    )


def _design(model: BasisModel, lights: NDArray[np.float64]) -> NDArray[np.float64]:
    """The viewer's basis (T, B) at the lights (camera frame)."""
    order, signs = _viewer_order(model)
    return evaluate_basis(model, lights)[:, order] * signs


def basis_planes(
    model: BasisModel,
    levels: NDArray[np.uint8],
    lights: NDArray[np.float64],
    visible: NDArray[np.bool_],
) -> NDArray[np.float32]:
    """A band's planes (n, B, 3) float32 in the viewer's units (0..1 is 8-bit black..white).

    The least squares of :func:`processing.sample_models.bases.fit_basis` (one
    pseudo-inverse of the design, shared by every pixel), without the leave-one-out errors it
    also computes and the export never reads, as one float32 matrix product: the export fits
    views of tens of megapixels, and that product is most of its time.

    Parameters
    ----------
    model : {"ptm", "hsh2", "hsh3"}
    levels : ndarray (T, n, 3), the band's 8-bit sRGB values 0..255
    lights : ndarray (T, 3), the measured directions, camera frame
    visible : ndarray (n,) of bool: the others are black (every coefficient 0)
    """
    t_count, count, _ = levels.shape
    order, signs = _viewer_order(model)
    solve = np.linalg.pinv(evaluate_basis(model, lights))[order] * signs[:, None] / 255.0
    flat = np.ascontiguousarray(levels, dtype=np.float32).reshape(t_count, -1)
    planes = (solve.astype(np.float32) @ flat).reshape(-1, count, 3).transpose(1, 0, 2)
    planes = np.ascontiguousarray(planes)
    planes[~visible] = 0.0
    return planes


def write_basis(
    folder: Path,
    model: BasisModel,
    store: PlaneStore,
    lights: NDArray[np.float64],
    layout: Layout,
    probe: Probe,
    seconds: float,
) -> WebModelExport:
    """Quantise one model's planes, write them and then ``info.json``; measure the errors."""
    count = terms(model)
    low, span = store.ranges()
    files = []
    exact = np.empty((len(probe.pixels), count, 3), np.float64)
    for j in range(count):
        values = store.image(j)
        exact[:, j] = values[probe.pixels]
        picture = quantise(values, low[j], span[j]).reshape(layout.height, layout.width, 3)
        del values  # one image of a large view at a time
        files.append(write_plane(folder, f"plane_{j}", picture, layout))
    flat_low, flat_span = low.reshape(-1), span.reshape(-1)
    info = {
        "width": layout.width,
        "height": layout.height,
        "format": layout.image_format,
        "type": _INFO_TYPE[model],
        "colorspace": "rgb",
        "lights": [round(float(v), 6) for v in lights.reshape(-1)],
        "nplanes": count * 3,
        "quality": layout.quality,
        "materials": [
            {
                "scale": [float(s) for s in flat_span],
                "bias": [float(b) for b in -flat_low / flat_span],
            }
        ],
    }
    write_json_atomic(folder / "info.json", info)  # last: a viewer never sees a partial model
    decoded = np.stack(
        [
            stored(folder, f"plane_{j}", layout).reshape(-1, 3)[probe.pixels] / 255.0 * span[j]
            + low[j]
            for j in range(count)
        ],
        axis=1,
    )  # (S, B, 3): the viewer's (byte / 255 - bias) * scale
    design = _design(model, lights)
    rendered = np.einsum("tb,sbc->tsc", design, decoded) * 255.0
    error = rendered - np.einsum("tb,sbc->tsc", design, exact) * 255.0
    shown = np.clip(np.rint(rendered), 0.0, 255.0)
    return WebModelExport(
        model=model,
        folder=folder,
        planes=count * 3,
        files=tuple(files),
        levels=layout.levels,
        rms_error=float(np.sqrt(np.mean(error**2))) if error.size else 0.0,
        max_error=float(np.abs(error).max()) if error.size else 0.0,
        psnr=psnr_levels(shown, probe.levels) if shown.size else float("inf"),
        seconds=seconds,
    )

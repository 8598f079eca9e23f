"""Shadow marks between measured lights, interpolated as signed distances to their edges.

A pixel field's shadow marks (1 lit, 0 shadowed, per pixel and measured light) are known at
the measured lights only. Blending the marks of the lights around a requested one (the
barycentric weights) fades a moving shadow out at each measured position and in at none: up
to three ghosts, each partly dark, none quite where the shadow is. Blending each mark image's signed
distance to its shadow's edge instead moves the edge: where a shadow slides by less than its
width between two lights, the blend of the distances puts the edge between its two measured
positions, as morphing by distance fields does. Where it moves further than it is wide, or
turns about its occluder (a high light between lights on opposite sides), the blended
distance loses it, and the faded marks were nearer.

So the two are mixed per pixel by how each, with the shading it darkens, predicted the
measured images from the other lights (leave one light out; :func:`distance_share` makes the
two errors a weight). On the path-traced 49-light domes (``rig sim rti``), the ``relief``
rung's PSNR at 20 test lights rose 0.03-2.7 dB on eight of nine scenes and fell 0.3 dB on the
ninth, a brushed knot (``docs/evaluation.md``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError

__all__ = ["distance_marks", "distance_share", "mark_distances"]


def mark_distances(lit: NDArray[np.floating], shape: tuple[int, int]) -> NDArray[np.float32]:
    """Each light's signed distance from every pixel to the edge of its shadow marks.

    Parameters
    ----------
    lit : ndarray, shape (T, H * W), 1 lit, 0 shadowed (0.5 and above counts as lit)
    shape : (H, W), the image the marks lie on

    Returns
    -------
    ndarray, shape (T, H * W), float32, pixels: positive where lit, negative in shadow, +-0.5
    at the pixels either side of an edge; a light with no edge (all lit, all shadowed) is the
    image's diagonal from one everywhere, with its sign
    """
    # scipy's exact Euclidean distance transform: the well-kept one, faster than a hand loop.
    from scipy.ndimage import distance_transform_edt

    marks = np.asarray(lit)
    if marks.ndim != 2 or marks.shape[1] != shape[0] * shape[1]:
        raise InputError(f"shadow marks {marks.shape} do not lie on an image of {shape}")
    lights = marks.reshape(len(marks), *shape) >= 0.5
    far = float(np.hypot(*shape))
    out = np.empty(lights.shape, dtype=np.float32)
    for t, image in enumerate(lights):
        if image.all() or not image.any():
            out[t] = far if image.all() else -far
            continue
        out[t] = np.where(
            image, distance_transform_edt(image) - 0.5, 0.5 - distance_transform_edt(~image)
        )
    return out.reshape(marks.shape)


def distance_marks(distances: NDArray[np.floating]) -> NDArray[np.float32]:
    """Marks (0..1) of signed distances (:func:`mark_distances`), one pixel of soft edge."""
    return np.clip(0.5 + np.asarray(distances, dtype=np.float32), 0.0, 1.0)


def distance_share(
    error_faded: NDArray[np.floating], error_moved: NDArray[np.floating]
) -> NDArray[np.float32]:
    """Per pixel, how far to trust the blended distances over the blended marks.

    Parameters
    ----------
    error_faded, error_moved : ndarray, shape (P,), each pixel's squared error when every
        measured light is predicted from the others (leave one light out) with the blended
        marks and with the blended distances (:func:`distance_marks`)

    Returns
    -------
    ndarray, shape (P,), float32, 0..1: the faded marks' part of the two errors (0.5 where
    both are exact), the weight of the distances
    """
    faded = np.asarray(error_faded, dtype=np.float64)
    moved = np.asarray(error_moved, dtype=np.float64)
    if faded.shape != moved.shape:
        raise InputError(f"errors of the two blends differ in shape: {faded.shape}, {moved.shape}")
    total = faded + moved
    share = np.divide(faded, total, out=np.full_like(total, 0.5), where=total > 0)
    return share.astype(np.float32)

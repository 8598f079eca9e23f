"""Cast shadows between the measured lights, from a relief's heights fitted to its shadows.

A pixel field's shadow marks (``lit`` of a parametric fit, :mod:`processing.sample_models`)
are known at the measured lights only. Relighting between them interpolates the marks, so a
shadow that moves between two lights comes out as two half shadows. On the path-traced matte
relief with 49 lights (``rig sim rti``), the test lights at 15 degrees, where shadows are long,
scored 20.8 dB against 32.4 dB at the others; with the true marks at the test lights the model
+ residual would score 29.3 dB instead of 23.5 (``docs/evaluation.md``).

Here the surface seen by the camera is taken as a height field h (pixels, in pixel units,
the camera distant and looking down its z axis). A pixel p is shadowed from a light whose
direction makes the slope s = d_z / |d_xy| with the image plane when something along the
ray toward the light rises faster: max_t (h(p + t u) - h(p)) / t > s, u the light's
direction in the image. :func:`relief_heights` fits h to the measured marks (gradient
descent on a logistic loss of that horizon test, PyTorch); :func:`relief_visibility` casts
its shadows for any light, softened by :data:`EDGE_SPREAD_PX` of position error at the
edges (a hard edge one pixel off costs more than a soft one, on 8-bit errors).

The fitted heights are what explains the shadows, not a measurement of shape: occluders out
of the camera's sight or surfaces that are not height fields (an overhang) are outside the
model, so the rung built on it (``relief``, :mod:`render.prediction_methods`) is chosen by
held-out error like every other.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numba
import numpy as np
from numpy.typing import NDArray

from core.directions import farthest_point_order
from core.errors import InputError, NotApplicable

__all__ = [
    "DECISIVE_TRAVEL",
    "EDGE_SPREAD_PX",
    "FIT_STEPS",
    "MAX_FIT_LIGHTS",
    "MAX_FIT_PIXELS",
    "RAY_OFFSETS",
    "TRUSTED_DISAGREEMENT",
    "despeckled",
    "relief_contradictions",
    "relief_disagreement",
    "relief_heights",
    "relief_visibility",
    "shadow_travel",
]

#: Distances (pixels) along the ray toward the light where the horizon is looked for: dense
#: near the pixel, where the edges of short shadows are, sparser far away.
RAY_OFFSETS = np.concatenate(
    [np.arange(1, 13), np.arange(14, 31, 2), np.arange(34, 71, 4), np.arange(78, 127, 8)]
).astype(np.float64)
#: Gradient steps of the fit (about 0.025 s each for 9,000 pixels and 49 lights on 2 cores).
FIT_STEPS = 200
#: Larger images are fitted at a coarser scale (heights scaled back up): the cost and the
#: memory (4 bytes per pixel, light and ray offset) are per pixel.
MAX_FIT_PIXELS = 20_000
#: More lights are fitted through this many spread over them: the cost is per light too, and a
#: dense dome's neighbouring shadows say little more about the heights.
MAX_FIT_LIGHTS = 100
#: Position error (pixels) of a cast shadow's edge that visibility is softened by.
EDGE_SPREAD_PX = 1.0
#: A pixel whose measured marks the relief contradicts at more than this share of its lights
#: is not a height field's (an overhang, a brushed highlight read as shadow): its shadows
#: between lights stay interpolated (see :func:`relief_disagreement`).
TRUSTED_DISAGREEMENT = 0.1
#: Shadow travel (:func:`shadow_travel`, pixels per pixel of height) above which a relief's
#: shadow beats interpolated marks: the relief's edges are a pixel or two off, the marks' half
#: shadows as wide as the travel. Path-traced 49-light domes, 20 test lights at 15, 45 and 75
#: degrees (travel 2.5-94, 0.5-0.9, under 0.5): the relief everywhere lost 0.2-3 dB at 45.
DECISIVE_TRAVEL = 1.0
#: A pixel this far (visibility) above or below all eight neighbours is lone (:func:`despeckled`).
LONE_STEP = 0.25
#: Lights whose direction is this close to the normal's plane (cosine) say nothing of shadows.
GRAZING_COSINE = 0.05
_LEARNING_RATE, _SMOOTHNESS = 0.3, 0.01
#: Lights whose rays are searched at once (the index is 4 bytes per pixel, light and offset).
_RAY_CHUNK = 16
_SHARPNESS_START, _SHARPNESS_END = 0.3, 0.03


def _image_rays(directions: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Unit steps (Q, 2) (column, row) toward each light in the image, and slopes (Q,)."""
    flat = np.hypot(directions[:, 0], directions[:, 1])
    safe = np.where(flat > 1e-9, flat, 1.0)
    # Camera frame: x right, y up; image rows grow downward.
    steps = np.stack([directions[:, 0] / safe, -directions[:, 1] / safe], axis=1)
    slopes = np.where(flat > 1e-9, directions[:, 2] / safe, np.inf)
    return steps, slopes


def _ray_index(
    shape: tuple[int, int],
    visible: NDArray[np.bool_],
    pixels: NDArray[np.int64],
    steps: NDArray[np.float64],
) -> NDArray[np.int32]:
    """Flat index (P, Q, K) of the visible pixel at each ray offset toward each light.

    ``steps`` (Q, 2) are the lights' unit steps in the image; the pixels are the nearest at
    each of :data:`RAY_OFFSETS`. Where the ray has left the object the index is ``H * W``,
    an extra height far below every other.
    """
    rows, cols = np.divmod(pixels, shape[1])
    index = np.full((len(pixels), len(steps), len(RAY_OFFSETS)), shape[0] * shape[1], np.int32)
    for q, step in enumerate(steps):
        c = np.rint(cols[:, None] + RAY_OFFSETS[None, :] * step[0]).astype(np.int64)
        r = np.rint(rows[:, None] + RAY_OFFSETS[None, :] * step[1]).astype(np.int64)
        inside = (c >= 0) & (c < shape[1]) & (r >= 0) & (r < shape[0])
        flat = np.where(inside, r * shape[1] + c, 0)
        index[:, q] = np.where(inside & visible.ravel()[flat], flat, index[:, q])
    return index


def _horizons(
    height: NDArray[np.float32], index: NDArray[np.int32], pixels: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.float32]]:
    """Each ray's highest occluder (P, Q) and its distance (P, Q), pixels.

    ``height`` holds the H * W heights and, last, the one far below every other that the
    rays leaving the object point at.
    """
    occluder = np.zeros(index.shape[:2], dtype=np.int64)
    distance = np.zeros(index.shape[:2], dtype=np.float32)
    inverse = (1.0 / RAY_OFFSETS).astype(np.float32)
    _highest_occluders(height, index, pixels, inverse, occluder, distance)
    return occluder, distance


def _informative(
    normals: NDArray[np.float64], directions: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """(P, T): the lights not grazing each pixel's tangent plane, whose marks say something."""
    return (normals @ directions.T) > GRAZING_COSINE


@numba.njit(parallel=True, cache=True)
def _highest_occluders(
    height: NDArray[np.float32],
    index: NDArray[np.int32],
    pixels: NDArray[np.int64],
    inverse: NDArray[np.float32],
    occluder: NDArray[np.int64],
    distance: NDArray[np.float32],
) -> None:
    # For each pixel and light, the point along the ray (index (P, T, K)) that rises fastest
    # above the pixel, and its distance: numba, as the rises of every ray at once would be
    # (P, T, K) floats a step.
    for p in numba.prange(index.shape[0]):
        own = height[pixels[p]]
        for t in range(index.shape[1]):
            best, at = -np.inf, 0
            for k in range(index.shape[2]):
                rise = (height[index[p, t, k]] - own) * inverse[k]
                if rise > best:
                    best, at = rise, k
            occluder[p, t] = index[p, t, at]
            distance[p, t] = 1.0 / inverse[at]


def relief_heights(
    lit: NDArray[np.integer],
    normals: NDArray[np.floating],
    directions: NDArray[np.floating],
    visible: NDArray[np.bool_],
    *,
    steps: int = FIT_STEPS,
    threads: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> NDArray[np.float32]:
    """Heights of the surface whose cast shadows best match the measured shadow marks.

    More than :data:`MAX_FIT_LIGHTS` lights (above the horizon) are fitted through that many,
    spread over them (farthest-point order), as a larger image is fitted coarser.

    Parameters
    ----------
    lit : ndarray, shape (H * W, T), 1 lit (or unknown), 0 shadowed, per pixel and light
    normals : ndarray, shape (H * W, 3), unit normals in the camera frame (x right, y up,
        z toward the camera): a light nearly in a pixel's tangent plane says nothing of it
    directions : ndarray, shape (T, 3), unit vectors toward the lights, camera frame
    visible : ndarray, shape (H, W), bool, the pixels of the object
    steps : int, gradient steps
    threads : int, optional, PyTorch's CPU threads (default: the idle cores)
    progress : callable (step, steps), optional

    Returns
    -------
    ndarray, shape (H, W), float32, heights in pixel units (0 outside ``visible``; 0
    everywhere when no measured light casts a shadow: a flat relief explains that)

    Raises
    ------
    NotApplicable
        PyTorch is missing.
    InputError
        Shapes that do not agree.
    """
    try:
        import torch
    except ImportError:
        raise NotApplicable("relief shadows: PyTorch is not installed") from None
    from processing.network_training import adam, idle_cores

    mask = np.asarray(visible, dtype=bool)
    marks = np.asarray(lit)
    d = np.asarray(directions, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    if mask.ndim != 2 or marks.shape != (mask.size, len(d)) or n.shape != (mask.size, 3):
        raise InputError(
            f"relief heights: marks {marks.shape}, normals {n.shape} and lights {d.shape} do "
            f"not fit an image of {mask.shape}"
        )
    scale = max(1, math.ceil(math.sqrt(mask.sum() / MAX_FIT_PIXELS)))
    if scale > 1:
        mask, marks, n = _coarser(mask, marks, n, scale)
    shape = (mask.shape[0], mask.shape[1])
    pixels = np.flatnonzero(mask)
    ray, slope = _image_rays(d)
    lights = np.flatnonzero(np.isfinite(slope) & (d[:, 2] > 0))
    lights = np.sort(lights[farthest_point_order(d[lights])[:MAX_FIT_LIGHTS]])
    informative = _informative(n[pixels], d[lights])
    target = marks[pixels][:, lights] >= 0.5
    shadowed = informative & ~target
    if len(pixels) == 0 or not shadowed.any():
        return np.zeros(np.shape(visible), dtype=np.float32)
    torch.set_num_threads(threads or idle_cores())
    index = _ray_index(shape, mask, pixels, ray[lights])
    missing = mask.size  # the extra height the rays that leave the object point at
    slopes = torch.from_numpy(slope[lights]).float()
    goal = torch.from_numpy(target.astype(np.float32))
    # Shadows are rare: weigh them up (square root of the imbalance) so they are not ignored.
    up = math.sqrt(max(float(informative.sum() - shadowed.sum()), 1.0) / float(shadowed.sum()))
    weight = torch.from_numpy(np.where(shadowed, up, 1.0) * informative).float()
    own = torch.from_numpy(pixels)
    height = torch.zeros(mask.size + 1)
    height[missing] = -1e4
    height.requires_grad_(True)
    optimiser = adam([{"params": [height], "lr": _LEARNING_RATE}])
    grid = mask.astype(np.float32)
    neighbours = (
        torch.from_numpy(grid[1:] * grid[:-1]),
        torch.from_numpy(grid[:, 1:] * grid[:, :-1]),
    )
    for step in range(steps):
        sharpness = max(_SHARPNESS_START * (1 - step / steps), _SHARPNESS_END)
        # The highest rise along each ray; only its occluder carries the gradient.
        occluder, distance = _horizons(height.detach().numpy(), index, pixels)
        optimiser.zero_grad()
        horizon = (height[torch.from_numpy(occluder)] - height[own][:, None]) / torch.from_numpy(
            distance
        )
        logit = (slopes[None, :] - horizon) / sharpness  # > 0: lit
        loss = (
            torch.nn.functional.binary_cross_entropy_with_logits(
                logit, goal, weight=weight, reduction="sum"
            )
            / weight.sum()
        )
        image = height[:-1].view(shape)
        smooth = ((image[1:] - image[:-1]).abs() * neighbours[0]).mean() + (
            (image[:, 1:] - image[:, :-1]).abs() * neighbours[1]
        ).mean()
        (loss + _SMOOTHNESS * smooth).backward()  # type: ignore[no-untyped-call]
        optimiser.step()
        with torch.no_grad():
            height[missing] = -1e4
        if progress is not None:
            progress(step + 1, steps)
    fitted = height.detach()[:-1].numpy().reshape(shape) * mask
    if scale > 1:
        fitted = _finer(fitted, scale, np.asarray(visible, dtype=bool))
    return fitted.astype(np.float32)


def relief_visibility(
    heights: NDArray[np.floating],
    directions: NDArray[np.floating],
    visible: NDArray[np.bool_],
    *,
    spread: float = EDGE_SPREAD_PX,
) -> NDArray[np.float32]:
    """Visibility of each pixel's lights in the relief ``heights``: its cast shadows.

    Parameters
    ----------
    heights : ndarray, shape (H, W), pixel units (:func:`relief_heights`)
    directions : ndarray, shape (Q, 3), unit vectors toward the lights, camera frame
    visible : ndarray, shape (H, W), bool, the pixels of the object (the only occluders)
    spread : float, pixels: each edge is softened over this position error along the light

    Returns
    -------
    ndarray, shape (H * W, Q), float32, 1 lit, 0 shadowed (1 outside ``visible``; 0 for a
    light below the image plane)
    """
    import cv2  # opencv's warp: sub-pixel shifts of a mark image, with its border rule

    h = np.asarray(heights, dtype=np.float64)
    mask = np.asarray(visible, dtype=bool)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    if h.shape != mask.shape or h.ndim != 2:
        raise InputError(f"relief heights {h.shape} and visible pixels {mask.shape} differ")
    shape = (h.shape[0], h.shape[1])
    pixels = np.flatnonzero(mask)
    flat = np.append(h.ravel(), -1e4).astype(np.float32)
    ray, slope = _image_rays(d)
    out = np.ones((len(d), *shape), dtype=np.float32)
    out[:, mask] = (d[:, 2] > 0.0).astype(np.float32)[:, None]
    # Straight overhead a height field shadows nothing; a few lights' rays at a time.
    cast = np.flatnonzero(np.isfinite(slope) & (d[:, 2] > 0.0))
    for start in range(0, len(cast), _RAY_CHUNK):
        chunk = cast[start : start + _RAY_CHUNK]
        occluder, distance = _horizons(flat, _ray_index(shape, mask, pixels, ray[chunk]), pixels)
        rise = (flat[occluder] - flat[pixels][:, None]) / distance
        out[chunk[:, None], *np.divmod(pixels, shape[1])] = (rise <= slope[chunk]).T
    if spread > 0:
        for q in cast:
            soft = 0.5 * out[q]
            for sign in (-1.0, 1.0):
                shift = np.array(
                    [[1, 0, sign * spread * ray[q, 0]], [0, 1, sign * spread * ray[q, 1]]],
                    dtype=np.float32,
                )
                soft += 0.25 * cv2.warpAffine(
                    out[q],
                    shift,
                    (shape[1], shape[0]),
                    flags=cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE,
                )
            out[q] = np.where(mask, soft, 1.0)
    return np.ascontiguousarray(out.reshape(len(d), -1).T)


def _coarser(
    mask: NDArray[np.bool_], marks: NDArray[np.integer], normals: NDArray[np.float64], scale: int
) -> tuple[NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64]]:
    """Blocks of ``scale`` x ``scale`` pixels: visible if any is, marks and normals averaged."""
    rows, cols = -(-mask.shape[0] // scale), -(-mask.shape[1] // scale)
    pad = ((0, rows * scale - mask.shape[0]), (0, cols * scale - mask.shape[1]))

    def blocks(values: NDArray[np.floating]) -> NDArray[np.float64]:
        grid = values.reshape(*mask.shape, -1) * mask[..., None]
        grid = np.pad(grid, (*pad, (0, 0)))
        return grid.reshape(rows, scale, cols, scale, -1).sum(axis=(1, 3)).reshape(rows * cols, -1)

    count = blocks(np.ones((mask.size, 1)))[:, 0]
    safe = np.maximum(count, 1.0)[:, None]
    coarse_marks = blocks(marks.astype(np.float64)) / safe
    coarse_normals = blocks(normals) / safe
    length = np.linalg.norm(coarse_normals, axis=1, keepdims=True)
    coarse_normals = np.divide(
        coarse_normals, length, out=np.zeros_like(coarse_normals), where=length > 0
    )
    return (count > 0).reshape(rows, cols), coarse_marks, coarse_normals


def _finer(
    heights: NDArray[np.floating], scale: int, mask: NDArray[np.bool_]
) -> NDArray[np.float64]:
    """Coarse heights back at the image's pixels, in its pixel units (``scale`` times larger)."""
    import cv2

    size = (heights.shape[1] * scale, heights.shape[0] * scale)
    fine = cv2.resize(np.asarray(heights, dtype=np.float32), size, interpolation=cv2.INTER_LINEAR)
    return fine[: mask.shape[0], : mask.shape[1]].astype(np.float64) * scale * mask


def shadow_travel(
    requested: NDArray[np.floating], measured: NDArray[np.floating], used: NDArray[np.bool_]
) -> NDArray[np.float64]:
    """How far a shadow moves between a requested light and the measured lights around it.

    A point ``h`` above its surroundings casts its shadow ``h`` times the light's (x, y) / z
    away; the travel is the largest change of that vector to a measured light the requested
    one is interpolated from: the shadow's move per unit of occluder height.

    Parameters
    ----------
    requested : ndarray, shape (Q, 3), unit vectors toward the requested lights, camera frame
    measured : ndarray, shape (Q, k, 3), the measured lights each one is interpolated from
    used : ndarray, shape (Q, k), bool, which of the k take part (a weight above 0)

    Returns
    -------
    ndarray, shape (Q,), float64, pixels of shadow per pixel of height (0 where none takes
    part; large toward the horizon)
    """
    q = np.asarray(requested, dtype=np.float64)
    m = np.asarray(measured, dtype=np.float64)
    floor = np.sin(np.radians(0.5))  # a light on the horizon casts an endless shadow
    offset = q[:, :2] / np.maximum(q[:, 2:3], floor)
    around = m[..., :2] / np.maximum(m[..., 2:3], floor)
    moves = np.linalg.norm(around - offset[:, None, :], axis=2)
    return np.max(np.where(used, moves, 0.0), axis=1, initial=0.0)


def relief_contradictions(
    heights: NDArray[np.floating],
    lit: NDArray[np.integer],
    normals: NDArray[np.floating],
    directions: NDArray[np.floating],
    visible: NDArray[np.bool_],
) -> NDArray[np.int8]:
    """Which measured marks the relief's cast shadows reproduce, per pixel and light.

    Parameters
    ----------
    heights : ndarray, shape (H, W), the relief (:func:`relief_heights`)
    lit, normals, directions, visible : as :func:`relief_heights` takes them

    Returns
    -------
    ndarray, shape (H * W, T), int8: 1 the relief's shadow contradicts the mark, 0 it
    reproduces it, -1 the light says nothing of the pixel's shadows (nearly in its tangent
    plane, or below the image plane)
    """
    cast = relief_visibility(heights, directions, visible, spread=0.0)
    informative = _informative(
        np.asarray(normals, dtype=np.float64), np.asarray(directions, dtype=np.float64)
    )
    wrong = (cast >= 0.5) != (np.asarray(lit) >= 0.5)
    return np.where(informative, wrong, -1).astype(np.int8)


def relief_disagreement(contradictions: NDArray[np.int8]) -> NDArray[np.float32]:
    """Share of each pixel's informative lights whose mark the relief contradicts.

    Parameters
    ----------
    contradictions : ndarray, shape (H * W, T), int8, of :func:`relief_contradictions`

    Returns
    -------
    ndarray, shape (H * W,), float32, 0..1 (0 where no light says anything of the pixel)
    """
    said = np.maximum((contradictions >= 0).sum(axis=1), 1)
    return ((contradictions == 1).sum(axis=1) / said).astype(np.float32)


def despeckled(
    visibility: NDArray[np.float32], near: NDArray[np.bool_], shape: tuple[int, int]
) -> NDArray[np.float32]:
    """Each light's visibility image with lone pixels taken by their neighbours.

    The relief's shadow and the interpolated marks are chosen per pixel (its trust, its
    marks), so a shadow could hold lone lit pixels, seen at once by a user. A pixel next to
    where the relief decides whose eight neighbours all lie more than :data:`LONE_STEP` on
    one side of it takes the 3 x 3 median. Only lone pixels: a median everywhere lost the
    copper bowl's rim detail (0.5 dB), and next to the relief's shadows the lion's (0.33 dB).

    Parameters
    ----------
    visibility : ndarray, shape (H * W, Q), float32, 1 lit, 0 shadowed
    near : ndarray, shape (H * W, Q), bool, the pixels and lights where the relief decides
    shape : (H, W)

    Returns
    -------
    ndarray, shape (H * W, Q), float32
    """
    if not near.any():
        return visibility
    # scipy's image filters: the well-kept median, neighbourhood extremes and dilation.
    from scipy.ndimage import binary_dilation, maximum_filter, median_filter, minimum_filter

    images = visibility.reshape(*shape, -1)
    ring = np.ones((3, 3, 1), dtype=bool)
    beside = binary_dilation(near.reshape(*shape, -1), ring).reshape(near.shape)
    ring[1, 1, 0] = False
    highest = maximum_filter(images, footprint=ring, mode="nearest").reshape(visibility.shape)
    lowest = minimum_filter(images, footprint=ring, mode="nearest").reshape(visibility.shape)
    lone = beside & ((highest < visibility - LONE_STEP) | (lowest > visibility + LONE_STEP))
    smooth = median_filter(images, size=(3, 3, 1), mode="nearest").reshape(visibility.shape)
    return np.where(lone, smooth, visibility)

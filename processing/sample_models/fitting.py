"""Fitting a field's per-sample models: :func:`fit_sample_models`.

:func:`fit_sample_models` checks the request, fits the linear bases, finds the starting normals
and runs the parametric kernel over memory-bounded chunks of samples.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from core.camera_model import rig_to_camera
from core.errors import DatasetError, InputError
from core.field_store import ReflectanceField
from processing.sample_models.bases import fit_basis
from processing.sample_models.fit_kernel import fit_samples
from processing.sample_models.fits import (
    BASIS_MODELS,
    MODELS,
    PARAMETRIC_MODELS,
    Fit,
    ModelName,
    ParametricFit,
    ParametricModelName,
    SampleModels,
)
from processing.sample_models.loo import LooError, leave_one_out_weights
from processing.sample_models.stereo import photometric_stereo

__all__ = ["ALPHA_RANGE", "fit_sample_models"]

#: GGX roughness searched (a lobe narrower than 0.02 is a mirror no rig samples).
ALPHA_RANGE = (0.02, 1.0)
#: Log-spaced alpha grid nodes, then golden-section steps between the best node's neighbours.
ALPHA_GRID = 16
GOLDEN_STEPS = 14
#: A light whose best model scale k_t is below this is shadowed for that sample.
SHADOW_RATIO = 0.5
#: Fits of the fit / shadow-mark alternation, at most.
SHADOW_ITERATIONS = 4
#: Normal refinement: first step and smallest step (radians) of the pattern search.
REFINE_STEP, REFINE_MIN_STEP = 0.08, 0.002
#: Bytes of radiance held in memory while fitting: the whole field in its storage dtype when it
#: fits (one pass over the store), else float32 chunks of samples (one pass per chunk).
FIT_MEMORY_BYTES = 6 << 30


def fit_sample_models(
    field: ReflectanceField,
    models: Sequence[str] | None = None,
    *,
    alpha_range: tuple[float, float] = ALPHA_RANGE,
    shadow_ratio: float = SHADOW_RATIO,
    refine_normals: bool | None = None,
    memory_bytes: int = FIT_MEMORY_BYTES,
    progress: bool = False,
) -> SampleModels:
    """Fit per-sample models to every sample of a field and score them by leave-one-light-out.

    Parameters
    ----------
    field : ReflectanceField
        Points (S cameras, stored normals) or the pixels of one view (RTI).
    models : sequence of str, optional
        Models to fit (``MODELS``; typed str, not ``ModelName``, because callers pass names
        read from saved fits and settings, checked here); default ``lambert`` and
        ``lambert+ggx`` for points, every model for pixels. Basis models apply to pixel fields
        only.
    alpha_range : (low, high), GGX roughness searched
    shadow_ratio : float in (0, 1), see :mod:`processing.sample_models` (Shadows)
    refine_normals : bool, optional
        Move each normal to the parametric model's optimum (pattern search). Default: on for
        pixel fields (their normals come from photometric stereo), off for point fields.
    memory_bytes : int, radiance held in memory at once (see ``FIT_MEMORY_BYTES``)
    progress : bool, show a progress bar over the chunks

    Returns
    -------
    SampleModels

    Raises
    ------
    InputError
        An unknown model, a basis model for a point field, bad ranges, too few lights.
    DatasetError
        A point field without normals.
    """
    names = _check_models(field, models)
    if not 0.0 < shadow_ratio < 1.0:
        raise InputError(f"shadow ratio must be in (0, 1), got {shadow_ratio}")
    grid = _alpha_grid(alpha_range)
    if field.shape[1] < 2:
        raise InputError(f"{field.path}: fitting needs at least 2 lights, the field has 1")
    lights = np.ascontiguousarray(field.light_directions, dtype=np.float64)
    frame, view, eyes, points = _viewing(field)
    fits: dict[str, Fit] = {}
    if field.sample_kind == "pixels":
        assert view is not None
        slab = field.camera_slab(0)
        for name in names:
            if name in BASIS_MODELS:
                fits[name] = fit_basis(name, slab, lights @ frame.T)
        start_normals = (
            field.normals.astype(np.float64)
            if field.normals is not None
            else photometric_stereo(slab, lights, view)
        )
    else:
        assert field.normals is not None
        start_normals = field.normals.astype(np.float64)
    parametric = [n for n in names if n in PARAMETRIC_MODELS]
    if parametric:
        refine = field.sample_kind == "pixels" if refine_normals is None else refine_normals
        fitted = _fit_parametric(
            field, parametric, start_normals, eyes, points, grid,
            refine=refine, shadow_ratio=shadow_ratio, memory_bytes=memory_bytes, progress=progress,
        )  # fmt: skip
        fits.update(fitted)
    return SampleModels(
        kind=field.sample_kind,
        light_directions=lights,
        camera_frame=frame,
        view_direction=view,
        points=points,
        fits={name: fits[name] for name in names},
        sample_count=field.shape[2],
    )


def _check_models(field: ReflectanceField, models: Sequence[str] | None) -> tuple[ModelName, ...]:
    """The models to fit, in the order named (default: by the field's kind).

    InputError for an empty list, an unknown model, a basis model of a point field or a
    repeated name.
    """
    if models is None:
        return PARAMETRIC_MODELS if field.sample_kind == "points" else MODELS
    names = tuple(models)
    if not names:
        raise InputError("no models to fit; name at least one of " + ", ".join(MODELS))
    checked: list[ModelName] = []
    for name in names:
        if name not in MODELS:
            raise InputError(f"unknown model {name!r}; use one of {', '.join(MODELS)}")
        if name in BASIS_MODELS and field.sample_kind == "points":
            raise InputError(
                f"model {name!r} is a basis over the light direction at one fixed view; "
                f"{field.path} holds surface points seen from {field.shape[0]} cameras: use "
                f"{' or '.join(PARAMETRIC_MODELS)}"
            )
        checked.append(name)
    if len(set(names)) != len(names):
        raise InputError(f"models are named more than once: {names}")
    return tuple(checked)


def _alpha_grid(alpha_range: tuple[float, float]) -> NDArray[np.float64]:
    """The log-spaced alpha nodes (ALPHA_GRID,) the kernel searches first."""
    low, high = alpha_range
    if not 0.0 < low < high <= 1.0:
        raise InputError(f"alpha range must satisfy 0 < low < high <= 1, got {alpha_range}")
    return np.geomspace(low, high, ALPHA_GRID)


def _viewing(
    field: ReflectanceField,
) -> tuple[
    NDArray[np.float64], NDArray[np.float64] | None, NDArray[np.float64], NDArray[np.float64] | None
]:
    """Camera frame (3, 3), distant view (3,) or None, eyes (S, 3) and points (P, 3) or None.

    Pixel fields: the rows of ``frame`` are the camera's x, y, z in the rig frame, the view is
    the camera direction and the one "eye" is that direction (the camera is distant). Point
    fields: identity frame, no view, the camera positions, the sample points.
    """
    camera = field.cameras[0]
    if field.sample_kind == "pixels":
        if field.shape[0] != 1:
            raise DatasetError(
                f"{field.path}: a pixel field has one camera, found {field.shape[0]}"
            )
        frame = np.ascontiguousarray(rig_to_camera(np.eye(3), camera).T)
        view = np.asarray(camera.direction, dtype=np.float64)
        return frame, view, view[None, :].copy(), None
    if field.points is None or field.normals is None:
        raise DatasetError(f"{field.path}: a point field needs points and normals to fit")
    eyes = np.stack([c.position for c in field.cameras]).astype(np.float64)
    return np.eye(3), None, eyes, field.points.astype(np.float64)


def _fit_parametric(
    field: ReflectanceField,
    names: list[ParametricModelName],
    start_normals: NDArray[np.float64],
    eyes: NDArray[np.float64],
    points: NDArray[np.float64] | None,
    grid: NDArray[np.float64],
    *,
    refine: bool,
    shadow_ratio: float,
    memory_bytes: int,
    progress: bool,
) -> dict[str, ParametricFit]:
    """The parametric fits ``names``, chunk by chunk of samples (see fit_sample_models)."""
    s_count, t_count, p_count = field.shape
    pixels = field.sample_kind == "pixels"
    lights = np.ascontiguousarray(field.light_directions, dtype=np.float64)
    loo_indices, loo_weights = leave_one_out_weights(lights)
    whole = _sample_major(field, memory_bytes)
    # float32 chunks beside the stored copy: half the budget when the copy is in memory.
    budget = memory_bytes // 2 if whole is not None else memory_bytes
    chunk = max(1, min(p_count, int(budget // (s_count * t_count * 3 * 4))))
    outputs: dict[str, dict[str, NDArray[Any]]] = {
        name: {
            "normal": np.zeros((p_count, 3)),
            "x1": np.zeros((p_count, 3)),
            "x2": np.zeros((p_count, 3)),
            "alpha": np.ones(p_count),
            "lit": np.ones((p_count, t_count), dtype=np.float32),
            "loo": np.zeros(p_count),
            "energy": np.zeros(p_count),
            "fitted": np.zeros(p_count, dtype=bool),
        }
        for name in names
    }
    steps = np.array([REFINE_STEP, REFINE_MIN_STEP])
    for start in tqdm(range(0, p_count, chunk), desc="fit", unit="chunk", disable=not progress):
        stop = min(start + chunk, p_count)
        radiance = _read_chunk(field, start, stop, whole)
        seen = np.ascontiguousarray(field.visibility[:, start:stop].T)
        part = slice(start, stop)
        chunk_points = np.zeros((stop - start, 3)) if points is None else points[part].copy()
        for name in names:
            o = outputs[name]
            fit_samples(
                radiance, seen, chunk_points, np.ascontiguousarray(start_normals[part]), eyes,
                pixels, lights, loo_indices, loo_weights, grid, GOLDEN_STEPS,
                name == "lambert+ggx", refine, shadow_ratio, SHADOW_ITERATIONS, steps,
                o["normal"][part], o["x1"][part], o["x2"][part], o["alpha"][part],
                o["lit"][part], o["loo"][part], o["energy"][part], o["fitted"][part],
            )  # fmt: skip
    fits: dict[str, ParametricFit] = {}
    for name in names:
        o = outputs[name]
        lobe = name == "lambert+ggx"
        fits[name] = ParametricFit(
            name=name,
            normals=o["normal"],
            rho_d=o["x1"].astype(np.float32),
            f0=(o["x2"] if lobe else np.zeros_like(o["x2"])).astype(np.float32),
            alpha=(o["alpha"] if lobe else np.ones(p_count)).astype(np.float32),
            lit=o["lit"],
            fitted=o["fitted"],
            loo=LooError(o["loo"], o["energy"]),
            normals_fitted=refine or (pixels and field.normals is None),
        )
    return fits


def _sample_major(field: ReflectanceField, memory_bytes: int) -> NDArray[Any] | None:
    """The whole radiance as (P, S, T, 3) in its storage dtype, or None if over ``memory_bytes``.

    Read in one pass over the cameras; when it exceeds ``memory_bytes``, chunks are read one by
    one instead.
    """
    s_count, t_count, p_count = field.shape
    if s_count * t_count * p_count * 3 * field.dtype.itemsize > memory_bytes:
        return None
    out = np.empty((p_count, s_count, t_count, 3), dtype=field.dtype)
    for s in range(s_count):
        out[:, s] = field.camera_radiance(s).transpose(1, 0, 2)
    return out


def _read_chunk(
    field: ReflectanceField, start: int, stop: int, whole: NDArray[Any] | None
) -> NDArray[np.float32]:
    """Radiance of samples start..stop as (Pc, S, T, 3), float32 (one sample's values together).

    From ``whole`` (:func:`_sample_major`) when it is in memory; else read from the store,
    which decompresses every (camera, light) chunk for each sample range.
    """
    if whole is not None:
        return np.ascontiguousarray(whole[start:stop], dtype=np.float32)
    s_count, t_count, _ = field.shape
    out = np.empty((stop - start, s_count, t_count, 3), dtype=np.float32)
    for s in range(s_count):
        out[:, s] = field.camera_radiance(s, slice(start, stop)).transpose(1, 0, 2)
    return out

"""Fitting a field's per-sample models: :func:`fit_sample_models`.

:func:`fit_sample_models` checks the request, fits the linear bases, finds the starting normals
and runs the parametric kernel over memory-bounded blocks of samples, in-process or as Dask
tasks (one per block).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from core.camera_model import rig_to_camera
from core.errors import DatasetError, InputError
from core.field_store import ReflectanceField, is_field_store
from core.memory_budget import default_memory_budget, format_size
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

__all__ = ["ALPHA_RANGE", "budget_for", "fit_sample_models", "sample_block_size"]

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


def fit_sample_models(
    field: ReflectanceField,
    models: Sequence[str] | None = None,
    *,
    alpha_range: tuple[float, float] = ALPHA_RANGE,
    shadow_ratio: float = SHADOW_RATIO,
    refine_normals: bool | None = None,
    memory_bytes: int | None = None,
    client: Any = None,
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
    memory_bytes : int, optional
        Bytes of radiance held in memory at once (default
        :func:`core.memory_budget.default_memory_budget`): the field is read and fitted in
        blocks of samples (float32, every camera and light of each sample) of at most this
        size, aligned to the store's chunks. The peak is up to twice this (a block as stored
        while it is widened and reordered) plus the outputs (the fits: about 100 + T bytes
        a sample per model), whatever the field's size.
    client : distributed.Client, optional
        Fit the blocks as Dask tasks on this client's cluster (:func:`core.cluster.dask_client`;
        each worker reads its block from the store, so ``field`` must be a store on disk, not
        a subset in memory); the results are the same as in-process. ``memory_bytes`` then
        bounds each task's block.
    progress : bool, show a progress bar over the blocks

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
    budget = budget_for(memory_bytes, client)
    if client is not None and not is_field_store(field.path):
        raise InputError(
            f"{field.path}: Dask workers read their samples from a field store on disk; this "
            "field is held in memory (a subset): fit it in-process"
        )
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
            refine=refine, shadow_ratio=shadow_ratio, block=sample_block_size(field, budget),
            client=client, progress=progress,
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
    block: int,
    client: Any,
    progress: bool,
) -> dict[str, ParametricFit]:
    """The parametric fits ``names``, block by block of samples (see fit_sample_models)."""
    _, t_count, p_count = field.shape
    pixels = field.sample_kind == "pixels"
    lights = np.ascontiguousarray(field.light_directions, dtype=np.float64)
    job = _BlockJob(tuple(names), eyes, pixels, lights, *leave_one_out_weights(lights), grid,
                    refine, shadow_ratio)  # fmt: skip
    outputs = {name: _empty_outputs(p_count, t_count) for name in names}
    blocks = [(start, min(start + block, p_count)) for start in range(0, p_count, block)]

    def inputs(start: int, stop: int) -> tuple[NDArray[Any], NDArray[Any], NDArray[Any]]:
        part = slice(start, stop)
        seen = np.ascontiguousarray(field.visibility[:, part].T)
        chunk_points = np.zeros((stop - start, 3)) if points is None else points[part].copy()
        return seen, chunk_points, np.ascontiguousarray(start_normals[part])

    if client is None:
        for start, stop in tqdm(blocks, desc="fit", unit="block", disable=not progress):
            fitted = job.run(field.sample_block(start, stop), *inputs(start, stop))
            _place(outputs, fitted, slice(start, stop))
    else:
        from dask.delayed import delayed

        from core.cluster import compute_each

        tasks = [
            delayed(_fit_stored_block, pure=False)(
                str(field.path), start, stop, job, *inputs(start, stop)
            )
            for start, stop in blocks
        ]
        for index, fitted in compute_each(client, tasks, progress=progress, what="fit"):
            start, stop = blocks[index]
            _place(outputs, fitted, slice(start, stop))
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


Outputs = dict[str, NDArray[Any]]


def _empty_outputs(count: int, t_count: int) -> Outputs:
    """The kernel's output arrays for ``count`` samples, at the values of an unfitted sample."""
    return {
        "normal": np.zeros((count, 3)),
        "x1": np.zeros((count, 3)),
        "x2": np.zeros((count, 3)),
        "alpha": np.ones(count),
        "lit": np.ones((count, t_count), dtype=np.uint8),
        "loo": np.zeros(count),
        "energy": np.zeros(count),
        "fitted": np.zeros(count, dtype=bool),
    }


def _place(
    outputs: dict[ParametricModelName, Outputs],
    fitted: dict[ParametricModelName, Outputs],
    part: slice,
) -> None:
    for name, arrays in fitted.items():
        for key, values in arrays.items():
            outputs[name][key][part] = values


@dataclass(frozen=True, eq=False)
class _BlockJob:
    """What fitting a block of samples needs besides the block.

    The same for every block, so a Dask task carries it whole (it pickles: the kernel's
    arguments are plain arrays).
    """

    names: tuple[ParametricModelName, ...]
    eyes: NDArray[np.float64]
    pixels: bool
    lights: NDArray[np.float64]
    loo_indices: NDArray[np.int64]
    loo_weights: NDArray[np.float64]
    grid: NDArray[np.float64]
    refine: bool
    shadow_ratio: float

    def run(
        self,
        radiance: NDArray[np.float32],
        seen: NDArray[np.bool_],
        points: NDArray[np.float64],
        normals: NDArray[np.float64],
    ) -> dict[ParametricModelName, Outputs]:
        """Fit each model to a block; returns each model's outputs (:func:`_empty_outputs`).

        Radiance (n, S, T, 3), seen (n, S), points and starting normals (n, 3).
        """
        count, t_count = radiance.shape[0], radiance.shape[2]
        steps = np.array([REFINE_STEP, REFINE_MIN_STEP])
        result: dict[ParametricModelName, Outputs] = {}
        for name in self.names:
            o = _empty_outputs(count, t_count)
            fit_samples(
                radiance, seen, points, normals, self.eyes, self.pixels, self.lights,
                self.loo_indices, self.loo_weights, self.grid, GOLDEN_STEPS,
                name == "lambert+ggx", self.refine, self.shadow_ratio, SHADOW_ITERATIONS, steps,
                o["normal"], o["x1"], o["x2"], o["alpha"], o["lit"], o["loo"], o["energy"],
                o["fitted"],
            )  # fmt: skip
            result[name] = o
        return result


def _fit_stored_block(
    path: str,
    start: int,
    stop: int,
    job: _BlockJob,
    seen: NDArray[np.bool_],
    points: NDArray[np.float64],
    normals: NDArray[np.float64],
) -> dict[ParametricModelName, Outputs]:
    """A Dask task: read samples start..stop from the store at ``path`` and fit them."""
    field = ReflectanceField.open(path, cached_slabs=0)
    return job.run(field.sample_block(start, stop), seen, points, normals)


def budget_for(memory_bytes: int | None, client: Any) -> int:
    """Bytes of radiance per block: as asked, else the default.

    On a cluster the default is no more than a third of the smallest worker's memory limit
    (the block, its widened copy, the outputs).
    """
    if memory_bytes is not None:
        return memory_bytes
    budget = default_memory_budget()
    if client is not None:
        from core.cluster import worker_memory

        smallest = worker_memory(client)
        if smallest:
            budget = min(budget, smallest // 3)
    return budget


def sample_block_size(field: ReflectanceField, memory_bytes: int) -> int:
    """Samples per block whose float32 radiance (every camera and light) fits ``memory_bytes``.

    All the samples when they fit, else a multiple of the store's chunk when one fits, else as
    many samples as fit.

    Raises
    ------
    InputError
        ``memory_bytes`` cannot hold even one sample's radiance.
    """
    s_count, t_count, p_count = field.shape
    per_sample = s_count * t_count * 3 * 4
    samples = memory_bytes // per_sample
    if samples < 1:
        raise InputError(
            f"a memory budget of {format_size(memory_bytes)} cannot hold one sample's radiance "
            f"({format_size(per_sample)} for {s_count} cameras x {t_count} lights); allow more "
            "(--max-memory)"
        )
    if samples >= p_count:
        return p_count
    chunk = field.sample_chunk
    return int(samples - samples % chunk if samples >= chunk else samples)

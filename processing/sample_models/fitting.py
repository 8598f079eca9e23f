"""Fitting a field's per-sample models: :func:`fit_sample_models` and :func:`fit_blocks`.

:func:`fit_blocks` checks the request and, over memory-bounded blocks of samples, in-process or
as Dask tasks (one per block), fits the linear bases, finds the starting normals and runs the
parametric kernel: each block is read from the store once and fitted whole, by every model.
:func:`fit_sample_models` gathers the blocks into a :class:`SampleModels` held in memory;
:func:`processing.sample_model_store.fit_to_file` writes them to the fit file as they come, for
fields whose fits do not fit in memory (a 24-megapixel capture's five models are 13 GB). The
per-sample arrays a fit fills are named by :class:`processing.sample_models.layout.FitLayout`.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.camera_model import rig_to_camera
from core.errors import DatasetError, InputError, NotApplicable
from core.field_store import ReflectanceField, is_field_store
from core.light_set import check_measured_lights
from core.memory_budget import default_memory_budget, format_size
from core.progress import progress_bar
from processing.interpolation import mean_spacing_deg
from processing.sample_models.bases import evaluate_basis, fit_basis
from processing.sample_models.fit_kernel import fit_samples
from processing.sample_models.fits import (
    BASIS_MODELS,
    MODELS,
    PARAMETRIC_MODELS,
    ModelName,
    ParametricModelName,
    SampleModels,
)
from processing.sample_models.layout import BlockFits, FitLayout
from processing.sample_models.loo import leave_one_out_weights
from processing.sample_models.stereo import check_stereo_lights, photometric_stereo

__all__ = [
    "ALPHA_RANGE",
    "FIT_BLOCK_BYTES",
    "LOBE_SPACING",
    "budget_for",
    "fit_blocks",
    "fit_sample_models",
    "lobe_alpha_range",
    "sample_block_size",
]

#: GGX roughness searched (a lobe narrower than 0.02 is a mirror no rig samples).
ALPHA_RANGE = (0.02, 1.0)
#: A one-view field fits no lobe narrower than this fraction of its lights' mean spacing
#: (radians; :func:`lobe_alpha_range`). GGX's full width at half maximum in half vectors is
#: 1.29 alpha (small alpha) and one view's half vectors are about s / 2 apart for lights s
#: apart: a lobe with alpha < 0.39 s falls between them (measured: the package's docstring).
LOBE_SPACING = 0.4
#: Log-spaced alpha grid nodes, then golden-section steps between the best node's neighbours.
ALPHA_GRID = 16
GOLDEN_STEPS = 14
#: A light whose best model scale k_t is below this is shadowed for that sample.
SHADOW_RATIO = 0.5
#: Fits of the fit / shadow-mark alternation, at most.
SHADOW_ITERATIONS = 4
#: Normal refinement: first step and smallest step (radians) of the pattern search.
REFINE_STEP, REFINE_MIN_STEP = 0.08, 0.002
#: Largest block (bytes of float32 radiance) the default budget gives. The kernel keeps both
#: cores busy with blocks of a few thousand samples, so a larger block buys no speed, only
#: memory: the block as stored and widened, and its fits (up to 530 bytes a sample for a pixel
#: field's five models at 60 lights), are most of a fit's peak. At 60 lights 512 MiB is 745,000
#: pixels; a 24-megapixel capture fits in 33 blocks at a peak under 2 GiB (docs/scale.md).
FIT_BLOCK_BYTES = 512 << 20


def fit_sample_models(
    field: ReflectanceField,
    models: Sequence[str] | None = None,
    *,
    alpha_range: tuple[float, float] | None = None,
    shadow_ratio: float = SHADOW_RATIO,
    refine_normals: bool | None = None,
    memory_bytes: int | None = None,
    client: Any = None,
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
    alpha_range : (low, high), optional, GGX roughness searched; default
        :func:`lobe_alpha_range` of the field's lights (a one-view field's lights cannot
        resolve a lobe much narrower than their spacing)
    shadow_ratio : float in (0, 1), see :mod:`processing.sample_models` (Shadows)
    refine_normals : bool, optional
        Move each normal to the parametric model's optimum (pattern search). Default: on for
        pixel fields (their normals come from photometric stereo), off for point fields.
    memory_bytes : int, optional
        Bytes of radiance held in memory at once (default :func:`budget_for`): the field is
        read and fitted in blocks of samples (float32, every camera and light of each sample)
        of at most this size, aligned to the store's chunks; every model, the basis models and
        the photometric-stereo normals of a pixel field included, is fitted block by block.
        The peak is up to twice this (a block as stored while it is widened and reordered)
        plus the outputs (the fits: about 100 + T bytes a sample per parametric model, 12 B +
        16 bytes per basis model), whatever the field's size; :func:`fit_blocks` streams the
        outputs instead of holding them.
    client : distributed.Client, optional
        Fit the blocks as Dask tasks on this client's cluster (:func:`core.cluster.dask_client`;
        each worker reads its block from the store, so ``field`` must be a store on disk, not
        a subset in memory); the results are the same as in-process. ``memory_bytes`` then
        bounds each task's block.

    Returns
    -------
    SampleModels

    Raises
    ------
    InputError
        An unknown model, a basis model for a point field, bad ranges.
    NotApplicable
        Too few lights: for a basis model's terms, photometric stereo, or any fit.
    DatasetError
        A point field without normals; lights no fit can use
        (:func:`core.light_set.check_measured_lights`).
    """
    layout, blocks = fit_blocks(
        field, models, alpha_range=alpha_range, shadow_ratio=shadow_ratio,
        refine_normals=refine_normals, memory_bytes=memory_bytes, client=client,
    )  # fmt: skip
    arrays = {
        key: np.empty((layout.sample_count, *shape), dtype=dtype)
        for key, (dtype, shape) in layout.arrays().items()
    }
    for part, fitted in blocks:
        for key, values in fitted.items():
            arrays[key][part] = values
    return layout.models(arrays)


def fit_blocks(
    field: ReflectanceField,
    models: Sequence[str] | None = None,
    *,
    alpha_range: tuple[float, float] | None = None,
    shadow_ratio: float = SHADOW_RATIO,
    refine_normals: bool | None = None,
    memory_bytes: int | None = None,
    client: Any = None,
) -> tuple[FitLayout, Iterator[tuple[slice, BlockFits]]]:
    """The fit of :func:`fit_sample_models`, block by block of samples, for a caller to place.

    The parameters are :func:`fit_sample_models`'s; every block is fitted whole, every model
    at once (one read of the block from the store), and nothing of the field or of the other
    blocks' fits is held: a caller that writes each block out (:func:`processing.
    sample_model_store.fit_to_file`) fits a field of any size in the memory of one block.

    Returns
    -------
    layout : FitLayout
    blocks : iterator of (slice, BlockFits)
        The samples of each block and their arrays, in order of the samples in-process, as
        they finish on a cluster. The checks are made before it is returned.
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
    if field.shape[1] < 2:
        raise NotApplicable(f"{field.path}: fitting needs at least 2 lights, the field has 1")
    lights = np.ascontiguousarray(field.light_directions, dtype=np.float64)
    frame, view, eyes, points = _viewing(field)
    pixels = field.sample_kind == "pixels"
    # pinv would fit degenerate lights without a word (and a choice run minutes on them).
    check_measured_lights(field.path, lights, blocked_below=field.below_horizon == "blocked")
    if alpha_range is None:
        alpha_range = lobe_alpha_range(lights, one_view=pixels)
    grid = _alpha_grid(alpha_range)
    camera_lights = lights @ frame.T
    terms = {name: evaluate_basis(name, camera_lights[:1]).shape[1] for name in BASIS_MODELS}
    for name in names:
        if name in BASIS_MODELS and field.shape[1] <= terms[name]:
            raise NotApplicable(
                f"model {name!r} has {terms[name]} terms; it needs more than that many lights, "
                f"the field has {field.shape[1]}"
            )
    parametric = tuple(n for n in names if n in PARAMETRIC_MODELS)
    if parametric and pixels and field.normals is None:
        check_stereo_lights(field.shape[1])
    if not pixels:
        assert field.normals is not None
    refine = pixels if refine_normals is None else refine_normals
    loo_indices, loo_weights = (
        leave_one_out_weights(lights) if parametric else (np.zeros((0, 0), np.int64),
                                                          np.zeros((0, 0)))
    )  # fmt: skip
    job = _BlockJob(
        names, parametric, eyes, pixels, lights, camera_lights, view, loo_indices, loo_weights,
        grid, refine, shadow_ratio,
    )  # fmt: skip
    layout = FitLayout(
        kind=field.sample_kind,
        light_directions=lights,
        camera_frame=frame,
        view_direction=view,
        points=points,
        sample_count=field.shape[2],
        names=names,
        basis_terms={name: terms[name] for name in names if name in BASIS_MODELS},
        normals_fitted=refine or (pixels and field.normals is None),
    )
    return layout, _run_blocks(field, job, points, sample_block_size(field, budget), client)


def _run_blocks(
    field: ReflectanceField,
    job: _BlockJob,
    points: NDArray[np.float64] | None,
    block: int,
    client: Any,
) -> Iterator[tuple[slice, BlockFits]]:
    """Fit every block of ``block`` samples (see :func:`fit_blocks`)."""
    p_count = field.shape[2]
    blocks = [(start, min(start + block, p_count)) for start in range(0, p_count, block)]
    stored = field.normals

    def inputs(start: int, stop: int) -> tuple[NDArray[Any], NDArray[Any], NDArray[Any] | None]:
        part = slice(start, stop)
        seen = np.ascontiguousarray(field.visibility[:, part].T)
        chunk_points = np.zeros((stop - start, 3)) if points is None else points[part].copy()
        normals = None if stored is None else np.ascontiguousarray(stored[part], np.float64)
        return seen, chunk_points, normals

    if client is None:
        for start, stop in progress_bar(blocks, desc="fit", unit="block"):
            yield slice(start, stop), job.run(field.sample_block(start, stop),
                                              *inputs(start, stop))  # fmt: skip
        return
    from dask.delayed import delayed

    from core.cluster import compute_each

    tasks = [
        delayed(_fit_stored_block, pure=False)(
            str(field.path), start, stop, job, *inputs(start, stop)
        )
        for start, stop in blocks
    ]
    for index, fitted in compute_each(client, tasks, what="fit"):
        start, stop = blocks[index]
        yield slice(start, stop), fitted


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


def lobe_alpha_range(lights: NDArray[np.floating], *, one_view: bool) -> tuple[float, float]:
    """The GGX roughness range a field's lights resolve: the default ``alpha_range`` of a fit.

    Parameters
    ----------
    lights : ndarray, shape (T, 3), unit light directions, T >= 2
    one_view : bool, a field of pixels (one camera) rather than of points seen by several

    Returns
    -------
    (low, high) : ``ALPHA_RANGE`` for a field of points; for one view the low end is at least
        ``LOBE_SPACING`` times the lights' mean spacing (radians), and at most half of high.
    """
    low, high = ALPHA_RANGE
    if one_view and len(lights) > 1:
        spacing = math.radians(mean_spacing_deg(lights))
        low = min(max(low, LOBE_SPACING * spacing), high / 2)
    return low, high


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


@dataclass(frozen=True, eq=False)
class _BlockJob:
    """What fitting a block of samples needs besides the block.

    The same for every block, so a Dask task carries it whole (it pickles: the kernel's
    arguments are plain arrays).
    """

    names: tuple[ModelName, ...]
    parametric: tuple[ParametricModelName, ...]
    eyes: NDArray[np.float64]
    pixels: bool
    lights: NDArray[np.float64]
    camera_lights: NDArray[np.float64]
    view: NDArray[np.float64] | None
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
        normals: NDArray[np.float64] | None,
    ) -> BlockFits:
        """Fit every model to a block; its arrays by :meth:`FitLayout.arrays` name.

        Radiance (n, S, T, 3), seen (n, S), points (n, 3), stored normals (n, 3) or None (a
        pixel field without them: photometric stereo on the block gives the starting normals).
        """
        count, t_count = radiance.shape[0], radiance.shape[2]
        result: BlockFits = {}
        if self.pixels:
            # The one camera's values, light-major as the bases and photometric stereo take
            # them: (T, n, 3).
            view_values = radiance[:, 0].transpose(1, 0, 2)
            for name in self.names:
                if name in BASIS_MODELS:
                    fit = fit_basis(name, view_values, self.camera_lights)
                    result[f"{name}__coefficients"] = fit.coefficients
                    result[f"{name}__loo_squared_error"] = fit.loo.squared_error
                    result[f"{name}__loo_energy"] = fit.loo.energy
            if self.parametric and normals is None:
                assert self.view is not None
                normals = photometric_stereo(view_values, self.lights, self.view)
            del view_values
        if not self.parametric:
            return result
        assert normals is not None
        steps = np.array([REFINE_STEP, REFINE_MIN_STEP])
        for name in self.parametric:
            o = _empty_outputs(count, t_count)
            fit_samples(
                radiance, seen, points, normals, self.eyes, self.pixels, self.lights,
                self.loo_indices, self.loo_weights, self.grid, GOLDEN_STEPS,
                name == "lambert+ggx", self.refine, self.shadow_ratio, SHADOW_ITERATIONS, steps,
                o["normal"], o["x1"], o["x2"], o["alpha"], o["lit"], o["loo"], o["energy"],
                o["fitted"],
            )  # fmt: skip
            lobe = name == "lambert+ggx"
            result |= {
                f"{name}__normals": o["normal"],
                f"{name}__rho_d": o["x1"].astype(np.float32),
                f"{name}__f0": (o["x2"] if lobe else np.zeros_like(o["x2"])).astype(np.float32),
                f"{name}__alpha": (o["alpha"] if lobe else np.ones(count)).astype(np.float32),
                f"{name}__lit": o["lit"],
                f"{name}__fitted": o["fitted"],
                f"{name}__loo_squared_error": o["loo"],
                f"{name}__loo_energy": o["energy"],
            }
        return result


def _fit_stored_block(
    path: str,
    start: int,
    stop: int,
    job: _BlockJob,
    seen: NDArray[np.bool_],
    points: NDArray[np.float64],
    normals: NDArray[np.float64] | None,
) -> BlockFits:
    """A Dask task: read samples start..stop from the store at ``path`` and fit them."""
    field = ReflectanceField.open(path, cached_slabs=0)
    return job.run(field.sample_block(start, stop), seen, points, normals)


def budget_for(memory_bytes: int | None, client: Any) -> int:
    """Bytes of radiance per block: as asked, else the default.

    The default is :func:`core.memory_budget.default_memory_budget`, at most
    :data:`FIT_BLOCK_BYTES`; on a cluster no more than a third of the smallest worker's memory
    limit (the block, its widened copy, the outputs).
    """
    if memory_bytes is not None:
        return memory_bytes
    budget = min(default_memory_budget(), FIT_BLOCK_BYTES)
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

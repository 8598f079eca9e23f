"""Measuring one relighting method on one field: its times, its memory and its errors.

:func:`measure_method` opens the method's engine on a :class:`bench.suite.fields.FieldRun`,
times the interactive loop, counts the arrays the engine holds and scores a frame of every
environment and view against the ground truth (relative RMSE, PSNR, :func:`ssim`).
:class:`MethodRows` measures each (scene, field, mode) once per run and relabels the row for
the other studies that ask for the same mode.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, fields, is_dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from bench.sim_truth import Truth, image_errors
from bench.suite.fields import Environment, FieldRun, spec_record
from bench.suite.methods import FieldSpec, Method, mode_record
from bench.suite.results import Row, Score
from bench.timing import loop_ms
from core.colour import linear_to_srgb
from core.field_store import ReflectanceField
from render.engines.interpolated import RelitImage
from render.engines.modes import RelightMode, open_relighter

__all__ = ["MethodRows", "engine_bytes", "measure_method", "score", "ssim"]


def ssim(image: RelitImage, truth: Truth) -> float:
    """Mean SSIM over the pixels both images cover, on tone-mapped 8-bit sRGB.

    Both images are scaled so the truth's 99th percentile over the covered pixels is white,
    clipped, sRGB-encoded to [0, 255] (the range OpenCV's SSIM constants assume), and zero
    outside the covered region; the SSIM map (11 x 11 Gaussian windows) is averaged over the
    covered pixels and the three channels.

    Parameters
    ----------
    image : RelitImage; truth : Truth, of the same view

    Returns
    -------
    float, NaN when no pixel is covered by both
    """
    mask = image.coverage & truth.image.coverage
    if not mask.any():
        return float("nan")
    white = float(np.percentile(truth.image.rgb[mask], 99.0))
    white = white if white > 0 else 1.0

    def tone(rgb: NDArray[np.float32]) -> NDArray[np.float64]:
        encoded = linear_to_srgb(np.clip(rgb / white, 0.0, 1.0)) * 255.0
        return np.where(mask[:, :, None], encoded, 0.0).astype(np.float64)

    # OpenCV's contrib module has no type stubs.
    quality: Any = getattr(cv2, "quality")  # noqa: B009
    _, ssim_map = quality.QualitySSIM_compute(tone(truth.image.rgb), tone(image.rgb))
    return float(np.mean(np.asarray(ssim_map)[mask]))


def engine_bytes(engine: object) -> int:
    """Bytes of the numpy arrays an engine holds, not counting the opened field's.

    Walks the engine's attributes (objects, dataclasses, dicts, sequences); an array and its
    views count once.

    Parameters
    ----------
    engine : object, a relighting engine after a frame

    Returns
    -------
    int
    """
    seen: set[int] = set()
    bases: set[int] = set()
    total = 0
    stack: list[object] = [value for key, value in vars(engine).items() if key != "field"]
    while stack:
        item = stack.pop()
        if id(item) in seen or item is None or isinstance(item, str | int | float | bool):
            continue
        seen.add(id(item))
        if isinstance(item, ReflectanceField):
            continue
        if isinstance(item, np.ndarray):
            base = item
            while isinstance(base.base, np.ndarray):
                base = base.base
            if id(base) not in bases:
                bases.add(id(base))
                total += base.nbytes
        elif isinstance(item, dict):
            stack += list(item.values())
        elif isinstance(item, list | tuple | set | frozenset):
            stack += list(item)
        elif is_dataclass(item):
            stack += [getattr(item, f.name) for f in fields(item)]
        elif hasattr(item, "__dict__"):
            stack += list(vars(item).values())
    return total


def score(image: RelitImage, truth: Truth, env: Environment, view: str) -> Score:
    """The errors of one relit image against its ground truth.

    Parameters
    ----------
    image : RelitImage; truth : Truth, of the same view
    env : Environment, the lighting the image was relit under; view : str, the view's name

    Returns
    -------
    Score
    """
    errors = image_errors(image, truth)
    return {
        "environment": env.name,
        "hdr": env.truth,
        "ldr": env.ldr,
        "view": view,
        "relative_rmse": errors["relative_rmse"],
        "sample_relative_rmse": errors["sample_relative_rmse"],
        "psnr_db": errors["psnr_db"],
        "ssim": ssim(image, truth),
        "outside_fraction": image.outside_fraction,
    }


def measure_method(
    run: FieldRun, method: Method, envs: dict[str, Environment], repeats: int, study: str
) -> Row:
    """Precompute, loop times, memory and errors of one method on one field.

    Parameters
    ----------
    run : FieldRun, the opened field
    method : Method
    envs : the environments to score (the first one also times the loop)
    repeats : int, timed frames per time (after a warm-up frame)
    study : str, the study the row is for

    Returns
    -------
    Row; its precompute includes loading the models' fit for model methods
    """
    start = time.perf_counter()
    engine = open_relighter(run.field, method.mode, run.models)
    precompute = time.perf_counter() - start
    models = method.mode.uses_models
    if models:
        precompute += run.models_timing["load_s"]
    timing_panorama = envs[next(iter(envs))].panorama
    loop = loop_ms(engine, timing_panorama, repeats, run.views["captured"])
    scores = []
    for env in envs.values():
        engine.set_lighting(env.panorama)
        for view, camera in run.views.items():
            engine.set_view(camera)
            scores.append(score(engine.render(), run.truths[(env.truth, view)], env, view))
    return {
        **spec_record(run.scene, run.spec),
        "label": method.label.strip(),
        "role": method.role,
        "mode": mode_record(method.mode),
        "k": method.mode.sampled_k,
        "precompute_s": precompute,
        "models_fit_s": run.models_timing.get("fit_s") if models else None,
        "models_load_s": run.models_timing["load_s"] if models else None,
        "new_lighting_ms": loop["loop_new_lighting_ms"],
        "new_view_ms": loop["loop_new_view_ms"],
        "memory_MB": engine_bytes(engine) / 1e6,
        "scores": scores,
        "study": study,
    }


def _print_row(row: Row) -> None:
    between = [s["relative_rmse"] for s in row["scores"] if s["view"] == "between" and not s["ldr"]]
    print(
        f"{row['study']:9s} {row['scene']:15s} S={row['S']:<3d} T={row['T']:<3d} "
        f"{row['label']:34s} new lighting {row['new_lighting_ms']:8.1f} ms  new view "
        f"{row['new_view_ms']:8.1f} ms  {row['memory_MB']:7.1f} MB  "
        f"rel. RMSE (HDR, between) {np.mean(between):7.2%}",
        flush=True,
    )


@dataclass
class MethodRows:
    """The rows of a run's studies, each (scene, field, mode) measured once.

    A mode two studies share (the K sweep's "paper K=64" is the chain's "paper") is measured
    for the first and its row relabelled for the next, so both report the same figures.

    Attributes
    ----------
    envs : the environments every method is scored under
    repeats : int, timed frames per time
    """

    envs: dict[str, Environment]
    repeats: int
    _done: dict[tuple[str, FieldSpec, RelightMode], Row] = field(
        default_factory=dict, init=False, repr=False
    )

    def row(self, run: FieldRun, study: str, method: Method) -> Row:
        """The row of ``method`` on ``run`` for ``study``, measured or relabelled; printed.

        Parameters
        ----------
        run : FieldRun; study : str; method : Method

        Returns
        -------
        Row, a new dict each time
        """
        key = (run.scene, run.spec, method.mode)
        if key not in self._done:
            self._done[key] = measure_method(run, method, self.envs, self.repeats, study)
        row: Row = {
            **self._done[key],
            "label": method.label.strip(),
            "role": method.role,
            "study": study,
        }
        _print_row(row)
        return row

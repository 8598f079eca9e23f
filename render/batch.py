"""Batch relighting: a sequence for each of many environments, in-process or on Dask.

A :class:`BatchPlan` names the field (a store on disk), the relighting mode, the saved model
fit when the mode needs one, the panoramas, the first view and the sequence. One task relights
one environment's whole sequence (the engine and its view plans are opened once per task) and
writes its frames into the output's Zarr array, one chunk per frame. The store is written
under a temporary name and put in place only when every task has finished, so a worker lost
mid-task (Dask runs its task again) or a failed run never leaves a partial store under the
real name. Results are the same in-process and on a cluster.

Output store (``OUT.zarr``): ``frames`` (E, F, H, W, 3) uint8, sRGB frames tone-mapped with
one exposure per environment (:func:`render.sequence.relight_sequence`); attributes
``panoramas`` (E paths), ``sequence``, ``frames``, ``camera`` and ``mode``.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import zarr
from numpy.typing import NDArray

from core.camera_model import PinholeCamera
from core.errors import InputError
from core.field_store import ReflectanceField, is_field_store
from core.progress import progress_bar
from processing.panorama import read_panorama
from processing.sample_model_store import read_sample_models
from render.engines.modes import RelightMode, open_relighter
from render.sequence import SequenceKind, relight_sequence

__all__ = ["BatchPlan", "read_batch_frames", "relight_batch"]


@dataclass(frozen=True)
class BatchPlan:
    """What a batch relights (frozen data: a Dask task carries it whole).

    Attributes
    ----------
    field : str, the field store's path
    mode : RelightMode, the relighting mode (settings, not an engine)
    models : str or None, the saved fit the mode relights through (None for interpolation)
    panoramas : tuple of str, the environments' files
    camera : PinholeCamera, the first frame's view
    sequence : {"environment", "turntable"}
    frames : int, frames per environment
    """

    field: str
    mode: RelightMode
    models: str | None
    panoramas: tuple[str, ...]
    camera: PinholeCamera
    sequence: SequenceKind
    frames: int

    def __post_init__(self) -> None:
        if not self.panoramas:
            raise InputError("a batch needs at least one panorama")
        if self.frames < 1:
            raise InputError(f"a sequence needs at least 1 frame, got {self.frames}")
        if not is_field_store(self.field):
            raise InputError(f"{self.field}: a batch relights a field store on disk")
        if self.mode.uses_models and self.models is None:
            raise InputError(f"{self.mode.describe()} relights through a saved fit: name it")


def relight_batch(plan: BatchPlan, output: str | os.PathLike[str], *, client: Any = None) -> Path:
    """Relight every environment of ``plan`` into the store ``output``; returns its path.

    Parameters
    ----------
    plan : BatchPlan
    output : path of the new store (``.zarr``); an existing one is refused
    client : distributed.Client, optional; one task per environment on its cluster

    Raises
    ------
    InputError
        ``output`` exists.
    """
    target = Path(output)
    if target.exists():
        raise InputError(f"{target}: exists; choose another path or remove it")
    partial = target.with_name(f".{target.name}.{os.getpid()}.partial")
    shutil.rmtree(partial, ignore_errors=True)
    width, height = plan.camera.width, plan.camera.height
    group = zarr.open_group(str(partial), mode="w")
    group.create_array(
        "frames", shape=(len(plan.panoramas), plan.frames, height, width, 3),
        chunks=(1, 1, height, width, 3), dtype="uint8", fill_value=0,
    )  # fmt: skip
    group.attrs.update(
        {
            "panoramas": list(plan.panoramas),
            "sequence": plan.sequence,
            "frames": plan.frames,
            "camera": asdict(plan.camera),
            "mode": plan.mode.describe(),
            "field": plan.field,
        }
    )
    try:
        indices = range(len(plan.panoramas))
        if client is None:
            for index in progress_bar(indices, desc="environments", unit="env"):
                relight_environment(plan, index, str(partial))
        else:
            from dask.delayed import delayed

            from core.cluster import compute_each

            tasks = [
                delayed(relight_environment, pure=False)(plan, i, str(partial)) for i in indices
            ]
            for _ in compute_each(client, tasks, what="environments"):
                pass  # each task wrote its frames
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    os.replace(partial, target)
    return target


def relight_environment(plan: BatchPlan, index: int, store: str) -> int:
    """One task: relight environment ``index`` of ``plan`` and write its frames into ``store``.

    Writing a frame replaces its chunk whole, so a task run again (its worker died) writes the
    same bytes. Returns ``index``.
    """
    field = ReflectanceField.open(plan.field)
    models = None if plan.models is None else read_sample_models(plan.models, field)
    engine = open_relighter(field, plan.mode, models)
    panorama = read_panorama(plan.panoramas[index])
    pictures = relight_sequence(
        engine, panorama, plan.camera, kind=plan.sequence, frames=plan.frames
    )
    frames = zarr.open_array(str(Path(store) / "frames"), mode="r+")
    for frame, picture in enumerate(pictures):
        frames[index, frame] = picture
    return index


def read_batch_frames(store: str | os.PathLike[str], index: int) -> list[NDArray[np.uint8]]:
    """The frames (H, W, 3) of environment ``index`` of a batch's store."""
    frames = zarr.open_array(str(Path(store) / "frames"), mode="r")
    return [np.asarray(frames[index, f]) for f in range(frames.shape[1])]

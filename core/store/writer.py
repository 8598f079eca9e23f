"""Writing a reflectance-field store: :class:`FieldStoreWriter` and its :class:`SlabWriter`.

The layout written is the one :mod:`core.field_store` documents and reads (names and numbers
in :mod:`core.store.schema`): the store is built under a temporary name (``.NAME.PID.partial``
beside it), renamed when complete, and bound to digests of every array and attribute
(:mod:`core.store.digests`).

A build that is stopped (an error, Ctrl-C, SIGTERM, which ``rig`` raises as Ctrl-C) removes its
partial store; one that is killed (SIGKILL, a power cut) cannot, and the next writer of a store
in that folder removes the partial stores whose process is gone (:func:`remove_stale_partials`).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import re
import shutil
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import zarr
from numpy.typing import NDArray
from zarr.core.array_spec import ArrayConfigParams

from core.atomic import write_problem
from core.camera_model import PinholeCamera
from core.errors import DatasetError, InputError
from core.store.attributes import direction_problem
from core.store.digests import StoreDigests, array_digest, combined_digest, metadata_digests
from core.store.integrity import (
    array_names,
    non_finite,
    radiance_digest,
    read_checked,
    slab_digest,
)
from core.store.schema import (
    DIGESTED_MARK,
    DIGESTS_ATTRIBUTE,
    FIELD_SCHEMA_VERSION,
    SAMPLE_CHUNK,
    companion_paths,
    is_field_store,
)

__all__ = ["FieldStoreWriter", "SlabWriter", "remove_stale_partials"]

#: Seconds an aborted store waits for zarr's writes already under way (a bound on a hang).
SETTLE_S = 60.0


class FieldStoreWriter:
    """Create a field store and fill it slab by slab; :meth:`finish` puts it in place.

    The store is written under a temporary name beside ``path`` and renamed onto it by
    :meth:`finish`, so a crash or an error (:meth:`abort`) never leaves a half-written store
    under the real name, nor mixes new slabs into an old store. :meth:`finish` records the
    ``radiance_digest`` attribute (SHA-256 over every slab's SHA-256, in camera then light
    order), by which a saved model fit knows the data it was fitted to, and ``digests``: the
    digests of every array and attribute (:mod:`core.store.digests`). The partial stores of
    writers of the same store that are gone are removed first (:attr:`removed_partials`).

    Parameters
    ----------
    path : the store's directory
    overwrite : bool
        Replace an existing store at ``path`` (and the files that belong to it, see
        :func:`companion_paths`) when finished; without it an existing store is refused.
    points, normals, light_directions, cameras, image_shape, dtype, light_model, provenance :
        the field's layout (see the module docstring)
    sample_chunk : int, samples per radiance chunk (default :data:`SAMPLE_CHUNK`)

    Attributes
    ----------
    removed_partials : list of Path, partial stores of this store left by processes that are
        gone (killed while they wrote), removed when this writer started

    Raises
    ------
    InputError
        ``path`` exists (without ``overwrite``), or is not a store or an empty folder.
    DatasetError
        The store cannot be created.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        overwrite: bool = False,
        points: NDArray[np.floating] | None,
        normals: NDArray[np.floating] | None,
        light_directions: NDArray[np.floating],
        cameras: list[PinholeCamera],
        image_shape: tuple[int, int] | None = None,
        dtype: str = "float32",
        light_model: dict[str, Any] | None = None,
        provenance: dict[str, Any] | None = None,
        sample_chunk: int = SAMPLE_CHUNK,
    ) -> None:
        if sample_chunk < 1:
            raise InputError(f"samples per chunk must be at least 1, got {sample_chunk}")
        if dtype not in ("float16", "float32"):
            raise InputError(f"field dtype must be float16 or float32, got {dtype!r}")
        if image_shape is None:
            if points is None or normals is None:
                raise InputError("a field of surface points needs their points and normals")
            p = len(points)
            samples: dict[str, Any] = {"kind": "points"}
        else:
            p = image_shape[0] * image_shape[1]
            samples = {"kind": "pixels", "height": image_shape[0], "width": image_shape[1]}
            if len(cameras) != 1:
                raise InputError(f"a field of pixels has exactly one camera, got {len(cameras)}")
        t, s = len(light_directions), len(cameras)
        if min(p, t, s) < 1:
            raise InputError(f"a field needs samples, lights and cameras, got P={p} T={t} S={s}")
        problem = direction_problem("light direction", light_directions)
        if problem is not None:
            raise InputError(f"{path}: {problem}")
        for name, values in (("points", points), ("normals", normals)):
            if values is not None and np.shape(values) != (p, 3):
                raise InputError(f"field {name} must have shape ({p}, 3), got {np.shape(values)}")
        self.path = Path(path)
        self.overwrite = overwrite
        _check_target(self.path, overwrite)
        self.removed_partials = remove_stale_partials(self.path)
        self.partial = self.path.with_name(f".{self.path.name}.{os.getpid()}.partial")
        shutil.rmtree(self.partial, ignore_errors=True)
        with self._writing(any_error=True):  # a failure leaves no partial store
            try:
                self.group = zarr.open_group(str(self.partial), mode="w")
            except Exception as error:  # zarr raises several types for unwritable paths
                raise DatasetError(f"{path}: cannot create the field store: {error}") from error
            self._slab_digests: dict[tuple[int, int], bytes] = {}
            self._camera_peaks = np.zeros(s)
            self._visibility_digests: dict[int, bytes] = {}
            # Every chunk is written, even one equal to the fill value (a black image, a camera
            # that sees nothing): a chunk that is not there is damage, never data.
            every_chunk: ArrayConfigParams = {"write_empty_chunks": True}
            self.radiance = self.group.create_array(
                "radiance", shape=(s, t, p, 3), chunks=(1, 1, min(p, sample_chunk), 3),
                dtype=dtype, fill_value=0.0,
                config=every_chunk, attributes={DIGESTED_MARK: True},
            )  # fmt: skip
            self.visibility = self.group.create_array(
                "visibility", shape=(s, p), chunks=(1, p), dtype="bool", fill_value=False,
                config=every_chunk,
            )  # fmt: skip
            constants: dict[str, NDArray[Any]] = {
                "light_directions": np.asarray(light_directions, dtype=np.float64),
                "camera_directions": np.array([c.direction for c in cameras], dtype=np.float64),
            }
            if points is not None:
                constants["points"] = np.asarray(points, dtype=np.float32)
            if normals is not None:
                constants["normals"] = np.asarray(normals, dtype=np.float32)
            self._data_digests: dict[str, str] = {}
            for name, values in constants.items():
                self.group.create_array(
                    name, shape=values.shape, dtype=values.dtype, config=every_chunk
                )[...] = values
                self._data_digests[name] = array_digest(name, values)
            self.group.attrs.update(
                {
                    "schema_version": FIELD_SCHEMA_VERSION,
                    "samples": samples,
                    "cameras": [asdict(c) for c in cameras],
                    "light_model": light_model or {"type": "directional", "irradiance": 1.0},
                    "provenance": provenance or {},
                }
            )

    @contextlib.contextmanager
    def _writing(self, *, any_error: bool = False) -> Iterator[None]:
        """A write into the partial store: a failed one (a full disk) names the store.

        The partial store is removed on a failed write (or, with ``any_error``, on any
        error), so a full disk leaves no ``.NAME.PID.partial`` behind.
        """
        try:
            yield
        except OSError as error:
            self.abort()
            raise InputError(write_problem(self.path, error)) from None
        except BaseException:
            if any_error:
                self.abort()
            raise

    def write_slab(self, camera: int, light: int, radiance: NDArray[np.floating]) -> None:
        """Store the radiance (P, 3) of every sample for one camera and one light.

        Raises
        ------
        DatasetError
            The slab holds NaN or infinity (or overflows the store's dtype): named by count
            and first sample; nothing is stored.
        """
        self.record_slab(
            camera, light, *_store_slab(self.radiance, self.path, camera, light, radiance)
        )

    def slab_writer(self) -> SlabWriter:
        """A writer of slabs into this store while it is built, for this or another process.

        What it writes counts once recorded here (:meth:`record_slab`): a Dask task writes
        its slabs and returns their digests and peaks for the building process to record.
        """
        return SlabWriter(self.partial, self.path)

    def record_slab(self, camera: int, light: int, digest: bytes, peak: float) -> None:
        """Count a slab written by a :class:`SlabWriter` (its digest and largest value)."""
        self._slab_digests[camera, light] = digest
        self._camera_peaks[camera] = max(self._camera_peaks[camera], peak)

    def write_visibility(self, camera: int, visible: NDArray[np.bool_]) -> None:
        """Store which samples (P,) camera ``camera`` sees."""
        seen = np.asarray(visible, dtype=bool)
        with self._writing():
            self.visibility[camera] = seen
        self._visibility_digests[camera] = slab_digest(seen)
        if not seen.any():
            self._camera_peaks[camera] = -1.0  # sees nothing: dark whatever its slabs hold

    def finish(self) -> Path:
        """Check every slab was written, record the digests and put the store at its path.

        Also records ``dark_cameras``: the cameras that see nothing or recorded no light
        under any light (a lens cap, a dead cable), so the guards need not read the store.
        Whatever stops it (an error, Ctrl-C, SIGTERM) removes the partial store; a store that
        was at the path stays until the new one takes its place.

        Raises
        ------
        DatasetError
            A slab or a camera's visibility was never written (named); the partial store is
            removed.
        InputError
            Another process put a store at the path while this one was building it (two
            builds of one new store: the first to finish wins); the partial store is removed.
        """
        try:
            return self._finish()
        except BaseException:  # Ctrl-C or SIGTERM too, wherever it comes
            self.abort()
            raise

    def _finish(self) -> Path:
        s_count, t_count = self.radiance.shape[:2]
        missing = [f"camera {s} light {t}" for s in range(s_count) for t in range(t_count)
                   if (s, t) not in self._slab_digests]  # fmt: skip
        missing += [f"the visibility of camera {s}" for s in range(s_count)
                    if s not in self._visibility_digests]  # fmt: skip
        if missing:
            raise DatasetError(
                f"{self.path}: {len(missing)} slabs were never written ({', '.join(missing[:5])}"
                f"{', ...' if len(missing) > 5 else ''}); the store was not made"
            )
        dark = [int(s) for s in np.flatnonzero(self._camera_peaks <= 0)]
        with self._writing():
            self.group.attrs["dark_cameras"] = dark
            self.group.attrs["radiance_digest"] = radiance_digest(
                self._slab_digests[key] for key in sorted(self._slab_digests)
            )
            self.group.attrs[DIGESTS_ATTRIBUTE] = self._digests().to_attribute()
            _check_target(self.path, self.overwrite)  # a store that came meanwhile wins
            self._put_in_place()
        return self.path

    def _digests(self) -> StoreDigests:
        """The record of the finished partial store: values given, metadata as written."""
        data = dict(self._data_digests)
        data["radiance"] = str(self.group.attrs["radiance_digest"])
        data["visibility"] = combined_digest(
            self._visibility_digests[camera] for camera in sorted(self._visibility_digests)
        )
        # The metadata as the files hold it, read back the way a reader will read it.
        written = zarr.open_group(str(self.partial), mode="r")
        attributes, metadata = metadata_digests(
            self.partial, dict(written.attrs), array_names(self.partial)
        )
        return StoreDigests(data=data, metadata=metadata, attributes=attributes)

    def _put_in_place(self) -> None:
        """Rename the partial store onto the path; an old store there is set aside first.

        Renaming a folder onto a folder that is not empty fails, so the old store is renamed
        aside, the new one put in place, and the old one removed: stopped in between, the old
        store is put back.
        """
        aside = self.path.with_name(f".{self.path.name}.{os.getpid()}.replaced")
        shutil.rmtree(aside, ignore_errors=True)
        try:
            if self.path.exists():
                os.replace(self.path, aside)
            os.replace(self.partial, self.path)
        except BaseException as error:
            if aside.exists() and not self.path.exists():
                os.replace(aside, self.path)
            if isinstance(error, OSError) and self.path.exists():  # another build's came first
                raise InputError(
                    f"{self.path}: another process put a field store there while this one "
                    "was building it; choose another path, or replace it (--overwrite)"
                ) from None
            raise
        shutil.rmtree(aside, ignore_errors=True)
        for companion in companion_paths(self.path):
            companion.unlink(missing_ok=True)

    def abort(self) -> None:
        """Remove the partial store; whatever was at the path stays as it was.

        Writes already under way in zarr's event loop are waited for first: a write that Ctrl-C
        or SIGTERM interrupted goes on in zarr's thread, and would make the folder again.
        """
        _settle_zarr_writes()
        shutil.rmtree(self.partial, ignore_errors=True)


def _settle_zarr_writes() -> None:
    """Wait (at most :data:`SETTLE_S`) for the tasks running in zarr's event loop to end."""
    from zarr.core import sync

    loop = sync.loop[0]
    if loop is None or not loop.is_running():
        return

    async def others_done() -> None:
        current = asyncio.current_task()
        pending = [task for task in asyncio.all_tasks() if task is not current]
        if pending:
            await asyncio.wait(pending, timeout=SETTLE_S)

    future = asyncio.run_coroutine_threadsafe(others_done(), loop)
    with contextlib.suppress(Exception):  # timed out, or the loop closed meanwhile
        future.result(timeout=SETTLE_S + 5.0)


_PARTIAL = re.compile(r"\.(?P<name>.+)\.(?P<pid>[0-9]+)\.(?:partial|replaced)")


def _alive(pid: int) -> bool:
    """Whether process ``pid`` exists (one of another user counts: it may be writing)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_partials(path: Path) -> list[Path]:
    """Remove the partial stores of ``path`` whose writing process is gone; returns them.

    A writer killed by SIGKILL (or a power cut) cannot remove its ``.NAME.PID.partial``. Only
    those of a PID that no longer exists on this machine are removed: a process writing one
    now keeps it. (The PID says nothing of another machine's processes: do not build one
    store from two machines sharing a folder.) A ``.NAME.PID.replaced`` store left by a writer
    killed between setting the old store aside and putting the new one in place is put back
    when no store is at the path.
    """
    folder = path.parent if str(path.parent) else Path(".")
    removed = []
    try:
        entries = list(folder.iterdir())
    except OSError:  # the folder does not exist yet: nothing left in it
        return []
    for entry in sorted(entries):
        match = _PARTIAL.fullmatch(entry.name)
        if not (match and match["name"] == path.name and entry.is_dir()):
            continue
        pid = int(match["pid"])
        if pid == os.getpid() or _alive(pid):
            continue
        if entry.name.endswith(".replaced") and not path.exists():
            os.replace(entry, path)
            continue
        shutil.rmtree(entry, ignore_errors=True)
        removed.append(entry)
    return removed


@dataclass(frozen=True)
class SlabWriter:
    """Writes and reads back slabs of a store being built (:meth:`FieldStoreWriter.slab_writer`).

    Plain paths, so it pickles into a Dask task; every slab is its own chunks, so processes
    writing different slabs never touch the same file.

    Attributes
    ----------
    partial : Path, the store under construction
    path : Path, the store's final path (named in errors)
    """

    partial: Path
    path: Path

    def _radiance(self, mode: str) -> Any:
        # write_empty_chunks is a setting of the opened array, not of the store: without it a
        # black part of a slab would not be written, and read as damage (a missing chunk).
        array = zarr.open_array(str(self.partial / "radiance"), mode=mode)
        return array.with_config({"write_empty_chunks": True})

    def write(self, camera: int, light: int, radiance: NDArray[np.floating]) -> tuple[bytes, float]:
        """Store one slab (P, 3); returns its digest and its largest value (0 when empty).

        Raises DatasetError for NaN or infinity (or an overflow of the store's dtype).
        """
        return _store_slab(self._radiance("r+"), self.path, camera, light, radiance)

    def read(self, camera: int, light: int) -> NDArray[np.float32]:
        """A slab (P, 3) written before, as float32."""
        array = self._radiance("r")
        return np.asarray(read_checked(self.partial, array, (camera, light)), dtype=np.float32)


def _store_slab(
    array: Any, where: Path, camera: int, light: int, radiance: NDArray[np.floating]
) -> tuple[bytes, float]:
    """Write one slab (P, 3) into the radiance ``array``; its digest and largest value.

    Raises DatasetError for NaN or infinity (or an overflow of the store's dtype), naming the
    store ``where``; nothing is written then.
    """
    with np.errstate(over="ignore"):  # an overflow becomes infinity, refused below
        values = np.ascontiguousarray(radiance, dtype=array.dtype)
    found = non_finite(values)
    if found is not None:
        raise DatasetError(
            f"{where}: camera {camera} light {light}: {found[0]} radiance values are "
            f"NaN or infinite in {array.dtype} (the first at sample {found[1][0]}); "
            "the store keeps finite light only: check the images and calibration"
        )
    try:
        array[camera, light] = values
    except OSError as error:  # a full disk
        raise InputError(write_problem(where, error)) from None
    return slab_digest(values), float(values.max()) if values.size else 0.0


def _check_target(path: Path, overwrite: bool) -> None:
    if not path.exists():
        return
    if not path.is_dir() or not (is_field_store(path) or not any(path.iterdir())):
        raise InputError(
            f"{path}: exists and is not a field store or an empty folder; choose another path"
        )
    if is_field_store(path) and not overwrite:
        raise InputError(
            f"{path}: a field store is already there; choose another path, or replace it "
            "(--overwrite), which also removes the model fit saved beside it"
        )

"""Simulated RTI captures on disk: a dome's images, ``.lp`` files and masks.

:func:`write_rti_capture` writes any images as a dome would leave them (the files
:func:`processing.rti.import_rti` reads: the format of :mod:`core.lp_format`, its mask sidecar
:data:`core.lp_format.MASK_SIDECARS`); :func:`make_world_rti` path-traces a world's capture
(:func:`sim.world.rti.render_world_rti`) and writes it, a fit set and a test set: what
``rig sim rti`` makes and the held-out-light study (:mod:`bench.held_out`) measures on.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.camera_model import rig_to_camera
from core.colour import linear_to_srgb
from core.directions import hemisphere_layout
from core.errors import InputError
from core.image_io import write_linear16_tiff, write_srgb8
from core.lp_format import MASK_SIDECARS, write_lp
from sim.world.mitsuba import DEFAULT_MAX_DEPTH
from sim.world.rti import render_world_rti

__all__ = ["RTI_SPEC", "RtiSpec", "make_world_rti", "write_rti_capture"]


def write_rti_capture(
    folder: str | os.PathLike[str],
    name: str,
    images: NDArray[np.floating],
    directions: ArrayLike,
    *,
    scale: float,
    mask: NDArray[np.bool_] | None = None,
    image_format: Literal["tiff16", "jpeg"] = "tiff16",
) -> Path:
    """Write an RTI capture as a dome would leave it: images, ``NAME.lp`` and ``NAME.mask.png``.

    Parameters
    ----------
    folder : the capture's folder (created)
    name : the ``.lp`` file's stem; images are ``images/NAME_NNN.tif``
    images : ndarray, shape (T, H, W, 3), linear radiance
    directions : array_like, shape (T, 3), toward each light in the camera frame
    scale : float > 0, the radiance written as 16-bit white (values above are clipped)
    mask : ndarray (H, W) of bool, or None: the object's pixels (the sidecar the import reads)
    image_format : {"tiff16", "jpeg"}
        ``tiff16``: linear 16-bit TIFF (``images/NAME_NNN.tif``); ``jpeg``: 8-bit sRGB JPEG of
        quality 95 (``.jpg``), as public RTI benchmarks and most domes ship them.
        :func:`processing.rti.import_rti` reads 16-bit as linear and 8-bit as sRGB by
        default.

    Returns
    -------
    Path of the ``.lp`` file.
    """
    root = Path(folder)
    pictures = np.asarray(images, dtype=np.float64)
    if pictures.ndim != 4 or pictures.shape[3] != 3 or not scale > 0:
        raise InputError(f"images must be (T, H, W, 3) and scale positive, got {pictures.shape}")
    if image_format not in ("tiff16", "jpeg"):
        raise InputError(f"image format must be 'tiff16' or 'jpeg', got {image_format!r}")
    suffix = ".tif" if image_format == "tiff16" else ".jpg"
    files = [f"images/{name}_{t:03d}{suffix}" for t in range(len(pictures))]
    for file, image in zip(files, pictures, strict=True):
        unit = np.clip(image * scale, 0.0, 1.0)
        if image_format == "tiff16":
            write_linear16_tiff(root / file, np.round(unit * 65535.0).astype(np.uint16))
        else:
            write_srgb8(root / file, np.round(linear_to_srgb(unit) * 255.0).astype(np.uint8))
    lp = root / f"{name}.lp"
    write_lp(lp, files, directions)
    if mask is not None:
        picture = np.where(np.asarray(mask, dtype=bool), 255, 0).astype(np.uint8)
        sidecar = MASK_SIDECARS[0].format(stem=name)
        write_srgb8(root / sidecar, np.repeat(picture[:, :, None], 3, axis=2))
    return lp


#: An RTI-style capture of a world: (fit lights, test lights, width, height, samples per
#: pixel); 49 to fit and 20 to predict, as the synthetic RTI benchmarks split their domes.
RtiSpec = tuple[int, int, int, int, int]
RTI_SPEC: RtiSpec = (49, 20, 128, 96, 256)


def make_world_rti(
    folder: Path,
    world: str,
    spec: RtiSpec,
    *,
    max_depth: int = DEFAULT_MAX_DEPTH,
    image_format: Literal["tiff16", "jpeg"] = "tiff16",
) -> None:
    """Path-trace an RTI capture of ``world`` into ``folder``: fit.lp, test.lp, images, masks.

    The fit lights are a Fibonacci dome, the test lights a grid (the two never coincide); one
    exposure for both sets puts 90 % of white at the object's 99.9th percentile. Images are
    linear 16-bit TIFF or, with ``image_format="jpeg"``, 8-bit sRGB JPEG as public benchmarks
    ship them (:func:`write_rti_capture`).

    Parameters
    ----------
    folder : Path, the capture's folder (created)
    world : str, a bundled world's name or a world file (:func:`sim.world.mitsuba.load_world`)
    spec : RtiSpec, (fit lights, test lights, width, height, samples per pixel)
    max_depth : int, the path tracer's longest path
    image_format : {"tiff16", "jpeg"}
    """
    fit_count, test_count, width, height, spp = spec
    fit = render_world_rti(
        world, fit_count, width=width, height=height, spp=spp, max_depth=max_depth
    )
    test = render_world_rti(
        world,
        hemisphere_layout(test_count, "grid"),
        width=width,
        height=height,
        spp=spp,
        max_depth=max_depth,
        seed=1,
    )
    # The two sets' masks differ by the path tracer's noise at the silhouette: pool the values.
    covered = np.concatenate([fit.images[:, fit.alpha >= 0.5].ravel(),
                              test.images[:, test.alpha >= 0.5].ravel()])  # fmt: skip
    scale = 0.9 / max(float(np.percentile(covered, 99.9)), 1e-12)
    for name, capture in (("fit", fit), ("test", test)):
        directions = rig_to_camera(capture.directions, capture.camera)
        write_rti_capture(folder, name, capture.images, directions, scale=scale,
                          mask=capture.alpha >= 0.5, image_format=image_format)  # fmt: skip
